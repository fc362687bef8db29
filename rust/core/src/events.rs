//! Events as the sensor outputs them, and their column-wise batches.

/// One output event: integer microseconds, pixel address, polarity (1 ON, 0 OFF), cause label.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Event {
    pub t_us: i64,
    pub x: u16,
    pub y: u16,
    pub p: i8,
    pub label: u8,
}

impl Event {
    /// Output order: by time, then row, then column.
    #[inline]
    pub fn order_key(&self) -> (i64, u16, u16) {
        (self.t_us, self.y, self.x)
    }
}

/// Events column by column, ready to become Arrow arrays without another pass.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct EventColumns {
    pub t_us: Vec<i64>,
    pub x: Vec<u16>,
    pub y: Vec<u16>,
    pub p: Vec<i8>,
    pub label: Vec<u8>,
}

impl EventColumns {
    pub fn len(&self) -> usize {
        self.t_us.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_us.is_empty()
    }

    /// `n` events, all zero, to be filled in; the label column stays empty without `labels`.
    pub fn zeroed(n: usize, labels: bool) -> Self {
        Self {
            t_us: vec![0; n],
            x: vec![0; n],
            y: vec![0; n],
            p: vec![0; n],
            label: vec![0; if labels { n } else { 0 }],
        }
    }

    /// The columns as equal-length slices, for filling in any order.
    fn slots(&mut self) -> Slots<'_> {
        let n = self.len();
        Slots {
            t_us: &mut self.t_us[..n],
            x: &mut self.x[..n],
            y: &mut self.y[..n],
            p: &mut self.p[..n],
            label: (!self.label.is_empty()).then(|| &mut self.label[..n]),
        }
    }

    pub fn from_events(events: &[Event], labels: bool) -> Self {
        Self {
            t_us: events.iter().map(|e| e.t_us).collect(),
            x: events.iter().map(|e| e.x).collect(),
            y: events.iter().map(|e| e.y).collect(),
            p: events.iter().map(|e| e.p).collect(),
            label: if labels {
                events.iter().map(|e| e.label).collect()
            } else {
                Vec::new()
            },
        }
    }
}

/// Columns cut to one length, so that one bounds check on an index covers all five.
struct Slots<'a> {
    t_us: &'a mut [i64],
    x: &'a mut [u16],
    y: &'a mut [u16],
    p: &'a mut [i8],
    label: Option<&'a mut [u8]>,
}

impl Slots<'_> {
    #[inline(always)]
    fn set(&mut self, i: usize, e: &Event) {
        assert!(i < self.t_us.len(), "event slot {i} out of range");
        self.t_us[i] = e.t_us;
        self.x[i] = e.x;
        self.y[i] = e.y;
        self.p[i] = e.p;
        if let Some(label) = &mut self.label {
            label[i] = e.label;
        }
    }
}

/// One tile's events of a frame, in pixel order (each pixel's in time order), and the times they
/// span, kept pixel by pixel so the sort needs no pass of its own to find them.
#[derive(Debug)]
pub struct EventRun {
    events: Vec<Event>,
    /// Their earliest and latest times (the count is `events`' length).
    span: TimeSpan,
}

impl Default for EventRun {
    fn default() -> Self {
        Self {
            events: Vec::new(),
            span: TimeSpan::EMPTY,
        }
    }
}

impl EventRun {
    /// Where the next pixel's events will start, for `close_pixel`.
    pub fn mark(&self) -> usize {
        self.events.len()
    }

    #[inline]
    pub fn push(&mut self, e: Event) {
        self.events.push(e);
    }

    /// The events pushed since `mark` are one pixel's, in time order: the first and the last
    /// bound their times.
    #[inline]
    pub fn close_pixel(&mut self, mark: usize) {
        if let (Some(first), Some(last)) = (self.events.get(mark), self.events.last()) {
            self.span.t_min_us = self.span.t_min_us.min(first.t_us);
            self.span.t_max_us = self.span.t_max_us.max(last.t_us);
        }
    }

    pub fn clear(&mut self) {
        self.events.clear();
        self.span = TimeSpan::EMPTY;
    }

    pub fn as_slice(&self) -> &[Event] {
        &self.events
    }

    fn span(&self) -> TimeSpan {
        TimeSpan {
            count: self.events.len(),
            ..self.span
        }
    }
}

/// Puts each frame's events in output order and holds back those later than the frame (latency
/// and jitter delay events past it).
#[derive(Debug, Default)]
pub struct EventQueue {
    /// Whether the output has the label column.
    labels: bool,
    /// Events later than the last frame's time, in output order.
    pending: Vec<Event>,
    /// Scratch: this frame's events in output order, the merge's output, the sort's buckets.
    sorted: Vec<Event>,
    merged: Vec<Event>,
    buckets: Vec<u32>,
}

impl EventQueue {
    pub fn new(labels: bool) -> Self {
        Self {
            labels,
            ..Self::default()
        }
    }

    /// Drop the events held back, for a sensor starting over; the choice of columns stays.
    pub fn clear(&mut self) {
        self.pending.clear();
    }

    /// Add a frame's events, given as runs that together are in pixel order, and take every
    /// event up to `t_us`, in output order.
    pub fn push_and_take<'a>(
        &mut self,
        runs: impl Iterator<Item = &'a EventRun> + Clone,
        t_us: i64,
    ) -> EventColumns {
        let span = runs
            .clone()
            .fold(TimeSpan::EMPTY, |span, run| span.merged(&run.span()));
        let runs = runs.map(EventRun::as_slice);
        if self.pending.is_empty() && span.t_max_us <= t_us && span.suits_counting_sort() {
            // Nothing held back and nothing to hold: sorted straight into the output.
            let mut out = EventColumns::zeroed(span.count, self.labels);
            let mut slots = out.slots();
            self.counting_sort(runs, &span, |i, e| slots.set(i, e));
            return out;
        }
        self.sort_frame(runs, &span);
        self.merge_with_pending();
        let due = self.merged.partition_point(|e| e.t_us <= t_us);
        let out = EventColumns::from_events(&self.merged[..due], self.labels);
        self.pending.clear();
        self.pending.extend_from_slice(&self.merged[due..]);
        out
    }

    /// This frame's events into `sorted` by (t, y, x).
    fn sort_frame<'a>(&mut self, runs: impl Iterator<Item = &'a [Event]> + Clone, span: &TimeSpan) {
        self.sorted.clear();
        if span.suits_counting_sort() {
            let mut sorted = std::mem::take(&mut self.sorted);
            sorted.resize(span.count, Event::default());
            self.counting_sort(runs, span, |i, e| sorted[i] = *e);
            self.sorted = sorted;
        } else {
            self.sorted.extend(runs.flatten());
            self.sorted.sort_by_key(Event::order_key);
        }
    }

    /// Pixel order is row-major, so a stable sort on t alone gives (t, y, x) order; counting
    /// does it in two passes, handing each event to `place` with its position.
    fn counting_sort<'a>(
        &mut self,
        runs: impl Iterator<Item = &'a [Event]> + Clone,
        span: &TimeSpan,
        mut place: impl FnMut(usize, &Event),
    ) {
        if span.count == 0 {
            return;
        }
        // Bucket k starts at the number of events earlier than t_min + k.
        let t_min = span.t_min_us;
        self.buckets.clear();
        self.buckets.resize((span.t_max_us - t_min) as usize + 2, 0);
        let buckets = self.buckets.as_mut_slice();
        for run in runs.clone() {
            for e in run {
                buckets[(e.t_us - t_min) as usize + 1] += 1;
            }
        }
        for k in 1..buckets.len() {
            buckets[k] += buckets[k - 1];
        }
        for run in runs {
            for e in run {
                let slot = &mut buckets[(e.t_us - t_min) as usize];
                place(*slot as usize, e);
                *slot += 1;
            }
        }
    }

    /// `pending` and `sorted` merged into `merged`; on equal keys the pending event goes first,
    /// since it was emitted earlier.
    fn merge_with_pending(&mut self) {
        let (a, b) = (&self.pending, &self.sorted);
        self.merged.clear();
        self.merged.reserve(a.len() + b.len());
        let (mut i, mut j) = (0, 0);
        while i < a.len() && j < b.len() {
            if a[i].order_key() <= b[j].order_key() {
                self.merged.push(a[i]);
                i += 1;
            } else {
                self.merged.push(b[j]);
                j += 1;
            }
        }
        self.merged.extend_from_slice(&a[i..]);
        self.merged.extend_from_slice(&b[j..]);
    }
}

/// How many events a frame has and the times they span.
#[derive(Clone, Copy, Debug)]
struct TimeSpan {
    count: usize,
    t_min_us: i64,
    t_max_us: i64,
}

impl TimeSpan {
    const EMPTY: Self = Self {
        count: 0,
        t_min_us: i64::MAX,
        t_max_us: i64::MIN,
    };

    fn merged(&self, other: &Self) -> Self {
        Self {
            count: self.count + other.count,
            t_min_us: self.t_min_us.min(other.t_min_us),
            t_max_us: self.t_max_us.max(other.t_max_us),
        }
    }

    /// Counting pays when there are not many more buckets than events (always, within a frame
    /// and its latency); an empty frame counts trivially.
    fn suits_counting_sort(&self) -> bool {
        self.count == 0 || ((self.t_max_us - self.t_min_us) as u64) < 4 * self.count as u64 + 4096
    }
}

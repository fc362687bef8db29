//! Events as the sensor outputs them, and their column-wise batches.
//!
//! A call's events can be many (up to the fuse's limit, `crate::fuse`): every large buffer here
//! is reserved fallibly, so memory that cannot be had is an `OutOfMemory` error, not an abort.

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
    pub fn zeroed(n: usize, labels: bool) -> Result<Self, OutOfMemory> {
        let fail = OutOfMemory { events: n };
        Ok(Self {
            t_us: try_zeroed(n).ok_or(fail)?,
            x: try_zeroed(n).ok_or(fail)?,
            y: try_zeroed(n).ok_or(fail)?,
            p: try_zeroed(n).ok_or(fail)?,
            label: try_zeroed(if labels { n } else { 0 }).ok_or(fail)?,
        })
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

    pub fn from_events(events: &[Event], labels: bool) -> Result<Self, OutOfMemory> {
        let fail = OutOfMemory {
            events: events.len(),
        };
        Ok(Self {
            t_us: try_column(events, |e| e.t_us).ok_or(fail)?,
            x: try_column(events, |e| e.x).ok_or(fail)?,
            y: try_column(events, |e| e.y).ok_or(fail)?,
            p: try_column(events, |e| e.p).ok_or(fail)?,
            label: if labels {
                try_column(events, |e| e.label).ok_or(fail)?
            } else {
                Vec::new()
            },
        })
    }
}

/// Memory for this many events could not be had.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OutOfMemory {
    pub events: usize,
}

/// An integer type, for which all-zero bytes are a value (0).
trait Zeroable: Copy {}
impl Zeroable for i64 {}
impl Zeroable for u16 {}
impl Zeroable for i8 {}
impl Zeroable for u8 {}

/// `vec![0; n]` (zeroed pages from the allocator, no pass to write them), or None instead of
/// an abort when the memory cannot be had.
fn try_zeroed<T: Zeroable>(n: usize) -> Option<Vec<T>> {
    let layout = std::alloc::Layout::array::<T>(n).ok()?;
    if layout.size() == 0 {
        return Some(Vec::new());
    }
    // SAFETY: the layout has a non-zero size.
    let start = unsafe { std::alloc::alloc_zeroed(layout) }.cast::<T>();
    if start.is_null() {
        return None;
    }
    // SAFETY: allocated by the global allocator with the layout of n T's, all zero bytes,
    // which is a valid T (an integer).
    Some(unsafe { Vec::from_raw_parts(start, n, n) })
}

/// One column of `events`, or None when its memory cannot be had.
fn try_column<T>(events: &[Event], field: impl Fn(&Event) -> T) -> Option<Vec<T>> {
    let mut column = Vec::new();
    column.try_reserve_exact(events.len()).ok()?;
    column.extend(events.iter().map(field));
    Some(column)
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

    pub fn len(&self) -> usize {
        self.events.len()
    }

    pub fn is_empty(&self) -> bool {
        self.events.is_empty()
    }

    /// Room for `more` events, or false when the memory cannot be had.
    pub fn try_reserve(&mut self, more: usize) -> bool {
        self.events.try_reserve(more).is_ok()
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

    /// Events held back.
    pub fn held(&self) -> usize {
        self.pending.len()
    }

    /// Add a frame's events, given as runs that together are in pixel order, and take every
    /// event up to `t_us`, in output order. When memory runs out the events held back are
    /// unchanged, and this frame's are dropped.
    pub fn push_and_take<'a>(
        &mut self,
        runs: impl Iterator<Item = &'a EventRun> + Clone,
        t_us: i64,
    ) -> Result<EventColumns, OutOfMemory> {
        let span = runs
            .clone()
            .fold(TimeSpan::EMPTY, |span, run| span.merged(&run.span()));
        let runs = runs.map(EventRun::as_slice);
        if self.pending.is_empty() && span.t_max_us <= t_us && span.suits_counting_sort() {
            // Nothing held back and nothing to hold: sorted straight into the output.
            let mut out = EventColumns::zeroed(span.count, self.labels)?;
            let mut slots = out.slots();
            self.counting_sort(runs, &span, |i, e| slots.set(i, e))?;
            return Ok(out);
        }
        let fail = OutOfMemory {
            events: span.count + self.pending.len(),
        };
        self.sort_frame(runs, &span).ok_or(fail)?;
        self.merge_with_pending().ok_or(fail)?;
        let due = self.merged.partition_point(|e| e.t_us <= t_us);
        let out = EventColumns::from_events(&self.merged[..due], self.labels)?;
        let later = &self.merged[due..];
        if later.len() > self.pending.capacity() {
            self.pending.try_reserve(later.len()).map_err(|_| fail)?;
        }
        self.pending.clear();
        self.pending.extend_from_slice(later);
        Ok(out)
    }

    /// This frame's events into `sorted` by (t, y, x).
    fn sort_frame<'a>(
        &mut self,
        runs: impl Iterator<Item = &'a [Event]> + Clone,
        span: &TimeSpan,
    ) -> Option<()> {
        self.sorted.clear();
        self.sorted.try_reserve(span.count).ok()?;
        if span.suits_counting_sort() {
            let mut sorted = std::mem::take(&mut self.sorted);
            sorted.resize(span.count, Event::default());
            let placed = self.counting_sort(runs, span, |i, e| sorted[i] = *e);
            self.sorted = sorted;
            placed.ok()
        } else {
            self.sorted.extend(runs.flatten());
            self.sorted.sort_by_key(Event::order_key);
            Some(())
        }
    }

    /// Pixel order is row-major, so a stable sort on t alone gives (t, y, x) order; counting
    /// does it in two passes, handing each event to `place` with its position.
    fn counting_sort<'a>(
        &mut self,
        runs: impl Iterator<Item = &'a [Event]> + Clone,
        span: &TimeSpan,
        mut place: impl FnMut(usize, &Event),
    ) -> Result<(), OutOfMemory> {
        if span.count == 0 {
            return Ok(());
        }
        // Bucket k starts at the number of events earlier than t_min + k.
        let t_min = span.t_min_us;
        let bucket_count = (span.t_max_us - t_min) as usize + 2;
        self.buckets.clear();
        self.buckets
            .try_reserve(bucket_count)
            .map_err(|_| OutOfMemory { events: span.count })?;
        self.buckets.resize(bucket_count, 0);
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
        Ok(())
    }

    /// `pending` and `sorted` merged into `merged`; on equal keys the pending event goes first,
    /// since it was emitted earlier.
    fn merge_with_pending(&mut self) -> Option<()> {
        let (a, b) = (&self.pending, &self.sorted);
        self.merged.clear();
        self.merged.try_reserve(a.len() + b.len()).ok()?;
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
        Some(())
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn columns_that_memory_cannot_hold_are_an_error_not_an_abort() {
        // 2^50 events are 8 PiB of times alone, beyond any address space (vec![0; n] aborted);
        // usize::MAX / 4 events overflow the byte count of a column.
        for n in [1usize << 50, usize::MAX / 4] {
            assert_eq!(
                EventColumns::zeroed(n, true).unwrap_err(),
                OutOfMemory { events: n }
            );
        }
        let columns = EventColumns::zeroed(3, false).unwrap();
        assert_eq!(
            (columns.t_us, columns.x, columns.label),
            (vec![0; 3], vec![0; 3], vec![])
        );
    }
}

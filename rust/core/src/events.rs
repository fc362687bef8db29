//! Events as the sensor outputs them, and their column-wise batches.

/// One output event: integer microseconds, pixel address, polarity (1 ON, 0 OFF), cause label.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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

    pub fn from_events(events: &[Event]) -> Self {
        Self {
            t_us: events.iter().map(|e| e.t_us).collect(),
            x: events.iter().map(|e| e.x).collect(),
            y: events.iter().map(|e| e.y).collect(),
            p: events.iter().map(|e| e.p).collect(),
            label: events.iter().map(|e| e.label).collect(),
        }
    }
}

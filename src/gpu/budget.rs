//! Time budgets: a call's deadline, and the measured cost of each stage's work from which
//! the scheduler sizes its next work item to the time left.

use std::time::{Duration, Instant};

/// Share of a bounded budget the quick preview march may take.
pub(super) const QUICK_SHARE: f64 = 0.4;
/// ...and at most this share of the full march still to come: a preview that cost more would
/// mostly delay the image it stands in for.
pub(super) const QUICK_OF_FULL: f64 = 0.1;

/// Milliseconds since `t`.
pub(super) fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// A call's deadline: None runs every item to completion.
#[derive(Clone, Copy, Debug)]
pub(super) struct Clock {
    deadline: Option<Instant>,
    /// The deadline only spaces out progress reports (an update in slices), so an item may
    /// overrun it: the march then keeps to whole rows of workgroups, its most efficient bands.
    pub whole_rows: bool,
}

impl Clock {
    /// A deadline `budget` from now, which a frame must keep.
    pub fn start(budget: Option<Duration>) -> Self {
        let started = Instant::now();
        Self { deadline: budget.map(|b| started + b), whole_rows: false }
    }

    /// A slice of `slice` between progress reports, which items may overrun.
    pub fn slice(slice: Duration) -> Self {
        Self { whole_rows: true, ..Self::start(Some(slice)) }
    }

    pub fn bounded(&self) -> bool {
        self.deadline.is_some()
    }

    /// Milliseconds left at `now` (None: unbounded).
    pub fn left_ms(&self, now: Instant) -> Option<f64> {
        self.deadline.map(|d| d.saturating_duration_since(now).as_secs_f64() * 1e3)
    }

    /// Whether the deadline has passed.
    pub fn spent(&self) -> bool {
        self.left_ms(Instant::now()).is_some_and(|ms| ms <= 0.0)
    }
}

/// Measured cost of one unit of a stage's work (a cell, a particle evaluation, a pixel),
/// smoothed, to size the next work item to the time left.
#[derive(Clone, Copy, Debug)]
pub(super) struct Rate {
    ms_per_unit: f64,
}

impl Rate {
    pub fn new(ms_per_unit: f64) -> Self {
        Self { ms_per_unit }
    }

    pub fn observe(&mut self, units: u64, ms: f64) {
        // Small items are dominated by fixed submit costs; they would make the rate optimistic.
        if units > 0 && ms > 0.5 {
            let r = ms / units as f64;
            self.ms_per_unit = if self.ms_per_unit > 0.0 { 0.5 * (self.ms_per_unit + r) } else { r };
        }
    }

    /// Units that fit in `ms` (a bounded budget), else everything.
    pub fn units_in(&self, ms: Option<f64>) -> u64 {
        match ms {
            Some(ms) => (ms.max(0.0) / self.ms_per_unit.max(1e-12)) as u64,
            None => u64::MAX,
        }
    }

    pub fn ms_for(&self, units: u64) -> f64 {
        units as f64 * self.ms_per_unit
    }

    /// The size of a quick preview of a `width`×`height` image whose march fits `budget_ms`:
    /// at most half the size per axis, in sixteenths of it, at least 16 pixels a side.
    pub fn quick_size(&self, width: u32, height: u32, budget_ms: Option<f64>) -> (u32, u32) {
        let pixels = (width as f64 * height as f64).max(1.0);
        let affordable = self.units_in(budget_ms) as f64;
        // Sixteenths of the full size, so small changes in the measured rate keep the target.
        let s = ((affordable / pixels).sqrt() * 16.0).floor().clamp(1.0, 8.0) / 16.0;
        let w = ((width as f64 * s) as u32).max(16).min(width);
        let h = ((height as f64 * s) as u32).max(16).min(height);
        (w, h)
    }
}

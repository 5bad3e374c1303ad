//! A planned propagation: its dispatches, how much each computes, and how far encoding got.

use super::Work;

/// The dispatches that bring the OPVs of some lights up to date, each valid to run once the
/// ones before it have completed, in this or an earlier submit.
pub struct PropagationJob {
    /// The lights this job propagates.
    pub lights: Vec<u32>,
    pub(super) work: Work,
    pub(super) groups: Vec<[u32; 3]>,
    /// Runs of steps that form one batch, with the entry and workgroups that run them as one.
    pub(super) whole: Vec<(std::ops::Range<usize>, usize, [u32; 3])>,
    /// Cells each dispatch computes: the unit of its cost.
    pub(super) units: Vec<u64>,
    pub(super) next: usize,
    pub(super) iterations: u32,
    /// Cells the whole job computes.
    pub(super) cells: u64,
    /// Directional lights' dispatches: those from this index on.
    pub(super) suns: Option<(usize, Work)>,
}

impl PropagationJob {
    pub fn done(&self) -> bool {
        self.next >= self.groups.len()
    }
    /// Cells of the next `count` dispatches.
    pub fn units(&self, count: usize) -> u64 {
        self.units[self.next.min(self.units.len())..(self.next + count).min(self.units.len())].iter().sum()
    }
    /// How many of the next dispatches fit in `units` cells (at least one).
    pub fn fitting(&self, units: u64) -> usize {
        let mut sum = 0u64;
        let mut n = 0;
        for &u in &self.units[self.next..] {
            if n > 0 && sum.saturating_add(u) > units {
                break;
            }
            sum = sum.saturating_add(u);
            n += 1;
        }
        n.max(1)
    }
    /// Fraction of the job's cells computed.
    pub fn fraction(&self) -> f64 {
        let total: u64 = self.units.iter().sum();
        if total == 0 {
            return 1.0;
        }
        self.units[..self.next].iter().sum::<u64>() as f64 / total as f64
    }
}

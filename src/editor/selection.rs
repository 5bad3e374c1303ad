//! Which particles and lights are selected: indices into the project's lists, kept valid
//! as edits remove items.

use std::collections::BTreeSet;

/// Which particles and lights are selected (indices into the project's lists).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Selection {
    pub particles: BTreeSet<usize>,
    pub lights: BTreeSet<usize>,
}

impl Selection {
    pub fn is_empty(&self) -> bool {
        self.particles.is_empty() && self.lights.is_empty()
    }
    pub fn clear(&mut self) {
        self.particles.clear();
        self.lights.clear();
    }
    pub fn len(&self) -> usize {
        self.particles.len() + self.lights.len()
    }

    /// Drops indices past the ends of lists of `particles` and `lights` items.
    pub fn keep_within(&mut self, particles: usize, lights: usize) {
        self.particles.retain(|&i| i < particles);
        self.lights.retain(|&i| i < lights);
    }
}

/// Indices of `kept` after the items in `removed` were deleted from the list.
pub fn remap_after_removal(kept: &BTreeSet<usize>, removed: &BTreeSet<usize>) -> BTreeSet<usize> {
    kept.iter().filter(|i| !removed.contains(i)).map(|&i| i - removed.range(..i).count()).collect()
}

//! Stable ids of particles and lights.
//!
//! An id names an object for as long as it exists: erasing or reordering others never
//! renames it, and a deleted object's id is not handed out again (the project keeps the
//! next id of each kind in [`NextIds`]), so "Particle #79" in an undo label, a slice or an
//! exported file always means the same particle.

use super::Project;
use serde::{Deserialize, Serialize};

/// The id the next new particle and the next new light get. Loading raises a counter that
/// is not above every id in use, so a hand-edited file cannot make ids collide.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(default)]
pub struct NextIds {
    pub particle: u32,
    pub light: u32,
}

/// The first of `ids` that occurs twice, as (first index, second index).
pub(crate) fn first_duplicate(ids: impl Iterator<Item = u32> + Clone) -> Option<(usize, usize)> {
    // Ids in ascending order, as the editor and version-1 files number them, cannot repeat.
    let mut last = None;
    if ids.clone().all(|id| last.replace(id).is_none_or(|l| l < id)) {
        return None;
    }
    let mut seen = std::collections::HashMap::new();
    for (i, id) in ids.enumerate() {
        if let Some(&first) = seen.get(&id) {
            return Some((first, i));
        }
        seen.insert(id, i);
    }
    None
}

impl Project {
    /// A fresh particle id (and advances the counter). The counters stay above every id in
    /// use as long as ids come from here, [`Self::ensure_unique_ids`] or a loaded file.
    pub fn new_particle_id(&mut self) -> u32 {
        let id = self.next_id.particle;
        self.next_id.particle += 1;
        id
    }

    /// A fresh light id (and advances the counter).
    pub fn new_light_id(&mut self) -> u32 {
        let id = self.next_id.light;
        self.next_id.light += 1;
        id
    }

    /// Raises each counter above every id in use.
    pub fn raise_next_ids(&mut self) {
        if let Some(m) = self.particles.iter().map(|p| p.id).max() {
            self.next_id.particle = self.next_id.particle.max(m.saturating_add(1));
        }
        if let Some(m) = self.lights.iter().map(|l| l.id).max() {
            self.next_id.light = self.next_id.light.max(m.saturating_add(1));
        }
    }

    /// Gives every particle or light whose id an earlier one already has a fresh id (a
    /// project built in code, where every id is 0). The editor and saving call this; ids
    /// that are already unique are left alone.
    pub fn ensure_unique_ids(&mut self) {
        self.raise_next_ids();
        let mut seen = std::collections::HashSet::new();
        for i in 0..self.particles.len() {
            if !seen.insert(self.particles[i].id) {
                self.particles[i].id = self.new_particle_id();
            }
        }
        seen.clear();
        for i in 0..self.lights.len() {
            if !seen.insert(self.lights[i].id) {
                self.lights[i].id = self.new_light_id();
            }
        }
    }

    /// Index of the particle with `id`.
    pub fn particle_index(&self, id: u32) -> Option<usize> {
        self.particles.iter().position(|p| p.id == id)
    }

    /// Index of the light with `id`.
    pub fn light_index(&self, id: u32) -> Option<usize> {
        self.lights.iter().position(|l| l.id == id)
    }

    /// "Particle #id", or the particle's own name.
    pub fn particle_label(&self, index: usize) -> String {
        match self.particles.get(index) {
            Some(p) => p.name.clone().unwrap_or_else(|| format!("Particle #{}", p.id)),
            None => format!("particle {index} (gone)"),
        }
    }

    /// "Light #id", or the light's own name.
    pub fn light_label(&self, index: usize) -> String {
        match self.lights.get(index) {
            Some(l) => l.name.clone().unwrap_or_else(|| format!("Light #{}", l.id)),
            None => format!("light {index} (gone)"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Particle;
    use glam::Vec3;

    #[test]
    fn code_built_projects_get_distinct_ids_and_new_ids_are_never_reused() {
        let mut p = Project {
            particles: (0..4).map(|i| Particle::new(Vec3::splat(i as f32), 0.1, 1.0)).collect(),
            ..Project::default()
        };
        p.ensure_unique_ids();
        let ids: Vec<u32> = p.particles.iter().map(|q| q.id).collect();
        assert_eq!(ids, [0, 1, 2, 3]);
        p.particles.pop();
        assert_eq!(p.new_particle_id(), 4, "the id of a deleted particle is not handed out again");
        assert_eq!(first_duplicate([3, 1, 3].into_iter()), Some((0, 2)));
    }
}

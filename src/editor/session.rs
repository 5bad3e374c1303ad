//! The editing session: the project being edited, the selection, undo/redo history, the file
//! it came from and whether it has unsaved changes.
//!
//! Nothing here draws or touches the GPU, so every edit the editor can make is testable
//! without a window. Undo keeps each step's project without its particles, and the particles
//! as what the step changed (see `history`), so a step costs what it touched however large
//! the scene; the history is bounded by step count and by total particles held.

use super::history::Stored;
use crate::scene::{Light, Particle, Project};
use glam::Vec3;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Most undo steps kept.
const MAX_UNDO_STEPS: usize = 200;
/// Most particles kept across all undo snapshots before the oldest steps are dropped.
const MAX_UNDO_PARTICLES: usize = 20_000_000;

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
}

/// One state of the project under edit, for keying what is derived from it (the preview,
/// read-backs, recovery files). `epoch` counts whole-project replacements (new, open,
/// restore), kept by the editor; `generation` is [`Session::generation`] or
/// [`Session::content_generation`] within one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Version {
    pub epoch: u64,
    pub generation: u64,
}

/// A tag that lets consecutive edits (one brush stroke, one slider drag) share one undo step.
pub type EditTag = u64;

/// An edit that starts a new undo step whatever came before.
pub const NEW_STEP: EditTag = 0;

/// One undo or redo step: `project` holds no particles, `particles` holds them (see
/// `history`) relative to the neighbouring state (the next newer one for undo steps, the
/// next older one for redo steps).
struct Snapshot {
    project: Project,
    particles: Stored,
    selection: Selection,
    generation: u64,
}

/// The project under edit plus its history and file state.
pub struct Session {
    project: Project,
    pub selection: Selection,
    undo: Vec<Snapshot>,
    redo: Vec<Snapshot>,
    path: Option<PathBuf>,
    name: String,
    generation: u64,
    content_generation: u64,
    next_generation: u64,
    saved_generation: Option<u64>,
    open_tag: Option<EditTag>,
    next_tag: EditTag,
}

impl Session {
    /// A session on `project`, read from `path` (or never saved when `path` is `None`;
    /// `name` is then shown in the title). It starts without unsaved changes.
    pub fn new(mut project: Project, path: Option<PathBuf>, name: &str) -> Self {
        project.ensure_unique_ids();
        let name = path
            .as_deref()
            .and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| name.to_owned());
        Self {
            project,
            selection: Selection::default(),
            undo: Vec::new(),
            redo: Vec::new(),
            path,
            name,
            generation: 1,
            content_generation: 1,
            next_generation: 2,
            saved_generation: Some(1),
            open_tag: None,
            next_tag: 1,
        }
    }

    pub fn project(&self) -> &Project {
        &self.project
    }
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }
    /// File name shown in the title.
    pub fn name(&self) -> &str {
        &self.name
    }
    /// Changes on every edit (and on undo/redo); lets views cache what they derive.
    pub fn generation(&self) -> u64 {
        self.generation
    }
    /// Like [`Self::generation`] but unchanged by camera moves: for views of the volumes.
    pub fn content_generation(&self) -> u64 {
        self.content_generation
    }
    pub fn is_dirty(&self) -> bool {
        self.saved_generation != Some(self.generation)
    }
    /// Records that the state of generation `generation` was written to `path`.
    pub fn mark_saved(&mut self, path: PathBuf, generation: u64) {
        self.name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        self.path = Some(path);
        self.saved_generation = Some(generation);
    }

    /// Marks the current state as not saved (restored recovery work).
    pub fn mark_unsaved(&mut self) {
        self.saved_generation = None;
    }

    /// A fresh tag for a multi-event edit such as a brush stroke.
    pub fn new_tag(&mut self) -> EditTag {
        self.next_tag += 1;
        self.next_tag
    }

    /// Takes back the coalesced edit `tag` if it is the one in progress, leaving no undo or
    /// redo step behind (a cancelled drag).
    pub fn cancel_edit(&mut self, tag: EditTag) {
        if tag != NEW_STEP && self.open_tag == Some(tag) {
            if let Some(s) = self.undo.pop() {
                self.swap_in(s);
            }
        }
        self.open_tag = None;
        self.compress_top();
    }

    /// Whether a coalesced edit (a stroke, a drag) is in progress.
    pub fn edit_in_progress(&self) -> bool {
        self.open_tag.is_some()
    }

    /// Ends the current coalesced edit: the next edit starts a new undo step.
    pub fn end_edit(&mut self) {
        self.open_tag = None;
        self.compress_top();
    }

    /// Shrinks the last undo step to what it changed, once no edit can extend it.
    fn compress_top(&mut self) {
        if let Some(s) = self.undo.last_mut() {
            s.particles.compress(&self.project.particles);
        }
    }

    /// Particles held by the undo and redo steps (a step holds what it changed).
    pub fn history_particles(&self) -> usize {
        self.undo.iter().chain(&self.redo).map(|s| s.particles.held()).sum()
    }

    /// Mutable access for an edit. A new undo step is recorded unless `tag` continues the
    /// edit in progress.
    pub fn edit(&mut self, tag: EditTag) -> &mut Project {
        if tag == NEW_STEP || self.open_tag != Some(tag) {
            self.push_undo();
            self.open_tag = if tag == NEW_STEP { None } else { Some(tag) };
        }
        self.generation = self.next_generation;
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        &mut self.project
    }

    /// Changes the view camera: saved with the project but not an undo step, like a view
    /// change in other editors.
    pub fn set_camera(&mut self, camera: crate::scene::Camera) {
        if camera != self.project.camera {
            self.project.camera = camera;
            self.generation = self.next_generation;
            self.next_generation += 1;
        }
    }

    fn push_undo(&mut self) {
        self.compress_top();
        self.undo.push(Snapshot {
            project: self.project.without_particles(),
            particles: Stored::Full(self.project.particles.clone()),
            selection: self.selection.clone(),
            generation: self.generation,
        });
        self.redo.clear();
        let mut total: usize = self.undo.iter().map(|s| s.particles.held()).sum();
        while self.undo.len() > MAX_UNDO_STEPS || (total > MAX_UNDO_PARTICLES && self.undo.len() > 1) {
            total -= self.undo.remove(0).particles.held();
        }
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }
    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }
    pub fn undo_len(&self) -> usize {
        self.undo.len()
    }

    /// What Undo would take back, named by ids ("Delete Particle #24"); None with nothing to undo.
    pub fn undo_label(&self) -> Option<String> {
        self.undo.last().map(|s| {
            let (before, after) = s.particles.sides(&self.project.particles);
            describe(&s.project, &self.project, &before, &after)
        })
    }

    /// What Redo would bring back.
    pub fn redo_label(&self) -> Option<String> {
        self.redo.last().map(|s| {
            let (after, before) = s.particles.sides(&self.project.particles);
            describe(&self.project, &s.project, &before, &after)
        })
    }

    /// Restores the state before the last edit; the camera stays where the user put it.
    pub fn undo(&mut self) -> bool {
        let Some(s) = self.undo.pop() else { return false };
        let current = self.swap_in(s);
        self.redo.push(current);
        true
    }

    pub fn redo(&mut self) -> bool {
        let Some(s) = self.redo.pop() else { return false };
        let current = self.swap_in(s);
        self.undo.push(current);
        true
    }

    fn swap_in(&mut self, mut s: Snapshot) -> Snapshot {
        self.open_tag = None;
        s.project.camera = self.project.camera;
        s.project.particles = std::mem::take(&mut self.project.particles);
        let particles = s.particles.restore(&mut s.project.particles);
        let project = std::mem::replace(&mut self.project, s.project);
        let selection = std::mem::replace(&mut self.selection, s.selection);
        let generation = std::mem::replace(&mut self.generation, s.generation);
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        self.sanitize_selection();
        Snapshot { project, particles, selection, generation }
    }

    fn sanitize_selection(&mut self) {
        let (np, nl) = (self.project.particles.len(), self.project.lights.len());
        self.selection.particles.retain(|&i| i < np);
        self.selection.lights.retain(|&i| i < nl);
    }

    // ---- edits used by tools, menus and panels ----

    /// Appends particles (one undo step per `tag`) and returns how many there are now.
    pub fn add_particles(&mut self, tag: EditTag, particles: impl IntoIterator<Item = Particle>) -> usize {
        let p = self.edit(tag);
        for mut q in particles {
            q.id = p.new_particle_id();
            p.particles.push(q);
        }
        p.particles.len()
    }

    /// Removes visible particles whose centre lies within `radius` of the line through
    /// `origin` along unit `dir` (in front of the origin). Returns how many were removed.
    pub fn erase_along_ray(&mut self, tag: EditTag, origin: Vec3, dir: Vec3, radius: f32) -> usize {
        let hit = |p: &Particle| {
            let d = p.center - origin;
            let t = d.dot(dir);
            !p.hidden && t > 0.0 && (d - dir * t).length_squared() <= radius * radius
        };
        if !self.project.particles.iter().any(hit) {
            return 0;
        }
        let removed: BTreeSet<usize> =
            self.project.particles.iter().enumerate().filter(|(_, p)| hit(p)).map(|(i, _)| i).collect();
        self.remove_particles(tag, &removed);
        removed.len()
    }

    fn remove_particles(&mut self, tag: EditTag, removed: &BTreeSet<usize>) {
        self.edit(tag).remove_particles(removed);
        self.selection.particles = remap_after_removal(&self.selection.particles, removed);
    }

    /// Multiplies the radius (or, with `density`, the density) of `targets` by `factor`.
    pub fn scale_particles(&mut self, tag: EditTag, targets: &BTreeSet<usize>, factor: f32, density: bool) {
        if targets.is_empty() || !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let project = self.edit(tag);
        for &i in targets {
            if let Some(p) = project.particles.get_mut(i) {
                if density {
                    p.density = (p.density * factor).clamp(0.0, 1.0e6);
                } else {
                    p.radius = (p.radius * factor).clamp(1.0e-4, 1.0e4);
                }
            }
        }
    }

    /// Moves the selected particles and lights by `delta`.
    pub fn translate_selection(&mut self, tag: EditTag, delta: Vec3) {
        if self.selection.is_empty() || !delta.is_finite() {
            return;
        }
        let sel = self.selection.clone();
        let project = self.edit(tag);
        for &i in &sel.particles {
            if let Some(p) = project.particles.get_mut(i) {
                p.center += delta;
            }
        }
        for &i in &sel.lights {
            project.move_light(i, delta);
        }
    }

    /// Deletes the selection; returns how many items went.
    pub fn delete_selection(&mut self) -> usize {
        if self.selection.is_empty() {
            return 0;
        }
        let n = self.selection.len();
        let particles = std::mem::take(&mut self.selection.particles);
        let lights = std::mem::take(&mut self.selection.lights);
        let project = self.edit(NEW_STEP);
        // Through the project, so that the deleted objects' animation tracks go too.
        project.remove_particles(&particles);
        project.remove_lights(&lights);
        n
    }

    /// Copies the selection, offset by `offset`, and selects the copies.
    pub fn duplicate_selection(&mut self, offset: Vec3) -> usize {
        if self.selection.is_empty() {
            return 0;
        }
        let sel = self.selection.clone();
        let project = self.edit(NEW_STEP);
        let (np, nl) = (project.particles.len(), project.lights.len());
        for &i in &sel.particles {
            if let Some(p) = project.particles.get(i).cloned() {
                let id = project.new_particle_id();
                project.particles.push(Particle { id, center: p.center + offset, ..p });
            }
        }
        for &i in &sel.lights {
            if let Some(l) = project.lights.get(i).cloned() {
                let id = project.new_light_id();
                project.lights.push(Light { id, position: l.position + offset, ..l });
            }
        }
        let (np2, nl2) = (project.particles.len(), project.lights.len());
        self.selection.particles = (np..np2).collect();
        self.selection.lights = (nl..nl2).collect();
        self.selection.len()
    }

    pub fn select_all(&mut self) {
        self.selection.particles = (0..self.project.particles.len()).collect();
        self.selection.lights = (0..self.project.lights.len()).collect();
    }

    /// Adds a light and selects it alone.
    pub fn add_light(&mut self, light: Light) -> usize {
        self.add_light_tagged(NEW_STEP, light)
    }

    /// Like [`Self::add_light`], as part of the edit `tag` (adding and placing a light by
    /// dragging is one undo step).
    pub fn add_light_tagged(&mut self, tag: EditTag, mut light: Light) -> usize {
        let project = self.edit(tag);
        light.id = project.new_light_id();
        project.lights.push(light);
        let i = project.lights.len() - 1;
        self.selection.clear();
        self.selection.lights.insert(i);
        i
    }

    /// Centre of the selected items, if any.
    pub fn selection_center(&self) -> Option<Vec3> {
        let p = &self.project;
        let points: Vec<Vec3> = self
            .selection
            .particles
            .iter()
            .filter_map(|&i| p.particles.get(i).map(|q| q.center))
            .chain(self.selection.lights.iter().filter_map(|&i| p.lights.get(i).map(|l| p.light_anchor(l))))
            .collect();
        if points.is_empty() {
            None
        } else {
            Some(points.iter().copied().sum::<Vec3>() / points.len() as f32)
        }
    }

    /// Replaces the whole project (File → New, Open, Revert): history and selection reset.
    pub fn replace(&mut self, project: Project, path: Option<PathBuf>, name: &str) {
        *self = Session::new(project, path, name);
    }
}

/// An undo step in words, from the objects whose ids appear, disappear or change between
/// `before` and `after`, and the settings that change.
pub fn describe_change(before: &Project, after: &Project) -> String {
    describe(before, after, &before.particles, &after.particles)
}

/// [`describe_change`] with the particles that differ given apart (the projects' own
/// particles are not read): those of `before`, then those of `after`.
fn describe(before: &Project, after: &Project, before_particles: &[Particle], after_particles: &[Particle]) -> String {
    use std::collections::HashMap;
    fn ids_text(kind: &str, ids: &[u32]) -> String {
        let mut ids = ids.to_vec();
        ids.sort_unstable();
        let shown: Vec<String> = ids.iter().take(3).map(|i| format!("#{i}")).collect();
        let more = if ids.len() > 3 { format!(" and {} more", ids.len() - 3) } else { String::new() };
        let plural = if ids.len() > 1 { "s" } else { "" };
        format!("{kind}{plural} {}{more}", shown.join(", "))
    }
    fn diff<T: PartialEq>(a: &[T], b: &[T], id: impl Fn(&T) -> u32) -> [Vec<u32>; 3] {
        let old: HashMap<u32, &T> = a.iter().map(|x| (id(x), x)).collect();
        let new: HashMap<u32, &T> = b.iter().map(|x| (id(x), x)).collect();
        let added = b.iter().map(&id).filter(|i| !old.contains_key(i)).collect();
        let removed = a.iter().map(&id).filter(|i| !new.contains_key(i)).collect();
        let changed = b.iter().filter(|x| old.get(&id(x)).is_some_and(|o| *o != *x)).map(&id).collect();
        [added, removed, changed]
    }
    let particles = diff(before_particles, after_particles, |p| p.id);
    let lights = diff(&before.lights, &after.lights, |l| l.id);
    let mut parts = Vec::new();
    for (verb, k) in [("Add", 0), ("Delete", 1), ("Change", 2)] {
        let mut objects = Vec::new();
        if !particles[k].is_empty() {
            objects.push(ids_text("Particle", &particles[k]));
        }
        if !lights[k].is_empty() {
            objects.push(ids_text("Light", &lights[k]));
        }
        if !objects.is_empty() {
            parts.push(format!("{verb} {}", objects.join(" and ")));
        }
    }
    let settings = [
        ("grid", before.grid != after.grid),
        ("medium", before.medium != after.medium),
        ("base volume", before.base_volume != after.base_volume),
        ("render settings", before.render != after.render),
        ("propagation", before.propagation != after.propagation),
        ("surfaces", before.surfaces != after.surfaces),
    ];
    let changed: Vec<&str> = settings.iter().filter(|(_, c)| *c).map(|(n, _)| *n).collect();
    if !changed.is_empty() {
        parts.push(format!("Change {}", changed.join(", ")));
    }
    if parts.is_empty() {
        "Edit".into()
    } else {
        parts.join("; ")
    }
}

/// Indices of `kept` after the items in `removed` were deleted from the list.
fn remap_after_removal(kept: &BTreeSet<usize>, removed: &BTreeSet<usize>) -> BTreeSet<usize> {
    kept.iter().filter(|i| !removed.contains(i)).map(|&i| i - removed.range(..i).count()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn session() -> Session {
        let p = Project {
            particles: (0..4).map(|i| Particle::new(Vec3::new(i as f32, 1.0, 0.0), 0.2, 1.0)).collect(),
            ..Project::default()
        };
        Session::new(p, Some(PathBuf::from("/tmp/x.ron")), "x")
    }

    #[test]
    fn a_stroke_is_one_undo_step() {
        let mut s = session();
        assert!(!s.is_dirty());
        let tag = s.new_tag();
        for _ in 0..5 {
            s.add_particles(tag, [Particle::new(Vec3::ONE, 0.1, 1.0)]);
        }
        s.end_edit();
        assert_eq!(s.project().particles.len(), 9);
        assert!(s.is_dirty());
        assert!(s.undo());
        assert_eq!(s.project().particles.len(), 4);
        assert!(!s.is_dirty(), "undoing back to the saved state is clean");
        assert!(!s.undo());
        assert!(s.redo());
        assert_eq!(s.project().particles.len(), 9);
    }

    #[test]
    fn undo_keeps_the_camera() {
        let mut s = session();
        s.add_particles(NEW_STEP, [Particle::new(Vec3::ONE, 0.1, 1.0)]);
        let mut cam = s.project().camera;
        cam.position.x += 1.0;
        s.set_camera(cam);
        s.undo();
        assert_eq!(s.project().camera, cam);
    }

    #[test]
    fn erasing_remaps_the_selection() {
        let mut s = session();
        s.selection.particles = [0, 3].into();
        let n = s.erase_along_ray(NEW_STEP, Vec3::new(1.0, 1.0, 5.0), Vec3::NEG_Z, 0.1);
        assert_eq!(n, 1);
        assert_eq!(s.selection.particles, [0, 2].into());
        assert_eq!(s.project().particles[2].center.x, 3.0);
    }

    #[test]
    fn delete_duplicate_select_all() {
        let mut s = session();
        s.selection.particles = [1].into();
        assert_eq!(s.duplicate_selection(Vec3::X), 1);
        assert_eq!(s.project().particles.len(), 5);
        assert_eq!(s.selection.particles, [4].into());
        s.select_all();
        assert_eq!(s.delete_selection(), 5);
        assert!(s.project().particles.is_empty());
        s.undo();
        assert_eq!(s.project().particles.len(), 5);
    }

    #[test]
    fn undo_labels_name_ids() {
        let mut s = session();
        s.selection.particles = [1, 2].into();
        s.delete_selection();
        assert_eq!(s.undo_label().unwrap(), "Delete Particles #1, #2");
        s.selection.particles = [1].into();
        s.translate_selection(NEW_STEP, Vec3::X);
        assert_eq!(s.undo_label().unwrap(), "Change Particle #3", "list position 1 is now the particle with id 3");
        s.add_particles(NEW_STEP, [Particle::new(Vec3::ONE, 0.1, 1.0)]);
        assert_eq!(s.undo_label().unwrap(), "Add Particle #4");
        s.undo();
        assert_eq!(s.redo_label().unwrap(), "Add Particle #4");
    }

    #[test]
    fn scaling_changes_radius_or_density() {
        let mut s = session();
        let t: BTreeSet<usize> = [0, 2].into();
        s.scale_particles(NEW_STEP, &t, 2.0, false);
        s.scale_particles(NEW_STEP, &t, 3.0, true);
        let p = &s.project().particles;
        assert!((p[0].radius - 0.4).abs() < 1e-6 && (p[0].density - 3.0).abs() < 1e-6);
        assert_eq!(p[1].radius, 0.2);
    }
}

//! The editing session: the project being edited, the file it came from and whether it has
//! unsaved changes, and the commands, the named edits every panel, tool and menu makes.
//!
//! The session composes the [`Selection`], the undo [`History`] and, in an animated
//! project, the [`Pose`] at the current frame: every command records its undo step through
//! the history, and then lets the pose key what it changed (see `pose`).
//!
//! Nothing here draws or touches the GPU, so every edit the editor can make is testable
//! without a window.

use super::history::{History, Snapshot};
use super::pose::{self, Pose};
use super::selection::remap_after_removal;
use crate::scene::animation::{Animation, Channel, Interp, KeyValue, Object};
use crate::scene::{
    Camera, GridSpec, Light, LightKindChoice, Medium, Noise, Particle, Project, PropagationSettings, RenderSettings,
};
use glam::Vec3;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::{Path, PathBuf};

pub use super::history::{describe_change, EditTag, NEW_STEP};
pub use super::selection::Selection;

/// One state of the project under edit, for keying what is derived from it (the preview,
/// read-backs, recovery files). `epoch` counts whole-project replacements (new, open,
/// restore), kept by the editor; `generation` is [`Session::generation`] or
/// [`Session::content_generation`] within one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Version {
    pub epoch: u64,
    pub generation: u64,
}

/// The project under edit plus its history and file state.
pub struct Session {
    project: Project,
    pub selection: Selection,
    history: History,
    pose: Pose,
    path: Option<PathBuf>,
    name: String,
    generation: u64,
    content_generation: u64,
    next_generation: u64,
    saved_generation: Option<u64>,
    /// Edits of animated values set a key at the current frame.
    pub auto_key: bool,
    /// The content generations since which the particles only grew at the end, each with
    /// how many there were then, oldest first (see [`Session::appended_since`]).
    appends: VecDeque<(u64, usize)>,
}

/// Most content generations [`Session::appended_since`] answers for.
const APPENDS_KEPT: usize = 256;

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
        let mut pose = Pose::new(&project);
        pose.apply(&mut project);
        Self {
            project,
            selection: Selection::default(),
            history: History::default(),
            pose,
            path,
            name,
            generation: 1,
            content_generation: 1,
            next_generation: 2,
            saved_generation: Some(1),
            auto_key: false,
            appends: VecDeque::new(),
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

    /// When every change since content generation `generation` only appended particles (a
    /// paint stroke), how many there were then: what a view derived from the particles
    /// needs to bring itself up to date with the new ones alone. None otherwise, or when
    /// `generation` is too old to say.
    pub fn appended_since(&self, generation: u64) -> Option<usize> {
        if generation == self.content_generation {
            return Some(self.project.particles.len());
        }
        self.appends.iter().find(|(g, _)| *g == generation).map(|&(_, n)| n)
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

    // ---- the undo history ----

    /// A fresh tag for a multi-event edit such as a brush stroke.
    pub fn new_tag(&mut self) -> EditTag {
        self.history.new_tag()
    }

    /// Takes back the coalesced edit `tag` if it is the one in progress, leaving no undo or
    /// redo step behind (a cancelled drag).
    pub fn cancel_edit(&mut self, tag: EditTag) {
        if let Some(s) = self.history.take_open(tag) {
            self.swap_in(s);
        }
        self.history.end(&self.project.particles);
    }

    /// Whether a coalesced edit (a stroke, a drag) is in progress.
    pub fn edit_in_progress(&self) -> bool {
        self.history.in_progress()
    }

    /// Ends the current coalesced edit: the next edit starts a new undo step.
    pub fn end_edit(&mut self) {
        self.history.end(&self.project.particles);
    }

    /// Particles held by the undo and redo steps (a step holds what it changed).
    pub fn history_particles(&self) -> usize {
        self.history.held()
    }

    /// Mutable access for an edit. A new undo step is recorded unless `tag` continues the
    /// edit in progress. The editor's own edits go through the named commands; this is
    /// the door for edits the commands do not name.
    pub fn edit(&mut self, tag: EditTag) -> &mut Project {
        self.edit_as(tag, false)
    }

    /// [`Self::edit`]; `append`: the edit only adds particles at the end of the list.
    fn edit_as(&mut self, tag: EditTag, append: bool) -> &mut Project {
        // Earlier edits' keys belong to their own step, before this one's snapshot.
        self.sync_keys();
        if append {
            if self.appends.len() == APPENDS_KEPT {
                self.appends.pop_front();
            }
            self.appends.push_back((self.content_generation, self.project.particles.len()));
        } else {
            self.appends.clear();
        }
        self.history.begin(tag, &self.project, &self.selection, self.generation);
        self.generation = self.next_generation;
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        &mut self.project
    }

    pub fn can_undo(&self) -> bool {
        self.history.can_undo()
    }
    pub fn can_redo(&self) -> bool {
        self.history.can_redo()
    }
    pub fn undo_len(&self) -> usize {
        self.history.undo_len()
    }

    /// What Undo would take back, named by ids ("Delete Particle #24"); None with nothing to undo.
    pub fn undo_label(&self) -> Option<String> {
        self.history.undo_label(&self.project)
    }

    /// What Redo would bring back.
    pub fn redo_label(&self) -> Option<String> {
        self.history.redo_label(&self.project)
    }

    /// Restores the state before the last edit; the camera stays where the user put it.
    pub fn undo(&mut self) -> bool {
        self.sync_keys();
        let Some(s) = self.history.pop_undo() else { return false };
        let current = self.swap_in(s);
        self.history.undone(current);
        true
    }

    pub fn redo(&mut self) -> bool {
        self.sync_keys();
        let Some(s) = self.history.pop_redo() else { return false };
        let current = self.swap_in(s);
        self.history.redone(current);
        true
    }

    fn swap_in(&mut self, mut s: Snapshot) -> Snapshot {
        s.project.camera = self.project.camera;
        s.project.particles = std::mem::take(&mut self.project.particles);
        let particles = s.particles.restore(&mut s.project.particles);
        let project = std::mem::replace(&mut self.project, s.project);
        let selection = std::mem::replace(&mut self.selection, s.selection);
        let generation = std::mem::replace(&mut self.generation, s.generation);
        self.appends.clear();
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        self.selection.keep_within(self.project.particles.len(), self.project.lights.len());
        // The snapshot was posed at the frame of its time, and may be animated or not.
        self.pose.refit(&mut self.project);
        if self.project.animation.is_some() {
            self.bump_view_generation();
        }
        Snapshot { project, particles, selection, generation }
    }

    // ---- time: the current frame, posing and keys ----

    /// The frame on show.
    pub fn frame(&self) -> i32 {
        self.pose.frame()
    }

    /// Shows `frame` (clamped to the animation's range): animated values take their values
    /// there and unkeyed edits are dropped. Not an edit: no undo step, and a saved project
    /// stays saved. Returns the unkeyed edits dropped.
    pub fn set_frame(&mut self, frame: i32) -> Vec<Channel> {
        self.sync_keys();
        let Some(dropped) = self.pose.show(&mut self.project, frame) else { return Vec::new() };
        self.bump_view_generation();
        dropped
    }

    /// Animated values changed on this frame without a key (see `pose`).
    pub fn unkeyed(&self) -> &BTreeMap<Channel, KeyValue> {
        self.pose.unkeyed()
    }

    /// The still project on show: [`Project::at_frame`] of the current frame with the
    /// unkeyed edits applied (the project itself when it is not animated).
    pub fn frame_still(&self) -> Project {
        self.pose.still(&self.project)
    }

    /// A new generation for a change of what is shown (the frame), not of the document:
    /// a saved document stays saved.
    fn bump_view_generation(&mut self) {
        self.appends.clear();
        let was_saved = self.saved_generation == Some(self.generation);
        self.generation = self.next_generation;
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        if was_saved {
            self.saved_generation = Some(self.generation);
        }
    }

    /// Completes the edits since the last call (see [`Pose::sync_keys`]). Part of the
    /// edit's undo step; the editor calls it once per frame and every edit and frame
    /// change calls it.
    pub fn sync_keys(&mut self) {
        self.pose.sync_keys(&mut self.project, self.auto_key);
    }

    /// The objects selected, as the animation names them.
    pub fn selected_objects(&self) -> Vec<Object> {
        let p = &self.project;
        let particles =
            self.selection.particles.iter().filter_map(|&i| p.particles.get(i)).map(|q| Object::Particle(q.id));
        let lights = self.selection.lights.iter().filter_map(|&i| p.lights.get(i)).map(|l| Object::Light(l.id));
        particles.chain(lights).collect()
    }

    /// Keys `channels` at the current frame with the values on show, as one undo step;
    /// returns how many keys were set. A still project becomes an animation.
    pub fn key_channels(&mut self, channels: &[Channel]) -> usize {
        self.sync_keys();
        let frame = self.frame();
        let values = self.pose.keys_to_set(&self.project, channels);
        if values.is_empty() {
            return 0;
        }
        let project = self.edit(NEW_STEP);
        let n = values.iter().filter(|(c, v, i)| project.set_key(*c, frame, *v, *i).is_ok()).count();
        for (c, _, _) in &values {
            self.pose.keyed(*c);
        }
        n
    }

    /// K: keys every animatable value of the selection at the current frame.
    pub fn key_selection(&mut self) -> usize {
        let channels: Vec<Channel> =
            self.selected_objects().into_iter().flat_map(|o| self.project.animatable(o)).collect();
        self.key_channels(&channels)
    }

    /// The Inspector's diamond: removes the key of `channel` at the current frame if it has
    /// one, else keys it there. One undo step.
    pub fn toggle_key(&mut self, channel: Channel) {
        self.sync_keys();
        let frame = self.frame();
        if self.project.has_key(channel, frame) {
            self.edit(NEW_STEP).remove_key(channel, frame);
            self.pose.repose_channel(&mut self.project, channel);
        } else {
            self.key_channels(&[channel]);
        }
    }

    /// The keys of `objects` at `frame` (every animated value of theirs keyed there).
    pub fn keys_at(&self, objects: &[Object], frame: i32) -> Vec<Channel> {
        pose::keys_at(&self.project, objects, frame)
    }

    /// Deletes the keys of `objects` at `frame`, as one undo step; returns how many went.
    pub fn delete_keys(&mut self, objects: &[Object], frame: i32) -> usize {
        self.sync_keys();
        let channels = self.keys_at(objects, frame);
        if channels.is_empty() {
            return 0;
        }
        let project = self.edit(NEW_STEP);
        let n = channels.iter().filter(|&&c| project.remove_key(c, frame)).count();
        self.pose.repose_objects(&mut self.project, objects);
        n
    }

    /// Moves the keys of `objects` at `from` to `to`, as one undo step (continued by `tag`
    /// while a drag goes on). Refused, with the reason, when one of those values already
    /// has a key at `to`.
    pub fn move_keys(&mut self, tag: EditTag, objects: &[Object], from: i32, to: i32) -> Result<usize, String> {
        self.sync_keys();
        let channels = self.keys_at(objects, from);
        if from == to || channels.is_empty() {
            return Ok(0);
        }
        if let Some(c) = channels.iter().find(|&&c| self.project.has_key(c, to)) {
            return Err(format!("{c} already has a key at frame {to}: delete it first or pick another frame"));
        }
        let project = self.edit(tag);
        for &c in &channels {
            project.move_key(c, from, to).map_err(|e| e.to_string())?;
        }
        self.pose.repose_objects(&mut self.project, objects);
        Ok(channels.len())
    }

    /// Sets the interpolation of the keys of `objects` at `frame` (towards each next key),
    /// as one undo step; returns how many keys changed.
    pub fn set_interp(&mut self, objects: &[Object], frame: i32, interp: Interp) -> usize {
        self.sync_keys();
        let channels = self.keys_at(objects, frame);
        let differs = |p: &Project, c: Channel| {
            p.track(c).and_then(|t| t.keys.iter().find(|k| k.frame == frame)).is_some_and(|k| k.interp != interp)
        };
        if !channels.iter().any(|&c| differs(&self.project, c)) {
            return 0;
        }
        let project = self.edit(NEW_STEP);
        let mut n = 0;
        for t in project.tracks.iter_mut().filter(|t| channels.contains(&t.on)) {
            for k in t.keys.iter_mut().filter(|k| k.frame == frame && k.interp != interp) {
                k.interp = interp;
                n += 1;
            }
        }
        self.pose.repose_objects(&mut self.project, objects);
        n
    }

    /// Makes a still project an animation of `animation`'s frames (one undo step) and shows
    /// its first frame.
    pub fn animate(&mut self, animation: Animation) {
        if self.project.animation.is_some() {
            return;
        }
        self.edit(NEW_STEP).animation = Some(animation);
        self.pose.jump(animation.start);
    }

    /// Changes the frame range or rate (one undo step per `tag`), keeping the current frame
    /// within the range.
    pub fn set_animation(&mut self, tag: EditTag, animation: Animation) {
        if self.project.animation == Some(animation)
            || animation.fps.is_nan()
            || animation.fps <= 0.0
            || animation.start > animation.end
        {
            return;
        }
        self.edit(tag).animation = Some(animation);
        self.pose.clamp_to(&mut self.project, animation);
    }

    /// Changes the view camera: saved with the project but not an undo step, like a view
    /// change in other editors.
    ///
    /// Moving the view is not an edit, so an animated camera is never keyed by it: the
    /// changed camera values are unkeyed edits (K or the Inspector's diamonds key them).
    pub fn set_camera(&mut self, camera: crate::scene::Camera) {
        if camera != self.project.camera {
            self.sync_keys();
            self.project.camera = camera;
            self.generation = self.next_generation;
            self.next_generation += 1;
            self.pose.note_camera(&self.project);
        }
    }

    // ---- edits used by tools, menus and panels ----

    /// Appends particles (one undo step per `tag`) and returns how many there are now.
    pub fn add_particles(&mut self, tag: EditTag, particles: impl IntoIterator<Item = Particle>) -> usize {
        let p = self.edit_as(tag, true);
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

    /// Changes particle `i` with `change` (one undo step per `tag`).
    pub fn edit_particle(&mut self, tag: EditTag, i: usize, change: impl FnOnce(&mut Particle)) {
        if let Some(q) = self.edit(tag).particles.get_mut(i) {
            change(q);
        }
    }

    /// Changes each of the particles `indices` with `change`, as one undo step.
    pub fn edit_particles(&mut self, indices: &[usize], change: impl Fn(&mut Particle)) {
        let project = self.edit(NEW_STEP);
        for &i in indices {
            if let Some(q) = project.particles.get_mut(i) {
                change(q);
            }
        }
    }

    /// Changes light `i` with `change` (one undo step per `tag`).
    pub fn edit_light(&mut self, tag: EditTag, i: usize, change: impl FnOnce(&mut Light)) {
        if let Some(q) = self.edit(tag).lights.get_mut(i) {
            change(q);
        }
    }

    /// Turns light `i` into another kind as [`Project::light_as_kind`] makes it (part of the
    /// edit `tag`); nothing happens when it cannot be.
    pub fn set_light_kind(&mut self, tag: EditTag, i: usize, kind: LightKindChoice) {
        if let Some(light) = self.project.light_as_kind(i, kind) {
            self.edit(tag).replace_light(i, light);
        }
    }

    /// Moves light `i`'s anchor by `delta` (see [`Project::move_light`]).
    pub fn move_light(&mut self, tag: EditTag, i: usize, delta: Vec3) {
        self.edit(tag).move_light(i, delta);
    }

    /// Aims spot or sun `i` at `target` (see [`Project::aim_spot`]).
    pub fn aim_spot(&mut self, tag: EditTag, i: usize, target: Vec3) {
        self.edit(tag).aim_spot(i, target);
    }

    /// Changes the medium with `change` (one undo step per `tag`).
    pub fn edit_medium(&mut self, tag: EditTag, change: impl FnOnce(&mut Medium)) {
        change(&mut self.edit(tag).medium);
    }

    /// Changes the medium's noise, when it has one, with `change`.
    pub fn edit_noise(&mut self, tag: EditTag, change: impl FnOnce(&mut Noise)) {
        if let Some(n) = self.edit(tag).medium.noise.as_mut() {
            change(n);
        }
    }

    /// Turns the medium's noise on (with `noise`) or off, as one undo step; the noise's
    /// animation goes with it.
    pub fn set_noise(&mut self, noise: Option<Noise>) {
        let project = self.edit(NEW_STEP);
        project.medium.noise = noise;
        project.drop_inapplicable_tracks();
    }

    /// Changes the grid box with `change` (one undo step per `tag`).
    pub fn edit_grid(&mut self, tag: EditTag, change: impl FnOnce(&mut GridSpec)) {
        change(&mut self.edit(tag).grid);
    }

    /// Changes the render settings with `change` (one undo step per `tag`).
    pub fn edit_render(&mut self, tag: EditTag, change: impl FnOnce(&mut RenderSettings)) {
        change(&mut self.edit(tag).render);
    }

    /// Sets the tone-mapping exposure (one undo step per `tag`).
    pub fn set_exposure(&mut self, tag: EditTag, exposure: f32) {
        self.edit_render(tag, |r| r.exposure = exposure);
    }

    /// Changes the camera with `change` as an undo step, as the Inspector's numbers do
    /// (moving the view is [`Self::set_camera`], which is none).
    pub fn edit_camera(&mut self, tag: EditTag, change: impl FnOnce(&mut Camera)) {
        change(&mut self.edit(tag).camera);
    }

    /// Changes the propagation settings with `change` (one undo step per `tag`).
    pub fn edit_propagation(&mut self, tag: EditTag, change: impl FnOnce(&mut PropagationSettings)) {
        change(&mut self.edit(tag).propagation);
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
    /// Auto-key stays as it was: it is the artist's mode of work, not the project's.
    pub fn replace(&mut self, project: Project, path: Option<PathBuf>, name: &str) {
        let auto_key = self.auto_key;
        *self = Session::new(project, path, name);
        self.auto_key = auto_key;
    }
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
    fn appended_since_follows_a_stroke_until_another_edit() {
        let mut s = session();
        let g0 = s.content_generation();
        assert_eq!(s.appended_since(g0), Some(4));
        let tag = s.new_tag();
        s.add_particles(tag, [Particle::new(Vec3::ONE, 0.1, 1.0)]);
        let g1 = s.content_generation();
        s.add_particles(tag, [Particle::new(Vec3::ONE, 0.1, 1.0), Particle::new(Vec3::ONE, 0.1, 1.0)]);
        assert_eq!((s.appended_since(g0), s.appended_since(g1)), (Some(4), Some(5)));
        s.end_edit();
        let g2 = s.content_generation();
        s.scale_particles(NEW_STEP, &[0].into(), 2.0, false);
        assert_eq!((s.appended_since(g0), s.appended_since(g2)), (None, None), "a change in place");
        let g3 = s.content_generation();
        s.add_particles(NEW_STEP, [Particle::new(Vec3::ONE, 0.1, 1.0)]);
        assert_eq!(s.appended_since(g3), Some(7));
        s.undo();
        assert_eq!(s.appended_since(g3), None, "undo replaces the list");
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

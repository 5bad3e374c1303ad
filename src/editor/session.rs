//! The editing session: the project being edited, the selection, undo/redo history, the file
//! it came from and whether it has unsaved changes; in an animated project also the current
//! frame and the keying that edits do there.
//!
//! An animated project is held *posed*: the still fields of every animated value hold that
//! value at the current frame (what [`Project::at_frame`] would give), so that every view
//! and edit sees the frame on show. [`Project::at_frame`] ignores those fields, so posing
//! never changes what the file means. After an edit, [`Session::sync_keys`] turns a changed
//! animated value into a key at the current frame when auto-key is on or the value has a key
//! there; otherwise the value stays changed on this frame only, an *unkeyed edit*
//! ([`Session::unkeyed`]) that the preview shows and the panels warn about, until it is keyed
//! or the frame changes (then, as in Blender, the value goes back to its keys). Values that
//! are not animated are edited as in a still.
//!
//! Nothing here draws or touches the GPU, so every edit the editor can make is testable
//! without a window. Undo keeps each step's project without its particles, and the particles
//! as what the step changed (see `history`), so a step costs what it touched however large
//! the scene; the history is bounded by step count and by total particles held.

use super::history::Stored;
use crate::scene::animation::{Animation, Channel, Interp, KeyValue, Object};
use crate::scene::{Light, Particle, Project};
use glam::Vec3;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
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
    /// The frame on show (meaningful in an animated project).
    frame: i32,
    /// Edits of animated values set a key at the current frame.
    pub auto_key: bool,
    /// Animated values changed on this frame without a key, with their changed values.
    unkeyed: BTreeMap<Channel, KeyValue>,
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
        let frame = project.animation.map_or(Animation::default().start, |a| a.start);
        let mut session = Self {
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
            frame,
            auto_key: false,
            unkeyed: BTreeMap::new(),
            appends: VecDeque::new(),
        };
        session.pose();
        session
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
    ///
    /// Moving the view is not an edit, so an animated camera is never keyed by it: the
    /// changed camera values are unkeyed edits (K or the Inspector's diamonds key them).
    pub fn set_camera(&mut self, camera: crate::scene::Camera) {
        if camera != self.project.camera {
            self.sync_keys();
            self.project.camera = camera;
            self.generation = self.next_generation;
            self.next_generation += 1;
            for c in self.project.animatable(Object::Camera) {
                let Some(track) = self.project.track(c) else { continue };
                match self.project.value_of(c) {
                    Some(v) if Some(v) != track.sample(self.frame) => {
                        self.unkeyed.insert(c, v);
                    }
                    _ => {
                        self.unkeyed.remove(&c);
                    }
                }
            }
        }
    }

    // ---- time: the current frame, posing and keys ----

    /// The frame on show.
    pub fn frame(&self) -> i32 {
        self.frame
    }

    /// Shows `frame` (clamped to the animation's range): animated values take their values
    /// there and unkeyed edits are dropped. Not an edit: no undo step, and a saved project
    /// stays saved. Returns the unkeyed edits dropped.
    pub fn set_frame(&mut self, frame: i32) -> Vec<Channel> {
        self.sync_keys();
        let frame = match self.project.animation {
            Some(a) => frame.clamp(a.start, a.end.max(a.start)),
            None => frame,
        };
        if frame == self.frame {
            return Vec::new();
        }
        let dropped: Vec<Channel> = self.unkeyed.keys().copied().collect();
        self.frame = frame;
        self.pose();
        self.bump_view_generation();
        dropped
    }

    /// Animated values changed on this frame without a key (see the module doc).
    pub fn unkeyed(&self) -> &BTreeMap<Channel, KeyValue> {
        &self.unkeyed
    }

    /// The still project on show: [`Project::at_frame`] of the current frame with the
    /// unkeyed edits applied (the project itself when it is not animated).
    pub fn frame_still(&self) -> Project {
        let mut still = self.project.at_frame(self.frame);
        for (&c, &v) in &self.unkeyed {
            still.apply(c, v);
        }
        still
    }

    /// Writes every animated value at the current frame into its still field and drops
    /// unkeyed edits.
    fn pose(&mut self) {
        self.unkeyed.clear();
        if self.project.animation.is_none() {
            return;
        }
        let frame = self.frame;
        let values: Vec<(Channel, KeyValue)> =
            self.project.tracks.iter().filter_map(|t| t.sample(frame).map(|v| (t.on, v))).collect();
        for (c, v) in values {
            self.project.apply(c, v);
        }
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

    /// Completes the edits since the last call: every animated value whose still field no
    /// longer holds its value at this frame was edited; it is keyed at this frame when
    /// auto-key is on or it has a key here (keeping that key's interpolation, or taking the
    /// one of the key before), and is an unkeyed edit otherwise. Part of the edit's undo
    /// step; the editor calls it once per frame and every edit and frame change calls it.
    pub fn sync_keys(&mut self) {
        let project = &self.project;
        self.unkeyed.retain(|c, _| project.is_animated(*c));
        let frame = self.frame;
        let mut changed = Vec::new();
        for t in &self.project.tracks {
            let Some(now) = self.project.value_of(t.on) else { continue };
            let expected = self.unkeyed.get(&t.on).copied().or_else(|| t.sample(frame));
            if Some(now) != expected {
                let interp = t.keys.iter().take_while(|k| k.frame <= frame).last().map_or(Interp::Linear, |k| k.interp);
                changed.push((t.on, now, interp));
            }
        }
        for (c, v, interp) in changed {
            if self.auto_key || self.project.has_key(c, frame) {
                if self.project.set_key(c, frame, v, interp).is_ok() {
                    self.unkeyed.remove(&c);
                }
            } else {
                self.unkeyed.insert(c, v);
            }
        }
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
        let frame = self.frame;
        let values: Vec<(Channel, KeyValue, Interp)> = channels
            .iter()
            .filter_map(|&c| {
                let v = self.project.value_of(c)?;
                let interp = self
                    .project
                    .track(c)
                    .and_then(|t| t.keys.iter().take_while(|k| k.frame <= frame).last())
                    .map_or(Interp::Linear, |k| k.interp);
                Some((c, v, interp))
            })
            .collect();
        if values.is_empty() {
            return 0;
        }
        let project = self.edit(NEW_STEP);
        let n = values.iter().filter(|(c, v, i)| project.set_key(*c, frame, *v, *i).is_ok()).count();
        for (c, _, _) in &values {
            self.unkeyed.remove(c);
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
        let frame = self.frame;
        if self.project.has_key(channel, frame) {
            self.edit(NEW_STEP).remove_key(channel, frame);
            self.pose_channel(channel);
        } else {
            self.key_channels(&[channel]);
        }
    }

    /// Re-poses one value after its keys changed (its still field shows the keys again).
    fn pose_channel(&mut self, channel: Channel) {
        self.unkeyed.remove(&channel);
        if let Some(v) = self.project.track(channel).and_then(|t| t.sample(self.frame)) {
            self.project.apply(channel, v);
        }
    }

    fn pose_objects(&mut self, objects: &[Object]) {
        let channels: Vec<Channel> =
            self.project.tracks.iter().map(|t| t.on).filter(|c| objects.contains(&c.0)).collect();
        for c in channels {
            self.pose_channel(c);
        }
    }

    /// The keys of `objects` at `frame` (every animated value of theirs keyed there).
    pub fn keys_at(&self, objects: &[Object], frame: i32) -> Vec<Channel> {
        self.project
            .tracks
            .iter()
            .filter(|t| objects.contains(&t.on.0) && t.keys.iter().any(|k| k.frame == frame))
            .map(|t| t.on)
            .collect()
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
        self.pose_objects(objects);
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
        self.pose_objects(objects);
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
        self.pose_objects(objects);
        n
    }

    /// Makes a still project an animation of `animation`'s frames (one undo step) and shows
    /// its first frame.
    pub fn animate(&mut self, animation: Animation) {
        if self.project.animation.is_some() {
            return;
        }
        self.edit(NEW_STEP).animation = Some(animation);
        self.frame = animation.start;
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
        let frame = self.frame.clamp(animation.start, animation.end);
        if frame != self.frame {
            self.frame = frame;
            self.pose();
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
        self.sync_keys();
        let Some(s) = self.undo.pop() else { return false };
        let current = self.swap_in(s);
        self.redo.push(current);
        true
    }

    pub fn redo(&mut self) -> bool {
        self.sync_keys();
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
        self.appends.clear();
        self.content_generation = self.next_generation;
        self.next_generation += 1;
        self.sanitize_selection();
        // The snapshot was posed at the frame of its time, and may be animated or not.
        if let Some(a) = self.project.animation {
            self.frame = self.frame.clamp(a.start, a.end.max(a.start));
        }
        self.pose();
        if self.project.animation.is_some() {
            self.bump_view_generation();
        }
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
    let mut particles = diff(before_particles, after_particles, |p| p.id);
    let mut lights = diff(&before.lights, &after.lights, |l| l.id);
    let (keys, keyed) = describe_keys(before, after);
    // A keyed value's change is the key's.
    particles[2].retain(|id| !keyed.contains(&Object::Particle(*id)));
    lights[2].retain(|id| !keyed.contains(&Object::Light(*id)));
    let mut parts = keys;
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
        ("medium", before.medium != after.medium && !keyed.contains(&Object::Medium)),
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

/// The changes of the frame range and of keys between `before` and `after` in words ("Key
/// Particle #3 at frame 12", "Move keys of Light #1 from frame 12 to 20"), and the objects
/// whose keys changed.
fn describe_keys(before: &Project, after: &Project) -> (Vec<String>, BTreeSet<Object>) {
    use crate::scene::animation::Key;
    let mut parts = Vec::new();
    match (before.animation, after.animation) {
        (None, Some(a)) => parts.push(format!("Animate (frames {}–{} at {} fps)", a.start, a.end, a.fps)),
        (Some(_), None) => parts.push("Remove the animation".to_string()),
        (Some(a), Some(b)) if a != b => {
            if (a.start, a.end) != (b.start, b.end) {
                parts.push(format!("Frame range {}–{}", b.start, b.end));
            }
            if a.fps != b.fps {
                parts.push(format!("Frame rate {} fps", b.fps));
            }
        }
        _ => {}
    }
    let keys_of = |p: &Project| -> BTreeMap<(Channel, i32), Key> {
        p.tracks.iter().flat_map(|t| t.keys.iter().map(move |k| ((t.on, k.frame), *k))).collect()
    };
    let (old, new) = (keys_of(before), keys_of(after));
    // (verb, channel, frame, detail) for every key added, removed, re-valued or re-shaped.
    let added: Vec<(Channel, i32)> = new.keys().filter(|k| !old.contains_key(*k)).copied().collect();
    let removed: Vec<(Channel, i32)> = old.keys().filter(|k| !new.contains_key(*k)).copied().collect();
    let revalued: Vec<(Channel, i32)> =
        new.iter().filter(|(k, v)| old.get(*k).is_some_and(|o| o.value != v.value)).map(|(k, _)| *k).collect();
    let reshaped: Vec<(Channel, i32, Interp)> = new
        .iter()
        .filter(|(k, v)| old.get(*k).is_some_and(|o| o.value == v.value && o.interp != v.interp))
        .map(|(k, v)| (k.0, k.1, v.interp))
        .collect();
    let mut keyed: BTreeSet<Object> = BTreeSet::new();
    for (c, _) in added.iter().chain(&removed).chain(&revalued) {
        keyed.insert(c.0);
    }
    for (c, _, _) in &reshaped {
        keyed.insert(c.0);
    }
    let objects = |keys: &[(Channel, i32)]| -> String {
        let set: BTreeSet<Object> = keys.iter().map(|(c, _)| c.0).collect();
        let names: Vec<String> = set.iter().take(3).map(object_name).collect();
        let more = if set.len() > 3 { format!(" and {} more", set.len() - 3) } else { String::new() };
        format!("{}{more}", names.join(", "))
    };
    let frames = |keys: &[(Channel, i32)]| -> String {
        let set: BTreeSet<i32> = keys.iter().map(|k| k.1).collect();
        match (set.first(), set.last()) {
            (Some(a), Some(b)) if a == b => format!("at frame {a}"),
            (Some(a), Some(b)) => format!("at frames {a}–{b}"),
            _ => String::new(),
        }
    };
    let single = |keys: &[(Channel, i32)]| -> String {
        match keys {
            [(c, _)] => format!("{c}"),
            _ => objects(keys),
        }
    };
    // A move: the same values lose their keys at one frame and gain them at another.
    let from: BTreeSet<i32> = removed.iter().map(|k| k.1).collect();
    let to: BTreeSet<i32> = added.iter().map(|k| k.1).collect();
    let same_channels = {
        let a: BTreeSet<Channel> = removed.iter().map(|k| k.0).collect();
        let b: BTreeSet<Channel> = added.iter().map(|k| k.0).collect();
        a == b && a.len() == removed.len() && b.len() == added.len()
    };
    if from.len() == 1 && to.len() == 1 && same_channels {
        let keys = if added.len() == 1 { "key" } else { "keys" };
        parts.push(format!(
            "Move {keys} of {} from frame {} to {}",
            single(&added),
            from.first().unwrap_or(&0),
            to.first().unwrap_or(&0)
        ));
    } else {
        let mut set = added.clone();
        set.extend(&revalued);
        if !set.is_empty() {
            parts.push(format!("Key {} {}", single(&set), frames(&set)));
        }
        if !removed.is_empty() {
            let keys = if removed.len() == 1 { "key" } else { "keys" };
            parts.push(format!("Delete {keys} of {} {}", single(&removed), frames(&removed)));
        }
    }
    if let Some((_, _, interp)) = reshaped.first() {
        let keys: Vec<(Channel, i32)> = reshaped.iter().map(|(c, f, _)| (*c, *f)).collect();
        parts.push(format!("{interp:?} interpolation on {} {}", single(&keys), frames(&keys)));
    }
    (parts, keyed)
}

fn object_name(o: &Object) -> String {
    match o {
        Object::Particle(id) => format!("Particle #{id}"),
        Object::Light(id) => format!("Light #{id}"),
        Object::Camera => "Camera".into(),
        Object::Medium => "Medium".into(),
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

    /// A session on 4 particles, animated over frames 1–20, particle #0's centre keyed at 1
    /// and 11 (linear), showing frame 6.
    fn animated() -> (Session, Channel) {
        let mut s = session();
        let c = Channel(Object::Particle(0), crate::scene::animation::Prop::Center);
        let mut p = s.project().clone();
        p.animation = Some(Animation { fps: 24.0, start: 1, end: 20 });
        p.set_key(c, 1, KeyValue::Vec3(Vec3::new(0.0, 1.0, 0.0)), Interp::Linear).unwrap();
        p.set_key(c, 11, KeyValue::Vec3(Vec3::new(10.0, 1.0, 0.0)), Interp::Linear).unwrap();
        s.replace(p, None, "anim");
        s.set_frame(6);
        (s, c)
    }

    #[test]
    fn the_project_is_posed_at_the_current_frame_and_its_still_is_at_frame() {
        let (mut s, c) = animated();
        assert_eq!(s.frame(), 6);
        assert_eq!(s.project().particles[0].center, Vec3::new(5.0, 1.0, 0.0), "the still fields show frame 6");
        assert_eq!(s.frame_still(), s.project().at_frame(6));
        assert!(!s.is_dirty(), "changing frame is not an edit");
        assert_eq!(s.set_frame(50), Vec::<Channel>::new());
        assert_eq!(s.frame(), 20, "clamped to the range");
        assert_eq!(s.value_now(c), Some(KeyValue::Vec3(Vec3::new(10.0, 1.0, 0.0))));
        assert_eq!(s.undo_len(), 0);
    }

    impl Session {
        fn value_now(&self, c: Channel) -> Option<KeyValue> {
            self.project.value_of(c)
        }
    }

    #[test]
    fn with_auto_key_an_edit_of_an_animated_value_keys_it_and_undo_takes_it_back() {
        let (mut s, c) = animated();
        s.auto_key = true;
        s.selection.particles = [0, 1].into();
        s.translate_selection(NEW_STEP, Vec3::Y);
        s.sync_keys();
        assert!(s.project().has_key(c, 6), "keyed at frame 6");
        assert_eq!(s.project().track(c).unwrap().sample(6), Some(KeyValue::Vec3(Vec3::new(5.0, 2.0, 0.0))));
        assert!(s.unkeyed().is_empty());
        assert_eq!(s.project().particles[1].center, Vec3::new(1.0, 2.0, 0.0), "an unanimated particle moves as before");
        assert!(s.project().track(Channel(Object::Particle(1), c.1)).is_none(), "and gets no key");
        assert_eq!(s.undo_label().unwrap(), "Key Particle #0 Center at frame 6; Change Particle #1");
        s.undo();
        assert!(!s.project().has_key(c, 6));
        assert_eq!(s.project().particles[0].center, Vec3::new(5.0, 1.0, 0.0));
    }

    #[test]
    fn without_auto_key_an_edit_on_an_unkeyed_frame_lasts_until_the_frame_changes() {
        let (mut s, c) = animated();
        s.selection.particles = [0].into();
        s.translate_selection(NEW_STEP, Vec3::Y);
        s.sync_keys();
        assert!(!s.project().has_key(c, 6));
        assert_eq!(s.unkeyed().get(&c), Some(&KeyValue::Vec3(Vec3::new(5.0, 2.0, 0.0))));
        assert_eq!(s.frame_still().particles[0].center, Vec3::new(5.0, 2.0, 0.0), "the preview shows the edit");
        assert_eq!(s.project().at_frame(6).particles[0].center, Vec3::new(5.0, 1.0, 0.0), "the file does not");
        // K keys the value on show.
        assert_eq!(s.key_selection(), 4);
        assert!(s.unkeyed().is_empty());
        assert_eq!(s.project().at_frame(6).particles[0].center, Vec3::new(5.0, 2.0, 0.0));
        assert_eq!(s.undo_label().unwrap(), "Key Particle #0 at frame 6");
        s.undo();
        s.translate_selection(NEW_STEP, Vec3::Y);
        assert_eq!(s.set_frame(7), vec![c], "changing frame drops the unkeyed edit");
        s.set_frame(6);
        assert_eq!(s.project().particles[0].center, Vec3::new(5.0, 1.0, 0.0), "back to the keys");
        // On a keyed frame an edit replaces the key, auto-key or not.
        s.set_frame(11);
        s.translate_selection(NEW_STEP, Vec3::Z);
        s.sync_keys();
        assert_eq!(s.project().track(c).unwrap().sample(11), Some(KeyValue::Vec3(Vec3::new(10.0, 1.0, 1.0))));
    }

    #[test]
    fn key_edits_are_single_undo_steps_with_labels() {
        let (mut s, c) = animated();
        s.selection.particles = [0].into();
        let objects = s.selected_objects();
        s.toggle_key(c);
        assert!(s.project().has_key(c, 6));
        assert_eq!(s.undo_label().unwrap(), "Key Particle #0 Center at frame 6");
        s.toggle_key(c);
        assert!(!s.project().has_key(c, 6));
        assert_eq!(s.undo_label().unwrap(), "Delete key of Particle #0 Center at frame 6");
        let tag = s.new_tag();
        assert_eq!(s.move_keys(tag, &objects, 11, 14), Ok(1));
        assert_eq!(s.move_keys(tag, &objects, 14, 16), Ok(1));
        s.end_edit();
        assert_eq!(s.project().key_frames(Object::Particle(0)), vec![1, 16]);
        assert_eq!(s.undo_label().unwrap(), "Move key of Particle #0 Center from frame 11 to 16", "a drag is one step");
        assert!(s.move_keys(NEW_STEP, &objects, 16, 1).unwrap_err().contains("already has a key at frame 1"));
        let third = (10.0f64 / 3.0) as f32;
        assert!((s.project().particles[0].center.x - third).abs() < 1e-6, "frame 6 re-posed: a third of the way to 16");
        assert_eq!(s.set_interp(&objects, 1, Interp::Hold), 1);
        assert_eq!(s.project().particles[0].center.x, 0.0, "held");
        assert_eq!(s.undo_label().unwrap(), "Hold interpolation on Particle #0 Center at frame 1");
        assert_eq!(s.delete_keys(&objects, 16), 1);
        assert_eq!(s.undo_label().unwrap(), "Delete key of Particle #0 Center at frame 16");
        s.undo();
        s.undo();
        assert!((s.project().particles[0].center.x - third).abs() < 1e-6, "undo re-poses");
    }

    #[test]
    fn animate_is_an_undoable_step() {
        let mut s = session();
        s.animate(Animation::default());
        assert_eq!(s.project().animation, Some(Animation::default()));
        assert_eq!(s.frame(), 1);
        assert_eq!(s.undo_label().unwrap(), "Animate (frames 1–120 at 24 fps)");
        s.set_animation(NEW_STEP, Animation { fps: 30.0, start: 5, end: 50 });
        assert_eq!(s.frame(), 5, "the frame stays within the range");
        assert_eq!(s.undo_label().unwrap(), "Frame range 5–50; Frame rate 30 fps");
        s.undo();
        s.undo();
        assert_eq!(s.project().animation, None);
    }
}

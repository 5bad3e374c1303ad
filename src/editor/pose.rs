//! The animated pose: the frame on show, the project's still fields posed at it, and the
//! unkeyed edits made there.
//!
//! An animated project is held *posed*: the still fields of every animated value hold that
//! value at the current frame (what [`Project::at_frame`] would give), so that every view
//! and edit sees the frame on show. [`Project::at_frame`] ignores those fields, so posing
//! never changes what the file means. After an edit, [`Pose::sync_keys`] turns a changed
//! animated value into a key at the current frame when auto-key is on or the value has a key
//! there; otherwise the value stays changed on this frame only, an *unkeyed edit*
//! ([`Pose::unkeyed`]) that the preview shows and the panels warn about, until it is keyed
//! or the frame changes (then, as in Blender, the value goes back to its keys). Values that
//! are not animated are edited as in a still.
//!
//! The pose reads and writes the project it is given and records no undo steps: the
//! session's commands decide what is one.

use crate::scene::animation::{Animation, Channel, Interp, KeyValue, Object};
use crate::scene::Project;
use std::collections::BTreeMap;

/// The frame on show and the values changed there without a key.
#[derive(Clone, Debug)]
pub struct Pose {
    /// The frame on show (meaningful in an animated project).
    frame: i32,
    /// Animated values changed on this frame without a key, with their changed values.
    unkeyed: BTreeMap<Channel, KeyValue>,
}

impl Pose {
    /// The pose at the first frame of `project`'s animation.
    pub fn new(project: &Project) -> Self {
        let frame = project.animation.map_or(Animation::default().start, |a| a.start);
        Self { frame, unkeyed: BTreeMap::new() }
    }

    /// The frame on show.
    pub fn frame(&self) -> i32 {
        self.frame
    }

    /// Animated values changed on this frame without a key (see the module doc).
    pub fn unkeyed(&self) -> &BTreeMap<Channel, KeyValue> {
        &self.unkeyed
    }

    /// The still project on show: [`Project::at_frame`] of the current frame with the
    /// unkeyed edits applied (the project itself when it is not animated).
    pub fn still(&self, project: &Project) -> Project {
        let mut still = project.at_frame(self.frame);
        for (&c, &v) in &self.unkeyed {
            still.apply(c, v);
        }
        still
    }

    /// Writes every animated value at the current frame into its still field and drops
    /// unkeyed edits.
    pub fn apply(&mut self, project: &mut Project) {
        self.unkeyed.clear();
        if project.animation.is_none() {
            return;
        }
        let frame = self.frame;
        let values: Vec<(Channel, KeyValue)> =
            project.tracks.iter().filter_map(|t| t.sample(frame).map(|v| (t.on, v))).collect();
        for (c, v) in values {
            project.apply(c, v);
        }
    }

    /// Shows `frame` (clamped to the animation's range) and poses `project` there, dropping
    /// unkeyed edits; returns those dropped. Nothing changes when the frame is already shown.
    pub fn show(&mut self, project: &mut Project, frame: i32) -> Option<Vec<Channel>> {
        let frame = match project.animation {
            Some(a) => frame.clamp(a.start, a.end.max(a.start)),
            None => frame,
        };
        if frame == self.frame {
            return None;
        }
        let dropped: Vec<Channel> = self.unkeyed.keys().copied().collect();
        self.frame = frame;
        self.apply(project);
        Some(dropped)
    }

    /// Moves to `frame` without posing (a project that just became animated shows its
    /// still values there).
    pub fn jump(&mut self, frame: i32) {
        self.frame = frame;
    }

    /// Keeps the frame within `project`'s range and poses it there (after the project was
    /// replaced by one that may be animated or not).
    pub fn refit(&mut self, project: &mut Project) {
        if let Some(a) = project.animation {
            self.frame = self.frame.clamp(a.start, a.end.max(a.start));
        }
        self.apply(project);
    }

    /// Keeps the frame within `animation`'s range, posing `project` when it moved.
    pub fn clamp_to(&mut self, project: &mut Project, animation: Animation) {
        let frame = self.frame.clamp(animation.start, animation.end);
        if frame != self.frame {
            self.frame = frame;
            self.apply(project);
        }
    }

    /// Records the camera's animated values that differ from their keys as unkeyed edits
    /// (a view move is never keyed).
    pub fn note_camera(&mut self, project: &Project) {
        for c in project.animatable(Object::Camera) {
            let Some(track) = project.track(c) else { continue };
            match project.value_of(c) {
                Some(v) if Some(v) != track.sample(self.frame) => {
                    self.unkeyed.insert(c, v);
                }
                _ => {
                    self.unkeyed.remove(&c);
                }
            }
        }
    }

    /// Completes the edits since the last call: every animated value whose still field no
    /// longer holds its value at this frame was edited; it is keyed at this frame when
    /// `auto_key` is on or it has a key here (keeping that key's interpolation, or taking the
    /// one of the key before), and is an unkeyed edit otherwise.
    pub fn sync_keys(&mut self, project: &mut Project, auto_key: bool) {
        self.unkeyed.retain(|c, _| project.is_animated(*c));
        let frame = self.frame;
        let mut changed = Vec::new();
        for t in &project.tracks {
            let Some(now) = project.value_of(t.on) else { continue };
            let expected = self.unkeyed.get(&t.on).copied().or_else(|| t.sample(frame));
            if Some(now) != expected {
                let interp = t.keys.iter().take_while(|k| k.frame <= frame).last().map_or(Interp::Linear, |k| k.interp);
                changed.push((t.on, now, interp));
            }
        }
        for (c, v, interp) in changed {
            if auto_key || project.has_key(c, frame) {
                if project.set_key(c, frame, v, interp).is_ok() {
                    self.unkeyed.remove(&c);
                }
            } else {
                self.unkeyed.insert(c, v);
            }
        }
    }

    /// The keys that keying `channels` here would set: each value on show, with the
    /// interpolation of the key at or before this frame.
    pub fn keys_to_set(&self, project: &Project, channels: &[Channel]) -> Vec<(Channel, KeyValue, Interp)> {
        let frame = self.frame;
        channels
            .iter()
            .filter_map(|&c| {
                let v = project.value_of(c)?;
                let interp = project
                    .track(c)
                    .and_then(|t| t.keys.iter().take_while(|k| k.frame <= frame).last())
                    .map_or(Interp::Linear, |k| k.interp);
                Some((c, v, interp))
            })
            .collect()
    }

    /// Forgets the unkeyed edit of `channel` (it was keyed).
    pub fn keyed(&mut self, channel: Channel) {
        self.unkeyed.remove(&channel);
    }

    /// Re-poses one value after its keys changed (its still field shows the keys again).
    pub fn repose_channel(&mut self, project: &mut Project, channel: Channel) {
        self.unkeyed.remove(&channel);
        if let Some(v) = project.track(channel).and_then(|t| t.sample(self.frame)) {
            project.apply(channel, v);
        }
    }

    /// Re-poses every animated value of `objects`.
    pub fn repose_objects(&mut self, project: &mut Project, objects: &[Object]) {
        let channels: Vec<Channel> = project.tracks.iter().map(|t| t.on).filter(|c| objects.contains(&c.0)).collect();
        for c in channels {
            self.repose_channel(project, c);
        }
    }
}

/// The keys of `objects` at `frame` (every animated value of theirs keyed there).
pub fn keys_at(project: &Project, objects: &[Object], frame: i32) -> Vec<Channel> {
    project
        .tracks
        .iter()
        .filter(|t| objects.contains(&t.on.0) && t.keys.iter().any(|k| k.frame == frame))
        .map(|t| t.on)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::super::session::{Session, NEW_STEP};
    use super::*;
    use crate::scene::Particle;
    use glam::Vec3;

    fn session() -> Session {
        let p = Project {
            particles: (0..4).map(|i| Particle::new(Vec3::new(i as f32, 1.0, 0.0), 0.2, 1.0)).collect(),
            ..Project::default()
        };
        Session::new(p, Some(std::path::PathBuf::from("/tmp/x.ron")), "x")
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
            self.project().value_of(c)
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

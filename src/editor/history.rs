//! The undo history: the undo and redo steps, the coalescing of one stroke or drag into one
//! step, the bounds on what is kept, and each step's label in words.
//!
//! A step keeps the project without its particles, and the particles as what the step
//! changed: a step starts as a copy of every particle (the edit in progress may still change
//! any of them); once it ends, the copy shrinks to the hunks that differ from the state after
//! it, so a dab, a stroke or a scale keeps only the particles it touched, however large the
//! scene. Undo applies a step's hunks to the current particles and keeps the ones it
//! replaced as the redo step, and redo does the reverse: every state is restored exactly.
//! The history is bounded by step count and by total particles held.

use super::selection::Selection;
use crate::scene::animation::{Channel, Interp, Object};
use crate::scene::{Particle, Project};
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// Most undo steps kept.
const MAX_UNDO_STEPS: usize = 200;
/// Most particles kept across all undo snapshots before the oldest steps are dropped.
const MAX_UNDO_PARTICLES: usize = 20_000_000;

/// A tag that lets consecutive edits (one brush stroke, one slider drag) share one undo step.
pub type EditTag = u64;

/// An edit that starts a new undo step whatever came before.
pub const NEW_STEP: EditTag = 0;

/// One undo or redo step: `project` holds no particles, `particles` holds them relative to
/// the neighbouring state (the next newer one for undo steps, the next older one for redo
/// steps).
pub struct Snapshot {
    pub project: Project,
    pub particles: Stored,
    pub selection: Selection,
    pub generation: u64,
}

/// The undo and redo steps and the coalesced edit in progress.
pub struct History {
    undo: Vec<Snapshot>,
    redo: Vec<Snapshot>,
    open_tag: Option<EditTag>,
    next_tag: EditTag,
}

impl Default for History {
    fn default() -> Self {
        Self { undo: Vec::new(), redo: Vec::new(), open_tag: None, next_tag: 1 }
    }
}

impl History {
    /// A fresh tag for a multi-event edit such as a brush stroke.
    pub fn new_tag(&mut self) -> EditTag {
        self.next_tag += 1;
        self.next_tag
    }

    /// Whether a coalesced edit (a stroke, a drag) is in progress.
    pub fn in_progress(&self) -> bool {
        self.open_tag.is_some()
    }

    /// Before an edit tagged `tag` of `current`: records a new step unless `tag` continues
    /// the edit in progress.
    pub fn begin(&mut self, tag: EditTag, current: &Project, selection: &Selection, generation: u64) {
        if tag == NEW_STEP || self.open_tag != Some(tag) {
            self.push(current, selection, generation);
            self.open_tag = if tag == NEW_STEP { None } else { Some(tag) };
        }
    }

    fn push(&mut self, current: &Project, selection: &Selection, generation: u64) {
        self.compress_top(&current.particles);
        self.undo.push(Snapshot {
            project: current.without_particles(),
            particles: Stored::Full(current.particles.clone()),
            selection: selection.clone(),
            generation,
        });
        self.redo.clear();
        let mut total: usize = self.undo.iter().map(|s| s.particles.held()).sum();
        while self.undo.len() > MAX_UNDO_STEPS || (total > MAX_UNDO_PARTICLES && self.undo.len() > 1) {
            total -= self.undo.remove(0).particles.held();
        }
    }

    /// Ends the coalesced edit in progress: the next edit starts a new step. `particles`
    /// are the current ones.
    pub fn end(&mut self, particles: &[Particle]) {
        self.open_tag = None;
        self.compress_top(particles);
    }

    /// The step of the coalesced edit `tag`, taken off the history, if it is the one in
    /// progress (a cancelled drag leaves no step behind).
    pub fn take_open(&mut self, tag: EditTag) -> Option<Snapshot> {
        if tag != NEW_STEP && self.open_tag == Some(tag) {
            self.open_tag = None;
            self.undo.pop()
        } else {
            None
        }
    }

    /// Shrinks the last undo step to what it changed, once no edit can extend it.
    fn compress_top(&mut self, particles: &[Particle]) {
        if let Some(s) = self.undo.last_mut() {
            s.particles.compress(particles);
        }
    }

    /// Particles held by the undo and redo steps (a step holds what it changed).
    pub fn held(&self) -> usize {
        self.undo.iter().chain(&self.redo).map(|s| s.particles.held()).sum()
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

    /// The step Undo restores, taken off the history; the state it replaces goes to
    /// [`Self::undone`].
    pub fn pop_undo(&mut self) -> Option<Snapshot> {
        let step = self.undo.pop();
        if step.is_some() {
            self.open_tag = None;
        }
        step
    }

    /// The state an undo replaced: Redo brings it back.
    pub fn undone(&mut self, current: Snapshot) {
        self.redo.push(current);
    }

    /// The step Redo restores, taken off the history; the state it replaces goes to
    /// [`Self::redone`].
    pub fn pop_redo(&mut self) -> Option<Snapshot> {
        let step = self.redo.pop();
        if step.is_some() {
            self.open_tag = None;
        }
        step
    }

    /// The state a redo replaced: Undo takes it back again.
    pub fn redone(&mut self, current: Snapshot) {
        self.undo.push(current);
    }

    /// What Undo would take back from `current`, named by ids ("Delete Particle #24"); None
    /// with nothing to undo.
    pub fn undo_label(&self, current: &Project) -> Option<String> {
        self.undo.last().map(|s| {
            let (before, after) = s.particles.sides(&current.particles);
            describe(&s.project, current, &before, &after)
        })
    }

    /// What Redo would bring back to `current`.
    pub fn redo_label(&self, current: &Project) -> Option<String> {
        self.redo.last().map(|s| {
            let (after, before) = s.particles.sides(&current.particles);
            describe(current, &s.project, &before, &after)
        })
    }
}

/// Replace `len` particles at `at` of the later state by `old` to get the earlier one.
#[derive(Clone, Debug, PartialEq)]
pub struct Hunk {
    pub at: usize,
    pub len: usize,
    pub old: Vec<Particle>,
}

/// A step's particles: all of them, or the hunks that turn the neighbouring state into them.
#[derive(Clone, Debug, PartialEq)]
pub enum Stored {
    Full(Vec<Particle>),
    Delta(Vec<Hunk>),
}

impl Stored {
    /// Particles this step holds.
    pub fn held(&self) -> usize {
        match self {
            Stored::Full(v) => v.len(),
            Stored::Delta(h) => h.iter().map(|h| h.old.len()).sum(),
        }
    }

    /// The hunks that turn `other` into this step's particles.
    pub fn compress(&mut self, other: &[Particle]) {
        if let Stored::Full(v) = self {
            *self = Stored::Delta(diff(v, other));
        }
    }

    /// Turns `current` into this step's particles; returns the step that turns them back.
    pub fn restore(self, current: &mut Vec<Particle>) -> Stored {
        match self {
            Stored::Full(v) => {
                let later = std::mem::replace(current, v);
                let mut back = Stored::Full(later);
                back.compress(current);
                back
            }
            Stored::Delta(hunks) => Stored::Delta(apply(current, hunks)),
        }
    }

    /// The particles that differ between this step and `current`, the neighbouring state:
    /// this step's side, then `current`'s. Enough to name what changed.
    pub fn sides(&self, current: &[Particle]) -> (Vec<Particle>, Vec<Particle>) {
        let computed;
        let hunks = match self {
            Stored::Full(v) => {
                computed = diff(v, current);
                &computed
            }
            Stored::Delta(h) => h,
        };
        let mine = hunks.iter().flat_map(|h| h.old.iter().cloned()).collect();
        let theirs = hunks.iter().flat_map(|h| current[h.at..h.at + h.len].iter().cloned()).collect();
        (mine, theirs)
    }
}

/// The hunks that turn `after` into `before`. Every edit keeps the particles it does not
/// touch in order, so a walk along both lists finds them: by ids where both lists ascend
/// (as the editor numbers them), else through an index of `after`. Any other order still
/// gives correct, only larger, hunks.
pub fn diff(before: &[Particle], after: &[Particle]) -> Vec<Hunk> {
    let ascending = |v: &[Particle]| v.windows(2).all(|w| w[0].id < w[1].id);
    let index: Option<HashMap<u32, usize>> = if ascending(before) && ascending(after) {
        None
    } else {
        Some(after.iter().enumerate().map(|(k, p)| (p.id, k)).collect())
    };
    let mut hunks = Vec::new();
    let mut open: Option<Hunk> = None;
    let (mut i, mut j) = (0, 0);
    while i < before.len() && j < after.len() {
        let (b, a) = (&before[i], &after[j]);
        if b == a {
            hunks.extend(open.take());
            i += 1;
            j += 1;
            continue;
        }
        let h = open.get_or_insert_with(|| Hunk { at: j, len: 0, old: Vec::new() });
        let removed = match &index {
            _ if b.id == a.id => {
                h.old.push(b.clone());
                h.len += 1;
                i += 1;
                j += 1;
                continue;
            }
            None => b.id < a.id,
            Some(m) => m.get(&b.id).is_none_or(|&k| k < j),
        };
        if removed {
            h.old.push(b.clone());
            i += 1;
        } else {
            h.len += 1;
            j += 1;
        }
    }
    if i < before.len() || j < after.len() {
        let h = open.get_or_insert_with(|| Hunk { at: j, len: 0, old: Vec::new() });
        h.old.extend_from_slice(&before[i..]);
        h.len += after.len() - j;
    }
    hunks.extend(open);
    hunks
}

/// Applies `hunks` (ascending, from [`diff`]) to `current`; returns the hunks that undo them.
pub fn apply(current: &mut Vec<Particle>, hunks: Vec<Hunk>) -> Vec<Hunk> {
    if hunks.iter().all(|h| h.len == h.old.len()) {
        // Changes in place: swap the hunks' particles.
        return hunks
            .into_iter()
            .map(|mut h| {
                current[h.at..h.at + h.len].swap_with_slice(&mut h.old);
                h
            })
            .collect();
    }
    if let [h] = &hunks[..] {
        if h.at + h.len == current.len() {
            // At the end (a stroke's new particles, or the ones it erased last).
            let h = hunks.into_iter().next().expect("one hunk");
            let old = current.split_off(h.at);
            let len = h.old.len();
            current.extend(h.old);
            return vec![Hunk { at: h.at, len, old }];
        }
    }
    let total =
        current.len() + hunks.iter().map(|h| h.old.len()).sum::<usize>() - hunks.iter().map(|h| h.len).sum::<usize>();
    let mut out = Vec::with_capacity(total);
    let mut reverse = Vec::with_capacity(hunks.len());
    let mut rest = std::mem::take(current).into_iter();
    let mut pos = 0;
    for h in hunks {
        out.extend(rest.by_ref().take(h.at - pos));
        let replaced: Vec<Particle> = rest.by_ref().take(h.len).collect();
        reverse.push(Hunk { at: out.len(), len: h.old.len(), old: replaced });
        out.extend(h.old);
        pos = h.at + h.len;
    }
    out.extend(rest);
    *current = out;
    reverse
}

/// An undo step in words, from the objects whose ids appear, disappear or change between
/// `before` and `after`, and the settings that change.
pub fn describe_change(before: &Project, after: &Project) -> String {
    describe(before, after, &before.particles, &after.particles)
}

/// [`describe_change`] with the particles that differ given apart (the projects' own
/// particles are not read): those of `before`, then those of `after`.
fn describe(before: &Project, after: &Project, before_particles: &[Particle], after_particles: &[Particle]) -> String {
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

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn particles(ids: &[u32]) -> Vec<Particle> {
        ids.iter().map(|&id| Particle { id, ..Particle::new(Vec3::splat(id as f32), 0.1, 1.0) }).collect()
    }

    /// Every pair of states round-trips through diff, apply and the reverse hunks.
    fn round_trip(before: Vec<Particle>, after: Vec<Particle>) -> usize {
        let hunks = diff(&before, &after);
        let held = hunks.iter().map(|h| h.old.len()).sum();
        let mut current = after.clone();
        let back = apply(&mut current, hunks);
        assert_eq!(current, before);
        apply(&mut current, back);
        assert_eq!(current, after);
        held
    }

    #[test]
    fn edits_keep_only_what_they_touch() {
        let base = particles(&(0..100).collect::<Vec<_>>());
        let mut appended = base.clone();
        appended.extend(particles(&[100, 101]));
        assert_eq!(round_trip(base.clone(), appended.clone()), 0);
        assert_eq!(round_trip(appended, base.clone()), 2);
        let mut erased = base.clone();
        erased.remove(70);
        erased.remove(10);
        assert_eq!(round_trip(base.clone(), erased), 2);
        let mut scaled = base.clone();
        scaled[5].radius = 0.5;
        scaled[50].density = 3.0;
        assert_eq!(round_trip(base.clone(), scaled), 2);
        let mut shuffled = base.clone();
        shuffled.swap(3, 90);
        round_trip(base.clone(), shuffled.clone());
        round_trip(shuffled, base.clone());
        let mut unordered = base.clone();
        unordered.reverse();
        let mut edited = unordered.clone();
        edited.remove(40);
        edited[2].radius = 2.0;
        assert_eq!(round_trip(unordered, edited), 2);
        round_trip(Vec::new(), base.clone());
        round_trip(base, Vec::new());
    }
}

//! The particles of undo steps, stored as what an edit changed.
//!
//! A step starts as a copy of every particle (the edit in progress may still change any of
//! them); once it ends, the copy shrinks to the hunks that differ from the state after it,
//! so a dab, a stroke or a scale keeps only the particles it touched. Undo applies a step's
//! hunks to the current particles and keeps the ones it replaced as the redo step, and
//! redo does the reverse: every state is restored exactly.

use crate::scene::Particle;
use std::collections::HashMap;

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

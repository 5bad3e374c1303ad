//! Frame sequences on the command line: which frames to bake (`--frames 1-120x4`) and where
//! each frame's file goes (`fog.####.vdb`, `fog.%04d.vdb`, `fog.$F4.vdb`).
//!
//! A [`FrameSet`] is a comma-separated list of items, each a frame (`7`), a range (`1-120`)
//! or a range with a step (`1-120x4`: 1, 5, 9, … up to 120). Frames may be negative
//! (`-10--1`). The set bakes in ascending order, each frame once.
//!
//! A [`FramePattern`] is an output path holding a frame number, in any of three spellings
//! used by other tools, anywhere in the path:
//! - `####`: the frame padded with zeros to as many digits as there are `#` (Blender, Nuke);
//! - `%04d` (or `%d`): printf style (ffmpeg, Nuke, Unreal);
//! - `$F4` (or `$F`): Houdini's.
//!
//! A sequence of more than one frame needs a pattern in every output path; a single frame
//! writes a path without one as it is.

use std::collections::BTreeSet;
use std::fmt;
use std::path::{Path, PathBuf};

/// The frame of an animation a file holds, and the animation's rate (recorded in VDB
/// metadata and the USD stage).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameTime {
    pub frame: i32,
    pub fps: f32,
}

/// Most frames a [`FrameSet`] may hold: a million frames is over nine hours at 30 fps, and a
/// range such as `1-2147483647` (a typo, or a damaged `farm.json`) is refused before its
/// frames are listed.
pub const MAX_FRAMES: u64 = 1_000_000;

/// Frames to bake, ascending, each once.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSet {
    frames: Vec<i32>,
    /// The text it was parsed from, for messages.
    text: String,
}

/// Why a frame list or a frame pattern is refused; the message names the fix.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct SequenceError(pub String);

fn err(message: String) -> SequenceError {
    SequenceError(message)
}

impl FrameSet {
    /// Parses `1-120`, `1-120x4`, `7` or `1,5,9-12`.
    pub fn parse(text: &str) -> Result<Self, SequenceError> {
        let usage = "write frames as 7, 1-120, 1-120x4 (every 4th) or a list such as 1,5,9-12";
        let trimmed = text.trim();
        if trimmed.is_empty() {
            return Err(err(format!("--frames is empty: {usage}")));
        }
        let mut frames = BTreeSet::new();
        for item in trimmed.split(',') {
            let item = item.trim();
            let bad = || err(format!("--frames {trimmed:?}: {item:?} is not a frame or a range: {usage}"));
            if item.is_empty() {
                return Err(bad());
            }
            let (range, step) = match item.split_once(['x', 'X']) {
                Some((r, s)) => {
                    let step: i64 = s.trim().parse().map_err(|_| bad())?;
                    if step < 1 {
                        return Err(err(format!(
                            "--frames {trimmed:?}: the step of {item:?} must be at least 1, got {step}: {usage}"
                        )));
                    }
                    (r.trim(), Some(step))
                }
                None => (item, None),
            };
            let (first, last) = split_range(range).ok_or_else(bad)?;
            if step.is_some() && first == last && !range[1..].contains('-') {
                // `7x2`: a step needs a range.
                return Err(bad());
            }
            if last < first {
                return Err(err(format!(
                    "--frames {trimmed:?}: the range {range:?} ends before it starts; write {last}-{first}"
                )));
            }
            let step = step.unwrap_or(1);
            let count = (last as i64 - first as i64) / step + 1;
            if frames.len() as u64 + count as u64 > MAX_FRAMES {
                return Err(err(format!(
                    "--frames {trimmed:?}: {range:?} lists {count} frames, more than the {MAX_FRAMES} a sequence may have"
                )));
            }
            let mut f = first as i64;
            while f <= last as i64 {
                frames.insert(f as i32);
                f += step;
            }
        }
        Ok(Self { frames: frames.into_iter().collect(), text: trimmed.to_string() })
    }

    /// One frame.
    pub fn single(frame: i32) -> Self {
        Self { frames: vec![frame], text: frame.to_string() }
    }

    pub fn frames(&self) -> &[i32] {
        &self.frames
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Refuses frames outside the animation range `start..=end`.
    pub fn check_within(&self, start: i32, end: i32) -> Result<(), SequenceError> {
        let outside: Vec<i32> = self.frames.iter().copied().filter(|f| !(start..=end).contains(f)).collect();
        match outside.as_slice() {
            [] => Ok(()),
            [f] => Err(err(format!(
                "--frames {}: frame {f} is outside the project's animation range {start}-{end}; \
                 choose frames within it or widen `animation` in the project",
                self.text
            ))),
            [f, .., l] => Err(err(format!(
                "--frames {}: {} frames ({f} … {l}) are outside the project's animation range {start}-{end}; \
                 choose frames within it or widen `animation` in the project",
                self.text,
                outside.len()
            ))),
        }
    }
}

impl fmt::Display for FrameSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

/// `a` or `a-b`, either of them possibly negative.
fn split_range(text: &str) -> Option<(i32, i32)> {
    if let Ok(f) = text.parse::<i32>() {
        return Some((f, f));
    }
    // The separator is the first '-' after the first character (which may be a sign).
    let cut = text.char_indices().skip(1).find(|&(_, c)| c == '-')?.0;
    let (a, b) = (text[..cut].trim(), text[cut + 1..].trim());
    Some((a.parse().ok()?, b.parse().ok()?))
}

/// One place in a path where the frame number goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Slot {
    start: usize,
    len: usize,
    /// Digits to pad to (1: no padding).
    width: usize,
}

/// An output path with frame-number placeholders (see the module doc).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FramePattern {
    text: String,
    slots: Vec<Slot>,
}

impl FramePattern {
    pub fn new(path: &Path) -> Self {
        let text = path.to_string_lossy().into_owned();
        let slots = find_slots(&text);
        Self { text, slots }
    }

    /// Whether the path holds a frame number.
    pub fn has_frame(&self) -> bool {
        !self.slots.is_empty()
    }

    /// The path of `frame`: every placeholder replaced by the frame number.
    pub fn path(&self, frame: i32) -> PathBuf {
        let mut out = String::with_capacity(self.text.len() + 4);
        let mut at = 0;
        for s in &self.slots {
            out.push_str(&self.text[at..s.start]);
            out.push_str(&format!("{frame:0width$}", width = s.width));
            at = s.start + s.len;
        }
        out.push_str(&self.text[at..]);
        PathBuf::from(out)
    }

    /// The path of every frame, or an error naming `flag` when several frames would go to one
    /// file without a placeholder.
    pub fn paths(&self, flag: &str, frames: &FrameSet) -> Result<Vec<PathBuf>, SequenceError> {
        if frames.len() > 1 && !self.has_frame() {
            let suggestion = suggest_pattern(Path::new(&self.text));
            return Err(err(format!(
                "{flag} {}: --frames {frames} is {} frames, and this path has no frame number, so every \
                 frame would overwrite one file; put one in the name, e.g. {} (or %04d, or $F4)",
                self.text,
                frames.len(),
                suggestion.display()
            )));
        }
        Ok(frames.frames().iter().map(|&f| self.path(f)).collect())
    }
}

/// `name.ext` → `name.####.ext`.
pub fn suggest_pattern(path: &Path) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    match path.extension() {
        Some(ext) => path.with_file_name(format!("{stem}.####.{}", ext.to_string_lossy())),
        None => path.with_file_name(format!("{stem}.####")),
    }
}

fn find_slots(text: &str) -> Vec<Slot> {
    let bytes = text.as_bytes();
    let mut slots = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'#' => {
                let n = bytes[i..].iter().take_while(|&&b| b == b'#').count();
                slots.push(Slot { start: i, len: n, width: n });
                i += n;
            }
            b'%' => {
                // %d, %4d, %04d
                let digits = bytes[i + 1..].iter().take_while(|b| b.is_ascii_digit()).count();
                if bytes.get(i + 1 + digits) == Some(&b'd') {
                    let width = text[i + 1..i + 1 + digits].parse().unwrap_or(1).max(1);
                    slots.push(Slot { start: i, len: digits + 2, width });
                    i += digits + 2;
                } else {
                    i += 1;
                }
            }
            b'$' if bytes.get(i + 1) == Some(&b'F') => {
                let digits = bytes[i + 2..].iter().take_while(|b| b.is_ascii_digit()).count();
                let width = text[i + 2..i + 2 + digits].parse().unwrap_or(1).max(1);
                slots.push(Slot { start: i, len: digits + 2, width });
                i += digits + 2;
            }
            _ => i += 1,
        }
    }
    slots
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_documented_forms() {
        assert_eq!(FrameSet::parse("7").unwrap().frames(), &[7]);
        assert_eq!(FrameSet::parse("1-4").unwrap().frames(), &[1, 2, 3, 4]);
        assert_eq!(FrameSet::parse("1-12x4").unwrap().frames(), &[1, 5, 9]);
        assert_eq!(FrameSet::parse("1,5,9-12").unwrap().frames(), &[1, 5, 9, 10, 11, 12]);
        assert_eq!(FrameSet::parse("12,1-3,2").unwrap().frames(), &[1, 2, 3, 12]);
        assert_eq!(FrameSet::parse("-3--1").unwrap().frames(), &[-3, -2, -1]);
        assert_eq!(FrameSet::parse("-2-1").unwrap().frames(), &[-2, -1, 0, 1]);
    }

    #[test]
    fn pads_each_spelling() {
        let p = |s: &str, f| FramePattern::new(Path::new(s)).path(f).display().to_string();
        assert_eq!(p("shots/fog.####.exr", 7), "shots/fog.0007.exr");
        assert_eq!(p("fog.##.exr", 123), "fog.123.exr");
        assert_eq!(p("fog.%04d.vdb", 42), "fog.0042.vdb");
        assert_eq!(p("fog.%d.vdb", 42), "fog.42.vdb");
        assert_eq!(p("fog.$F4.vdb", 5), "fog.0005.vdb");
        assert_eq!(p("fog.$F.vdb", 5), "fog.5.vdb");
        assert_eq!(p("f$F3/fog_#.vdb", 9), "f009/fog_9.vdb");
        assert!(!FramePattern::new(Path::new("fog.vdb")).has_frame());
        assert!(!FramePattern::new(Path::new("100%.vdb")).has_frame());
    }
}

//! Playback: the play mode, the real-time clock, stepping and looping through the frame
//! range, the frames dropped and the rate achieved, and where the scrub bar lies. The
//! Timeline's state without its drawing (`timeline` draws it and acts on the editor).
//!
//! *Real time* keeps the animation's clock: each drawn frame shows the frame due at that
//! moment, dropping those the pipeline had no time for. *Every frame* shows each frame
//! until the preview has converged on it, then moves on. These are functions of their
//! inputs and a time, so they are tested with a fake clock.

use super::history::EditTag;
use crate::scene::animation::{Animation, Object};
use egui::Rect;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

/// How playback treats frames the preview cannot finish in time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlayMode {
    /// Keep time: show the frame due now, skipping frames.
    #[default]
    RealTime,
    /// Show every frame, each converged (full resolution, fresh shadows), however long.
    EveryFrame,
}

impl PlayMode {
    pub fn label(self) -> &'static str {
        match self {
            PlayMode::RealTime => "Real time",
            PlayMode::EveryFrame => "Every frame",
        }
    }
}

/// `frame` moved by `delta` frames, within the animation's range.
pub fn step_frame(a: &Animation, frame: i32, delta: i32) -> i32 {
    frame.saturating_add(delta).clamp(a.start, a.end.max(a.start))
}

/// The frame after `frame` in playback: the start again after the end when looping, None
/// (playback ends) otherwise.
pub fn next_frame(a: &Animation, frame: i32, looping: bool) -> Option<i32> {
    if frame >= a.end {
        looping.then_some(a.start)
    } else {
        Some((frame + 1).max(a.start))
    }
}

/// Frames skipped going forward from `from` to `to` in playback (across the loop's seam).
pub fn frames_skipped(a: &Animation, from: i32, to: i32) -> u64 {
    let len = (a.end - a.start + 1).max(1) as i64;
    let ahead = (to as i64 - from as i64).rem_euclid(len);
    ahead.saturating_sub(1) as u64
}

/// Real-time playback's clock: frame `anchor_frame` was due at time `anchor_time` (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealTimeClock {
    pub anchor_time: f64,
    pub anchor_frame: i32,
}

impl RealTimeClock {
    /// The frame due at time `now`: one more every 1/fps s, wrapping to the start when
    /// looping; None once past the end without looping.
    pub fn frame_at(&self, a: &Animation, now: f64, looping: bool) -> Option<i32> {
        // A frame is due at its time, not a rounding error after it.
        let ahead = ((now - self.anchor_time).max(0.0) * a.fps as f64 + 1e-6).floor() as i64;
        let f = self.anchor_frame as i64 + ahead;
        let (s, e) = (a.start as i64, a.end as i64);
        if f <= e {
            Some(f.max(s) as i32)
        } else if looping {
            let len = (e - s + 1).max(1);
            Some((s + (f - s).rem_euclid(len)) as i32)
        } else {
            None
        }
    }
}

/// The rate at which playback shows new frames, over the last two seconds.
#[derive(Clone, Debug, Default)]
pub struct FrameMeter {
    times: VecDeque<f64>,
}

impl FrameMeter {
    pub fn clear(&mut self) {
        self.times.clear();
    }
    /// A new frame was shown at time `now` (s).
    pub fn shown(&mut self, now: f64) {
        self.times.push_back(now);
        while self.times.len() > 2 && now - self.times[0] > 2.0 {
            self.times.pop_front();
        }
    }
    /// Frames per second, once two frames were shown.
    pub fn fps(&self) -> Option<f64> {
        let (first, last) = (self.times.front()?, self.times.back()?);
        let span = last - first;
        (self.times.len() >= 2 && span > 0.0).then(|| (self.times.len() - 1) as f64 / span)
    }
}

/// A marker drag in progress: the keys that were at `from` are now at `at`.
#[derive(Clone, Debug)]
pub(crate) struct KeyDrag {
    pub(super) tag: EditTag,
    pub(super) objects: Vec<Object>,
    pub(super) at: i32,
}

/// Where the scrub bar was drawn, so that scripted drivers can point at frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScrubBar {
    pub rect: Rect,
    pub start: i32,
    pub end: i32,
}

impl ScrubBar {
    pub(super) const MARGIN: f32 = 10.0;

    /// The x of `frame`'s tick.
    pub fn x_of(&self, frame: i32) -> f32 {
        let span = (self.end - self.start).max(1) as f32;
        self.rect.left() + Self::MARGIN + (frame - self.start) as f32 / span * (self.rect.width() - 2.0 * Self::MARGIN)
    }

    /// The frame nearest to `x`, within the range.
    pub fn frame_at(&self, x: f32) -> i32 {
        let span = (self.end - self.start).max(1) as f32;
        let u = (x - self.rect.left() - Self::MARGIN) / (self.rect.width() - 2.0 * Self::MARGIN).max(1.0);
        (self.start as f32 + u * span).round().clamp(self.start as f32, self.end as f32) as i32
    }

    /// Where the markers of keys sit.
    pub fn marker_y(&self) -> f32 {
        self.rect.bottom() - 9.0
    }
}

/// The Timeline's state: playback, the selected key marker and what is measured.
#[derive(Default)]
pub(crate) struct TimelineState {
    pub playing: Option<RealTimeClock>,
    pub looping: bool,
    pub mode: PlayMode,
    /// The selected marker: a frame, with the objects whose keys it stood for.
    pub selected_key: Option<(i32, Vec<Object>)>,
    pub drag: Option<KeyDrag>,
    /// Whether the scrub bar is being dragged (not a marker).
    pub scrubbing: bool,
    pub meter: FrameMeter,
    /// Frames skipped by real-time playback since it started.
    pub dropped: u64,
    pub bar: Option<ScrubBar>,
}

impl TimelineState {
    pub fn new() -> Self {
        Self { looping: true, ..Self::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use egui::{Pos2, Vec2};

    const A: Animation = Animation { fps: 24.0, start: 1, end: 10 };

    #[test]
    fn stepping_stays_in_the_range_and_playback_loops_or_ends() {
        assert_eq!(step_frame(&A, 5, 1), 6);
        assert_eq!(step_frame(&A, 10, 1), 10, "no step past the end");
        assert_eq!(step_frame(&A, 1, -1), 1, "no step before the start");
        assert_eq!(step_frame(&A, 40, -1), 10, "a frame outside the range comes back into it");
        assert_eq!(next_frame(&A, 9, false), Some(10));
        assert_eq!(next_frame(&A, 10, true), Some(1), "looping wraps to the start");
        assert_eq!(next_frame(&A, 10, false), None, "without looping playback ends");
        assert_eq!(next_frame(&A, -3, false), Some(1));
    }

    #[test]
    fn real_time_playback_shows_the_frame_due_and_counts_the_dropped_ones() {
        let clock = RealTimeClock { anchor_time: 100.0, anchor_frame: 3 };
        let t = |frames: f64| 100.0 + frames / 24.0;
        assert_eq!(clock.frame_at(&A, t(0.0), false), Some(3));
        assert_eq!(clock.frame_at(&A, t(0.999), false), Some(3), "not due yet");
        assert_eq!(clock.frame_at(&A, t(1.0), false), Some(4), "due at its time exactly");
        assert_eq!(clock.frame_at(&A, t(7.0), false), Some(10));
        assert_eq!(clock.frame_at(&A, t(8.0), false), None, "past the end without looping");
        assert_eq!(clock.frame_at(&A, t(8.0), true), Some(1), "the loop's seam");
        assert_eq!(clock.frame_at(&A, t(8.0 + 10.0 * 3.0 + 4.0), true), Some(5), "three loops later");
        assert_eq!(clock.frame_at(&A, 99.0, false), Some(3), "a clock going back holds the anchor");
        // A slow preview: drawn frames at 0, 2.5 and 6 frame times show 3, 5 and 9.
        let shown: Vec<i32> = [0.0, 2.5, 6.0].iter().filter_map(|&f| clock.frame_at(&A, t(f), false)).collect();
        assert_eq!(shown, vec![3, 5, 9]);
        let dropped: u64 = shown.windows(2).map(|w| frames_skipped(&A, w[0], w[1])).sum();
        assert_eq!(dropped, 1 + 3, "4 and 6, 7, 8 were never shown");
        assert_eq!(frames_skipped(&A, 9, 2), 2, "10 and 1 across the seam");
        assert_eq!(frames_skipped(&A, 4, 5), 0);
    }

    #[test]
    fn the_meter_counts_frames_shown_over_the_recent_window() {
        let mut m = FrameMeter::default();
        assert_eq!(m.fps(), None);
        m.shown(10.0);
        assert_eq!(m.fps(), None, "one frame is no rate");
        for k in 1..=12 {
            m.shown(10.0 + k as f64 * 0.25);
        }
        assert_eq!(m.fps(), Some(4.0));
        for k in 1..=8 {
            m.shown(13.0 + k as f64 * 0.5);
        }
        assert_eq!(m.fps(), Some(2.0), "the old rate has left the window");
    }

    #[test]
    fn the_scrub_bar_maps_frames_to_x_and_back() {
        let bar =
            ScrubBar { rect: Rect::from_min_size(Pos2::new(100.0, 0.0), Vec2::new(220.0, 40.0)), start: 1, end: 11 };
        assert_eq!(bar.x_of(1), 110.0);
        assert_eq!(bar.x_of(11), 310.0);
        for f in 1..=11 {
            assert_eq!(bar.frame_at(bar.x_of(f)), f);
            assert_eq!(bar.frame_at(bar.x_of(f) + 9.0), f, "the nearest frame");
        }
        assert_eq!(bar.frame_at(0.0), 1);
        assert_eq!(bar.frame_at(1000.0), 11);
    }
}

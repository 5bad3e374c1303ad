//! The Timeline tab and playback: the current frame, the frame range and rate, a scrub bar
//! with the selection's keys as markers (click to select, drag to move, right click for
//! delete and interpolation), and playing in real time or frame by frame.
//!
//! Playback drives the current frame only; the preview follows it as it follows any edit.
//! *Real time* keeps the animation's clock: each drawn frame shows the frame due at that
//! moment, dropping those the pipeline had no time for. *Every frame* shows each frame
//! until the preview has converged on it, then moves on. The pure parts (stepping, the
//! real-time clock, dropped frames, the achieved rate) are functions of their inputs and a
//! time, so they are tested with a fake clock.

use super::commands::Command;
use super::session::EditTag;
use super::state::EditorState;
use crate::scene::animation::{Animation, Interp, Object};
use egui::{Color32, DragValue, Pos2, Rect, Sense, Stroke, Ui, Vec2};
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
    tag: EditTag,
    objects: Vec<Object>,
    at: i32,
}

/// Where the scrub bar was drawn, so that scripted drivers can point at frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScrubBar {
    pub rect: Rect,
    pub start: i32,
    pub end: i32,
}

impl ScrubBar {
    const MARGIN: f32 = 10.0;

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

impl EditorState {
    /// Shows `frame`, saying which unkeyed edits that dropped.
    pub(crate) fn goto_frame(&mut self, frame: i32) {
        let dropped = self.session.set_frame(frame);
        if !dropped.is_empty() {
            let names: Vec<String> = dropped.iter().map(|c| c.to_string()).collect();
            self.info(format!("Unkeyed changes dropped: {} (they were not keyed)", names.join(", ")));
        }
    }

    pub(crate) fn toggle_play(&mut self) {
        if self.timeline.playing.take().is_some() {
            return;
        }
        let Some(a) = self.session.project().animation else {
            self.info("Nothing to play: Animate gives the project a frame range");
            return;
        };
        if self.session.frame() >= a.end && !self.timeline.looping {
            self.goto_frame(a.start);
        }
        let now = self.ctx.input(|i| i.time);
        self.timeline.playing = Some(RealTimeClock { anchor_time: now, anchor_frame: self.session.frame() });
        self.timeline.meter.clear();
        self.timeline.meter.shown(now);
        self.timeline.dropped = 0;
    }

    /// The frame-stepping commands, by the delta or the end they go to.
    pub(crate) fn step(&mut self, command: Command) {
        let Some(a) = self.session.project().animation else { return };
        let f = self.session.frame();
        let to = match command {
            Command::NextFrame => step_frame(&a, f, 1),
            Command::PreviousFrame => step_frame(&a, f, -1),
            Command::FirstFrame => a.start,
            _ => a.end,
        };
        self.timeline.playing = None;
        self.goto_frame(to);
    }

    /// Whether playback runs in "every frame" mode.
    pub(super) fn playing_every_frame(&self) -> bool {
        self.timeline.playing.is_some() && self.timeline.mode == PlayMode::EveryFrame
    }

    /// Whether the preview shows the current state converged (or there is no preview).
    fn preview_done(&self) -> bool {
        let key = super::state::PreviewKey { version: self.version(), size: self.view.preview_size };
        self.gpu.as_ref().is_none_or(|g| g.error.is_some() || g.converged == Some(key))
    }

    /// Moves playback on, once per frame before the panels draw.
    pub(super) fn tick_playback(&mut self) {
        if let Some((_, objects)) = &self.timeline.selected_key {
            if *objects != self.session.selected_objects() {
                self.timeline.selected_key = None;
            }
        }
        let Some(clock) = self.timeline.playing else { return };
        let Some(a) = self.session.project().animation else {
            self.timeline.playing = None;
            return;
        };
        let now = self.ctx.input(|i| i.time);
        let frame = self.session.frame();
        let looping = self.timeline.looping;
        match self.timeline.mode {
            PlayMode::RealTime => match clock.frame_at(&a, now, looping) {
                Some(f) if f != frame => {
                    self.timeline.dropped += frames_skipped(&a, frame, f);
                    self.goto_frame(f);
                    self.timeline.meter.shown(now);
                }
                Some(_) => {}
                None => {
                    self.goto_frame(a.end);
                    self.timeline.playing = None;
                }
            },
            PlayMode::EveryFrame => {
                if self.preview_done() {
                    match next_frame(&a, frame, looping) {
                        Some(f) => {
                            self.goto_frame(f);
                            self.timeline.meter.shown(now);
                        }
                        None => self.timeline.playing = None,
                    }
                }
            }
        }
        self.ctx.request_repaint();
    }

    /// "24.0 frames/s of 24, 3 dropped" while playing.
    pub(crate) fn playback_text(&self) -> Option<String> {
        self.timeline.playing?;
        let a = self.session.project().animation?;
        let rate = self.timeline.meter.fps().map_or("–".to_string(), |f| format!("{f:.1}"));
        Some(match self.timeline.mode {
            PlayMode::RealTime => {
                format!("Playing {rate} frames/s of {}, {} dropped", a.fps, self.timeline.dropped)
            }
            PlayMode::EveryFrame => format!("Playing every frame converged: {rate} frames/s (target {})", a.fps),
        })
    }

    /// "Preview: frame 40 with shadows from frame 31" while the image on show mixes frames.
    pub(crate) fn preview_frames_note(&self) -> Option<String> {
        let status = self.preview_status()?;
        match (status.shown_frame, status.shadows_frame) {
            (Some(fog), Some(shadows)) if fog != shadows => {
                Some(format!("Preview: frame {fog} with shadows from frame {shadows}"))
            }
            (Some(fog), None) if status.shadows_stale => {
                Some(format!("Preview: frame {fog} with shadows from before the animation was shown"))
            }
            _ => None,
        }
    }

    /// The Delete command on a selected key marker: its keys go.
    pub(crate) fn delete_selected_keys(&mut self) -> bool {
        let Some((frame, objects)) = self.timeline.selected_key.take() else { return false };
        let n = self.session.delete_keys(&objects, frame);
        if n == 0 {
            self.info(format!("No keys at frame {frame} to delete"));
        }
        true
    }
}

/// The colour of the viewport's motion paths and their key dots.
pub const MOTION_PATH: Color32 = Color32::from_rgb(120, 200, 255);

const KEY_COLOR: Color32 = Color32::from_rgb(240, 200, 60);
const SELECTED_KEY_COLOR: Color32 = Color32::from_rgb(255, 120, 40);

/// A key diamond centred at `c`.
pub(crate) fn paint_diamond(ui: &Ui, c: Pos2, r: f32, fill: Option<Color32>, stroke: Stroke) {
    let points = vec![c + Vec2::new(0.0, -r), c + Vec2::new(r, 0.0), c + Vec2::new(0.0, r), c + Vec2::new(-r, 0.0)];
    let shape = egui::epaint::PathShape::convex_polygon(points, fill.unwrap_or(Color32::TRANSPARENT), stroke);
    ui.painter().add(shape);
}

pub(crate) fn show(state: &mut EditorState, ui: &mut Ui) {
    let Some(a) = state.session.project().animation else {
        ui.horizontal(|ui| {
            let (text, tip) = Command::Animate.text_and_tooltip();
            if ui.button(text).on_hover_text(tip).clicked() {
                state.run(Command::Animate);
            }
            ui.label("This project is a still: Animate gives it frames 1–120 at 24 fps (or press K on a selection).");
        });
        return;
    };
    ui.horizontal_wrapped(|ui| {
        let playing = state.timeline.playing.is_some();
        for (command, text) in [
            (Command::FirstFrame, "|<"),
            (Command::PreviousFrame, "<"),
            (Command::PlayPause, if playing { "Pause" } else { "Play" }),
            (Command::NextFrame, ">"),
            (Command::LastFrame, ">|"),
        ] {
            let tip = format!("{} ({})", command.tooltip(), command.shortcut_text());
            if ui.button(text).on_hover_text(tip).clicked() {
                state.run(command);
            }
        }
        ui.separator();
        let label = ui.label("frame");
        let mut f = state.session.frame();
        let r = ui
            .add(DragValue::new(&mut f).range(a.start..=a.end))
            .labelled_by(label.id)
            .on_hover_text("The frame on show");
        if r.changed() {
            state.timeline.playing = None;
            state.goto_frame(f);
        }
        let mut b = a;
        let label = ui.label("start");
        let r1 = ui
            .add(DragValue::new(&mut b.start).range(-100_000..=a.end))
            .labelled_by(label.id)
            .on_hover_text("First frame");
        let label = ui.label("end");
        let r2 = ui
            .add(DragValue::new(&mut b.end).range(a.start..=1_000_000))
            .labelled_by(label.id)
            .on_hover_text("Last frame");
        let label = ui.label("fps");
        let r3 = ui
            .add(DragValue::new(&mut b.fps).range(0.1..=1000.0).speed(0.1).max_decimals(3))
            .labelled_by(label.id)
            .on_hover_text("Frames per second: frame f is at f / fps seconds (wind drifts the noise by time)");
        for r in [r1, r2, r3] {
            if r.changed() {
                state.session.set_animation(r.id.value(), b);
            }
        }
        ui.separator();
        let toggles = [(Command::LoopPlayback, state.timeline.looping), (Command::AutoKey, state.session.auto_key)];
        for (command, on) in toggles {
            if command.menu_checkbox(ui, on) {
                state.run(command);
            }
        }
        egui::ComboBox::from_id_salt("play mode")
            .selected_text(state.timeline.mode.label())
            .show_ui(ui, |ui| {
                for mode in [PlayMode::RealTime, PlayMode::EveryFrame] {
                    let tip = match mode {
                        PlayMode::RealTime => "Keep the animation's time, dropping frames the preview cannot finish",
                        PlayMode::EveryFrame => {
                            "Show every frame at full quality (converged) before the next, however slow"
                        }
                    };
                    ui.selectable_value(&mut state.timeline.mode, mode, mode.label()).on_hover_text(tip);
                }
            })
            .response
            .on_hover_text("How playback treats frames the preview cannot finish in time");
        let (text, tip) = Command::InsertKey.text_and_tooltip();
        if ui.button(text).on_hover_text(format!("{tip} (K)")).clicked() {
            state.run(Command::InsertKey);
        }
        if let Some(t) = state.playback_text() {
            ui.label(t);
        }
        if let Some(note) = state.preview_frames_note() {
            ui.colored_label(ui.visuals().warn_fg_color, note).on_hover_text(
                "Propagation has not caught up with the frames shown: the optical depths are an earlier frame's",
            );
        }
    });
    scrub_bar(state, ui, a);
}

/// The frames with keys on any of `objects`.
fn marker_frames(state: &EditorState, objects: &[Object]) -> Vec<i32> {
    let p = state.session.project();
    let mut frames: Vec<i32> = objects.iter().flat_map(|&o| p.key_frames(o)).collect();
    frames.sort_unstable();
    frames.dedup();
    frames
}

fn scrub_bar(state: &mut EditorState, ui: &mut Ui, a: Animation) {
    let height = 36.0;
    let (rect, response) =
        ui.allocate_exact_size(Vec2::new(ui.available_width().max(60.0), height), Sense::click_and_drag());
    let bar = ScrubBar { rect, start: a.start, end: a.end };
    state.timeline.bar = Some(bar);
    let objects = state.session.selected_objects();
    let markers = marker_frames(state, &objects);
    let marker_at = |x: f32| {
        markers
            .iter()
            .copied()
            .filter(|&f| (bar.x_of(f) - x).abs() <= 6.0)
            .min_by(|&f, &g| (bar.x_of(f) - x).abs().total_cmp(&(bar.x_of(g) - x).abs()))
    };
    let on_markers = |p: Pos2| (p.y - bar.marker_y()).abs() <= 8.0;

    // Press: a marker selects it (and a drag moves it); elsewhere the bar scrubs.
    let press = ui.input(|i| i.pointer.press_origin());
    if response.clicked() || response.drag_started() || response.secondary_clicked() {
        if let Some(p) = press.or(response.interact_pointer_pos()) {
            match marker_at(p.x).filter(|_| on_markers(p)) {
                Some(f) => {
                    state.timeline.selected_key = Some((f, objects.clone()));
                    if response.drag_started() {
                        let tag = state.session.new_tag();
                        state.timeline.drag = Some(KeyDrag { tag, objects: objects.clone(), at: f });
                    }
                }
                None if !response.secondary_clicked() => {
                    state.timeline.selected_key = None;
                    state.timeline.playing = None;
                    state.timeline.scrubbing = response.drag_started();
                    state.goto_frame(bar.frame_at(p.x));
                }
                None => {}
            }
        }
    }
    if response.dragged() {
        if let Some(p) = response.interact_pointer_pos() {
            let target = bar.frame_at(p.x);
            if let Some(drag) = state.timeline.drag.clone() {
                // Over a frame where one of the values has a key, the keys wait for a free one.
                if target != drag.at && state.session.move_keys(drag.tag, &drag.objects, drag.at, target).is_ok() {
                    state.timeline.drag = Some(KeyDrag { at: target, ..drag });
                    state.timeline.selected_key = Some((target, objects.clone()));
                }
            } else if state.timeline.scrubbing {
                state.goto_frame(target);
            }
        }
    }
    if response.drag_stopped() {
        if state.timeline.drag.take().is_some() {
            state.session.end_edit();
        }
        state.timeline.scrubbing = false;
    }
    let selected = state.timeline.selected_key.as_ref().map(|(f, _)| *f);
    response.context_menu(|ui| key_menu(state, ui, selected));

    // Drawing: ticks with frame numbers, the current frame, the markers.
    let painter = ui.painter_at(rect);
    let visuals = ui.visuals();
    painter.rect_filled(rect, 3.0, visuals.extreme_bg_color);
    let span = (a.end - a.start).max(1);
    let px_per_frame = (rect.width() - 2.0 * ScrubBar::MARGIN) / span as f32;
    let label_step = [1, 2, 5, 10, 20, 25, 50, 100, 200, 250, 500, 1000, 2000, 5000, 10_000]
        .into_iter()
        .find(|s| *s as f32 * px_per_frame >= 36.0)
        .unwrap_or(10_000);
    let text_color = visuals.weak_text_color();
    let first = a.start.div_euclid(label_step) * label_step;
    let mut f = first;
    while f <= a.end {
        if f >= a.start {
            let x = bar.x_of(f);
            painter
                .line_segment([Pos2::new(x, rect.top()), Pos2::new(x, rect.top() + 6.0)], Stroke::new(1.0, text_color));
            painter.text(
                Pos2::new(x, rect.top() + 7.0),
                egui::Align2::CENTER_TOP,
                f.to_string(),
                egui::FontId::proportional(10.0),
                text_color,
            );
        }
        f += label_step;
    }
    for &f in &markers {
        let color = if selected == Some(f) { SELECTED_KEY_COLOR } else { KEY_COLOR };
        paint_diamond(ui, Pos2::new(bar.x_of(f), bar.marker_y()), 5.0, Some(color), Stroke::new(1.0, Color32::BLACK));
    }
    let x = bar.x_of(state.session.frame());
    let accent = visuals.selection.bg_fill;
    painter.line_segment([Pos2::new(x, rect.top()), Pos2::new(x, rect.bottom())], Stroke::new(2.0, accent));
    response.on_hover_text(
        "Click or drag to show a frame. Diamonds: the selection's keys; click one to select it (Delete deletes it), drag \
         it to another frame, right click for its interpolation",
    );
}

/// The right-click menu of a key marker.
fn key_menu(state: &mut EditorState, ui: &mut Ui, selected: Option<i32>) {
    let Some(frame) = selected else {
        ui.label("Right click a key marker for its menu");
        return;
    };
    let objects = state.timeline.selected_key.as_ref().map(|(_, o)| o.clone()).unwrap_or_default();
    ui.label(format!("Keys at frame {frame}"));
    if Command::DeleteKeys.menu_button(ui, true) {
        state.run(Command::DeleteKeys);
        ui.close();
    }
    ui.separator();
    ui.label("Interpolation to the next key");
    for (interp, tip) in [
        (Interp::Hold, "Keep this value until the next key"),
        (Interp::Linear, "Change at a constant rate"),
        (Interp::Smooth, "Ease out of this key and into the next (never overshoots)"),
    ] {
        if ui.button(format!("{interp:?}")).on_hover_text(tip).clicked() {
            state.session.set_interp(&objects, frame, interp);
            ui.close();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

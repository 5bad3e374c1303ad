//! The Timeline tab and playback: the current frame, the frame range and rate, a scrub bar
//! with the selection's keys as markers (click to select, drag to move, right click for
//! delete and interpolation), and playing in real time or frame by frame.
//!
//! Playback (`playback`) drives the current frame only; the preview follows it as it
//! follows any edit.

use super::commands::Command;
use super::playback::{frames_skipped, next_frame, step_frame, KeyDrag, RealTimeClock};
pub use super::playback::{PlayMode, ScrubBar};
use super::state::EditorState;
use crate::scene::animation::{Animation, Interp, Object};
use egui::{Color32, DragValue, Pos2, Sense, Stroke, Ui, Vec2};

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

//! The editor driven by script: a headless editor window (egui_kittest) on the real pipeline
//! and device, fed the input an artist's pointer, wheel and keys would give, one frame at a
//! time. The interaction benchmark and the editor's tests build and drive the editor through
//! it, so that an input means the same frames in both.
//!
//! The driver dereferences to its [`Harness`], for queries and input it does not name.

use super::app::{PreviewScale, Quality, StartProject};
use super::{EditorApp, EditorOptions};
use egui::{Event, Key, Modifiers, PointerButton, Pos2, Rect, Vec2};
use egui_kittest::Harness;

/// How the editor is opened: window size, preview quality and scale, start-up options.
#[derive(Clone, Debug)]
pub struct DriverSetup {
    /// The window's size in points.
    pub size: Vec2,
    pub quality: Quality,
    /// The preview's resolution; `None` keeps the editor's own default.
    pub preview_scale: Option<PreviewScale>,
    pub options: EditorOptions,
}

impl Default for DriverSetup {
    /// A 1280×800 window with the preview converging every frame at a quarter of the
    /// viewport's pixels: what the tests check does not depend on the march's resolution.
    fn default() -> Self {
        Self {
            size: Vec2::new(1280.0, 800.0),
            quality: Quality::Full,
            preview_scale: Some(PreviewScale::Quarter),
            options: EditorOptions::default(),
        }
    }
}

/// A headless editor under scripted input.
pub struct EditorDriver {
    harness: Harness<'static, EditorApp>,
}

impl EditorDriver {
    /// The editor on `start`, before its first frame.
    pub fn new(start: StartProject, setup: DriverSetup) -> Self {
        let DriverSetup { size, quality, preview_scale, options } = setup;
        let harness = Harness::builder().with_size(size).wgpu_setup(super::wgpu_setup()).build_eframe(move |cc| {
            let mut app = EditorApp::new(cc, start, options);
            app.set_quality(quality);
            if let Some(scale) = preview_scale {
                app.set_preview_scale(scale);
            }
            app
        });
        Self { harness }
    }

    pub fn app(&self) -> &EditorApp {
        self.harness.state()
    }

    pub fn app_mut(&mut self) -> &mut EditorApp {
        self.harness.state_mut()
    }

    /// The viewport's rectangle as laid out in the last frame: read it again after anything
    /// that can move it (a tab opened or closed, the window resized).
    pub fn viewport_rect(&self) -> Option<Rect> {
        self.app().viewport_rect()
    }

    /// Whether the preview shows the converged image of the current project.
    pub fn converged(&self) -> bool {
        self.app().preview_status().is_some_and(|s| s.converged)
    }

    /// Steps until `done` holds after a step, at most `max_steps` times; whether it did.
    pub fn step_until(&mut self, max_steps: usize, done: impl Fn(&EditorApp) -> bool) -> bool {
        for _ in 0..max_steps {
            self.harness.step();
            if done(self.app()) {
                return true;
            }
        }
        false
    }

    /// Steps until the preview has converged, at most `max_steps` times; whether it did.
    pub fn step_until_converged(&mut self, max_steps: usize) -> bool {
        self.step_until(max_steps, |app| app.preview_status().is_some_and(|s| s.converged))
    }

    /// One frame with `event` (if any) as its input, painted as a window's frame is.
    pub fn painted_frame(&mut self, event: Option<Event>) -> Result<(), String> {
        if let Some(e) = event {
            self.harness.event(e);
        }
        self.harness.step();
        self.harness.render().map(|_| ())
    }

    /// A pointer button going down or up at `pos`.
    pub fn button_event(pos: Pos2, button: PointerButton, pressed: bool) -> Event {
        Event::PointerButton { pos, button, pressed, modifiers: Modifiers::NONE }
    }

    /// A wheel turn of `delta_y` points with `modifiers` held.
    pub fn wheel_event(delta_y: f32, modifiers: Modifiers) -> Event {
        Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: Vec2::new(0.0, delta_y),
            phase: egui::TouchPhase::Move,
            modifiers,
        }
    }

    /// The pointer moves to `pos`; one frame.
    pub fn move_to(&mut self, pos: Pos2) {
        self.harness.event(Event::PointerMoved(pos));
        self.harness.step();
    }

    /// `button` goes down (or up) at `pos`; one frame.
    pub fn press(&mut self, pos: Pos2, button: PointerButton, pressed: bool) {
        self.harness.event(Self::button_event(pos, button, pressed));
        self.harness.step();
    }

    /// A click of `button` at `pos`: move there, press, release, and one frame more.
    pub fn click(&mut self, pos: Pos2, button: PointerButton) {
        self.move_to(pos);
        self.press(pos, button, true);
        self.press(pos, button, false);
        self.harness.step();
    }

    /// A primary-button stroke through `points`: the button goes down on the first and up on
    /// the last, one frame per point, and one frame more after the release.
    pub fn stroke(&mut self, points: &[Pos2]) {
        let (Some(&first), Some(&last)) = (points.first(), points.last()) else { return };
        self.stroke_released_at(first, &points[1..], last);
    }

    /// A straight primary-button drag from `from` to `to` in `steps` moves, released at `to`.
    pub fn drag(&mut self, from: Pos2, to: Pos2, steps: usize) {
        let moves: Vec<Pos2> = (1..=steps).map(|k| from + (to - from) * (k as f32 / steps as f32)).collect();
        self.stroke_released_at(from, &moves, to);
    }

    fn stroke_released_at(&mut self, first: Pos2, moves: &[Pos2], release: Pos2) {
        self.move_to(first);
        self.press(first, PointerButton::Primary, true);
        for &p in moves {
            self.move_to(p);
        }
        self.press(release, PointerButton::Primary, false);
        self.harness.step();
    }

    /// A wheel turn of `delta_y` points with `modifiers` held; one frame.
    pub fn wheel(&mut self, delta_y: f32, modifiers: Modifiers) {
        self.harness.event(Self::wheel_event(delta_y, modifiers));
        self.harness.step();
    }

    /// `key` pressed and released with `modifiers` held, as a shortcut: two frames.
    pub fn shortcut(&mut self, modifiers: Modifiers, key: Key) {
        self.harness.key_press_modifiers(modifiers, key);
        self.harness.run_steps(2);
    }
}

impl std::ops::Deref for EditorDriver {
    type Target = Harness<'static, EditorApp>;
    fn deref(&self) -> &Self::Target {
        &self.harness
    }
}

impl std::ops::DerefMut for EditorDriver {
    fn deref_mut(&mut self) -> &mut Self::Target {
        &mut self.harness
    }
}

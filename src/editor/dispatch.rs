//! Command dispatch: what each [`Command`] does, and the keyboard (shortcuts and held
//! arrow keys).

use super::commands::Command;
use super::session::NEW_STEP;
use super::state::{Action, EditorState, Gesture, Modal};
use egui::{Context, Key};

impl EditorState {
    pub(super) fn shortcuts(&mut self, ctx: &Context) {
        let typing = ctx.egui_wants_keyboard_input();
        let pointer = ctx.input(|i| i.pointer.hover_pos());
        let in_viewport = pointer.zip(self.view.viewport_rect).is_some_and(|(p, r)| r.contains(p));
        for command in Command::pressed(ctx, typing, in_viewport) {
            self.run(command);
        }
        if typing || ctx.input(|i| i.modifiers.command) {
            return;
        }
        let step = 0.08;
        // In an animated project Left and Right step frames.
        let sideways = self.session.project().animation.is_none();
        let orbit = ctx.input(|i| {
            let mut d = glam::Vec2::ZERO;
            if sideways && i.key_down(Key::ArrowLeft) {
                d.x -= step;
            }
            if sideways && i.key_down(Key::ArrowRight) {
                d.x += step;
            }
            if i.key_down(Key::ArrowUp) {
                d.y += step;
            }
            if i.key_down(Key::ArrowDown) {
                d.y -= step;
            }
            d
        });
        if orbit != glam::Vec2::ZERO {
            let c = super::view::orbit(&self.session.project().camera, orbit.x, orbit.y);
            self.session.set_camera(c);
        }
    }

    /// Runs `command`, from a menu or a shortcut.
    pub(crate) fn run(&mut self, command: Command) {
        use super::view::AxisView;
        self.last_command = Some(command);
        let zoom = |s: &mut Self, f: f32| {
            let c = super::view::zoom(&s.session.project().camera, f);
            s.session.set_camera(c);
        };
        match command {
            Command::New => self.request(Action::New),
            Command::Open => self.request(Action::OpenDialog),
            Command::Save => self.save(),
            Command::SaveAs => self.save_as_dialog(),
            Command::ImportVdb => self.import_vdb_dialog(),
            Command::Export => self.open_export_window(),
            Command::Revert => self.request(Action::Revert),
            Command::RemoveBaseVolume => {
                if self.session.project().base_volume.is_some() {
                    self.session.edit(NEW_STEP).base_volume = None;
                }
            }
            Command::Quit => self.request(Action::Quit),
            Command::Undo => self.undo(),
            Command::Redo => self.redo(),
            Command::SelectAll => self.session.select_all(),
            Command::Duplicate => self.duplicate(),
            Command::Delete => {
                if !self.delete_selected_keys() {
                    self.delete();
                }
            }
            Command::Escape => {
                if self.view.modal.is_some() {
                    self.cancel_modal();
                } else if matches!(self.view.gesture, Some(Gesture::Gizmo { .. })) {
                    self.cancel_gizmo();
                } else if self.export.window.is_some() {
                    self.export.window = None;
                } else if self.view.show_shortcuts {
                    self.view.show_shortcuts = false;
                } else {
                    self.session.selection.clear();
                }
            }
            Command::Grab | Command::ScaleSelection => {
                let scale = command == Command::ScaleSelection;
                let start = self.ctx.input(|i| i.pointer.hover_pos());
                let applicable = if scale {
                    !self.session.selection.particles.is_empty()
                } else {
                    !self.session.selection.is_empty()
                };
                if let (Some(start), true, true) = (start, applicable, self.view.modal.is_none()) {
                    self.start_modal(scale, start);
                }
            }
            Command::FitGrid => super::viewport::fit_grid(self),
            Command::ToolSelect | Command::ToolPaint | Command::ToolScale | Command::ToolErase | Command::ToolLight => {
                if let Some(tool) = command.tool() {
                    self.view.tool = tool;
                }
            }
            Command::FrameSelection => self.frame_selection(),
            Command::ViewFront => self.axis_view(AxisView::Front),
            Command::ViewRight => self.axis_view(AxisView::Right),
            Command::ViewTop => self.axis_view(AxisView::Top),
            Command::ViewBack => self.axis_view(AxisView::Back),
            Command::ViewLeft => self.axis_view(AxisView::Left),
            Command::ZoomIn => zoom(self, 0.85),
            Command::ZoomOut => zoom(self, 1.0 / 0.85),
            Command::SliceNext | Command::SlicePrevious => {
                let max =
                    self.session.project().grid.resolution.to_array()[self.view.slices.axis.index()].saturating_sub(1);
                let i = self.view.slices.index.min(max);
                self.view.slices.index =
                    if command == Command::SliceNext { (i + 1).min(max) } else { i.saturating_sub(1) };
            }
            Command::PanelViewport
            | Command::PanelSlices
            | Command::PanelOutliner
            | Command::PanelInspector
            | Command::PanelStats
            | Command::PanelTimeline
            | Command::ResetLayout => self.dock_commands.push(command),
            Command::ParticleOutlines => self.view.outline_all = !self.view.outline_all,
            Command::SlicePlane => self.view.show_slice_plane = !self.view.show_slice_plane,
            Command::MoveGizmo => self.view.show_gizmo = !self.view.show_gizmo,
            Command::Shortcuts => self.view.show_shortcuts = !self.view.show_shortcuts,
            Command::Animate => {
                if self.session.project().animation.is_none() {
                    self.session.animate(crate::scene::animation::Animation::default());
                }
            }
            Command::PlayPause => self.toggle_play(),
            Command::PreviousFrame | Command::NextFrame | Command::FirstFrame | Command::LastFrame => {
                self.step(command)
            }
            Command::InsertKey => {
                if self.session.selection.is_empty() {
                    self.info("Select particles or lights to key (the Inspector's diamonds key single values)");
                } else {
                    let n = self.session.key_selection();
                    self.info(format!("{n} values keyed at frame {}", self.session.frame()));
                }
            }
            Command::DeleteKeys => {
                if !self.delete_selected_keys() {
                    self.info("Select a key marker in the Timeline first");
                }
            }
            Command::AutoKey => self.session.auto_key = !self.session.auto_key,
            Command::LoopPlayback => self.timeline.looping = !self.timeline.looping,
            Command::PerPixelMarch => self.view.per_pixel_march = !self.view.per_pixel_march,
            Command::PlayEveryFrame => {
                use super::playback::PlayMode;
                self.timeline.mode = match self.timeline.mode {
                    PlayMode::RealTime => PlayMode::EveryFrame,
                    PlayMode::EveryFrame => PlayMode::RealTime,
                };
            }
        }
    }

    pub(super) fn start_modal(&mut self, scale: bool, start: egui::Pos2) {
        let tag = self.session.new_tag();
        self.view.modal = Some(Modal { scale, tag, start, applied: glam::Vec3::ZERO, applied_factor: 1.0 });
    }

    pub(crate) fn cancel_modal(&mut self) {
        if let Some(m) = self.view.modal.take() {
            if m.applied != glam::Vec3::ZERO || m.applied_factor != 1.0 {
                self.session.undo();
            }
        }
    }

    /// Ends a move-gizmo drag, putting the selection back where the drag began.
    pub(crate) fn cancel_gizmo(&mut self) {
        if let Some(Gesture::Gizmo { tag, .. }) = self.view.gesture {
            self.session.cancel_edit(tag);
            self.view.gesture = Some(Gesture::Cancelled);
        }
    }

    pub(crate) fn undo(&mut self) {
        self.view.modal = None;
        self.timeline.selected_key = None;
        if !self.session.undo() {
            self.info("Nothing to undo");
        }
    }

    pub(crate) fn redo(&mut self) {
        self.view.modal = None;
        self.timeline.selected_key = None;
        if !self.session.redo() {
            self.info("Nothing to redo");
        }
    }

    pub(crate) fn delete(&mut self) {
        self.session.delete_selection();
    }

    pub(crate) fn duplicate(&mut self) {
        let offset = self.session.project().grid.cell_size().max_element() * 2.0;
        self.session.duplicate_selection(glam::Vec3::new(offset, 0.0, offset));
    }

    pub(crate) fn frame_selection(&mut self) {
        let p = self.session.project();
        let (center, radius) = match self.session.selection_center() {
            Some(c) => {
                let r = self
                    .session
                    .selection
                    .particles
                    .iter()
                    .filter_map(|&i| p.particles.get(i))
                    .map(|q| (q.center - c).length() + q.radius * 2.0)
                    .chain(
                        self.session
                            .selection
                            .lights
                            .iter()
                            .filter_map(|&i| p.lights.get(i))
                            .map(|l| (p.light_anchor(l) - c).length() + 0.1),
                    )
                    .fold(0.1f32, f32::max);
                (c, r)
            }
            None => ((p.grid.min + p.grid.max) * 0.5, p.grid.size().length() * 0.5),
        };
        let c = super::view::frame(&p.camera, center, radius);
        self.session.set_camera(c);
    }

    pub(crate) fn axis_view(&mut self, v: super::view::AxisView) {
        let p = self.session.project();
        let c = super::view::axis_view(&p.camera, &p.grid, v);
        self.session.set_camera(c);
    }
}

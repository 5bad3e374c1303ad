//! The menu bar. Every item is a [`Command`], run through the same dispatch as its shortcut.

use super::commands::Command;
use super::layout::Tab;
use super::state::{Action, EditorState};
use egui_dock::DockState;

impl EditorState {
    /// File, Edit, View, Preview, Animation and Help. Panel commands need the dock, so the view menu reads it
    /// to show which panels are open.
    pub(super) fn menu_bar(&mut self, ui: &mut egui::Ui, dock: &DockState<Tab>) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| self.file_menu(ui));
            ui.menu_button("Edit", |ui| self.edit_menu(ui));
            ui.menu_button("View", |ui| self.view_menu(ui, dock));
            ui.menu_button("Preview", |ui| {
                if Command::PerPixelMarch.menu_checkbox(ui, self.view.per_pixel_march) {
                    self.run(Command::PerPixelMarch);
                }
            });
            ui.menu_button("Animation", |ui| self.animation_menu(ui));
            ui.menu_button("Help", |ui| self.command_button(ui, Command::Shortcuts, true));
        });
    }

    /// A menu button for `command`; runs it when clicked.
    fn command_button(&mut self, ui: &mut egui::Ui, command: Command, enabled: bool) {
        if command.menu_button(ui, enabled) {
            self.run(command);
        }
    }

    fn view_menu(&mut self, ui: &mut egui::Ui, dock: &DockState<Tab>) {
        ui.label("Panels");
        for tab in Tab::ALL {
            let open = dock.find_tab(&tab).is_some();
            let command = Command::for_panel(tab);
            if command.menu_checkbox(ui, open) {
                self.run(command);
            }
        }
        self.command_button(ui, Command::ResetLayout, true);
        ui.separator();
        let toggles = [
            (Command::ParticleOutlines, self.view.outline_all),
            (Command::SlicePlane, self.view.show_slice_plane),
            (Command::MoveGizmo, self.view.show_gizmo),
        ];
        for (command, on) in toggles {
            if command.menu_checkbox(ui, on) {
                self.run(command);
            }
        }
        ui.separator();
        ui.label("Camera");
        self.camera_menu(ui);
    }

    fn animation_menu(&mut self, ui: &mut egui::Ui) {
        let animated = self.session.project().animation.is_some();
        if !animated {
            self.command_button(ui, Command::Animate, true);
            ui.separator();
        }
        for c in
            [Command::PlayPause, Command::PreviousFrame, Command::NextFrame, Command::FirstFrame, Command::LastFrame]
        {
            self.command_button(ui, c, animated);
        }
        ui.separator();
        self.command_button(ui, Command::InsertKey, !self.session.selection.is_empty());
        self.command_button(ui, Command::DeleteKeys, self.timeline.selected_key.is_some());
        ui.separator();
        let toggles = [
            (Command::AutoKey, self.session.auto_key),
            (Command::LoopPlayback, self.timeline.looping),
            (Command::PlayEveryFrame, self.timeline.mode == super::playback::PlayMode::EveryFrame),
        ];
        for (command, on) in toggles {
            if command.menu_checkbox(ui, on) {
                self.run(command);
            }
        }
    }

    fn camera_menu(&mut self, ui: &mut egui::Ui) {
        for c in [
            Command::ViewFront,
            Command::ViewBack,
            Command::ViewRight,
            Command::ViewLeft,
            Command::ViewTop,
            Command::FrameSelection,
            Command::ZoomIn,
            Command::ZoomOut,
        ] {
            self.command_button(ui, c, true);
        }
    }

    fn file_menu(&mut self, ui: &mut egui::Ui) {
        for c in [Command::New, Command::Open] {
            self.command_button(ui, c, true);
        }
        ui.menu_button("Open Recent", |ui| {
            if self.recent.is_empty() {
                ui.label("No recent projects");
            }
            for path in self.recent.clone() {
                if ui.button(path.display().to_string()).clicked() {
                    self.request(Action::Open(path));
                }
            }
        });
        ui.separator();
        for c in [Command::Save, Command::SaveAs, Command::Export] {
            self.command_button(ui, c, true);
        }
        ui.separator();
        self.command_button(ui, Command::ImportVdb, true);
        if self.session.project().base_volume.is_some() {
            self.command_button(ui, Command::RemoveBaseVolume, true);
        }
        let can_revert = self.session.path().is_some();
        self.command_button(ui, Command::Revert, can_revert);
        ui.separator();
        self.command_button(ui, Command::Quit, true);
    }

    fn edit_menu(&mut self, ui: &mut egui::Ui) {
        let undo = self.session.undo_label().map_or("Undo".to_string(), |l| format!("Undo {l}"));
        if Command::Undo.menu_button_text(ui, self.session.can_undo(), &undo) {
            self.run(Command::Undo);
        }
        let redo = self.session.redo_label().map_or("Redo".to_string(), |l| format!("Redo {l}"));
        if Command::Redo.menu_button_text(ui, self.session.can_redo(), &redo) {
            self.run(Command::Redo);
        }
        ui.separator();
        let has_selection = !self.session.selection.is_empty();
        for (c, enabled) in
            [(Command::SelectAll, true), (Command::Duplicate, has_selection), (Command::Delete, has_selection)]
        {
            self.command_button(ui, c, enabled);
        }
        ui.separator();
        let has_particles = !self.session.project().particles.is_empty();
        self.command_button(ui, Command::FitGrid, has_particles);
    }
}

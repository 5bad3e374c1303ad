//! File actions: new, open, save, revert and quit (asking first when they would discard
//! unsaved changes), the file dialogs they open, recent files, dropped files and
//! File → Import VDB….

use super::files::{DialogKind, DialogSpec, FileDialogs};
use super::state::{Action, EditorState, JobResult, LoadJob, Pick};
use crate::scene::{load_project_with, save_project, Project};
use egui::{Context, Id};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Most recent files remembered.
const MAX_RECENT: usize = 10;

impl EditorState {
    /// A file dropped on the window: a project opens (asking first about unsaved changes),
    /// a VDB goes to the import window.
    pub(super) fn open_dropped(&mut self, ctx: &Context) {
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw.dropped_files.iter().map(|f| f.path().to_path_buf()).filter(|p| !p.as_os_str().is_empty()).collect()
        });
        if let Some(path) = dropped.into_iter().next() {
            let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            if ext == "ron" {
                self.request(Action::Open(path));
            } else if ext == "vdb" {
                self.import_vdb(path);
            } else {
                self.error(format!("{}: not a Fogsmith project or VDB; drop a .ron or .vdb file", path.display()));
            }
        }
    }

    /// Reads a project in a background thread, as [`Self::spawn`] does, with the steps of
    /// its load (which `read` reports through the callback it is given) in the status bar.
    pub(super) fn spawn_load(
        &mut self,
        label: &str,
        file: &Path,
        read: impl FnOnce(&mut dyn FnMut(&str, f64)) -> JobResult + Send + 'static,
    ) {
        let steps = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
        let name = file.file_name().map_or_else(|| file.display().to_string(), |n| n.to_string_lossy().into_owned());
        self.jobs.load = Some(LoadJob { name, started: Instant::now(), steps: steps.clone() });
        let ctx = self.ctx.clone();
        self.spawn(label, move || {
            read(&mut |step, fraction| {
                if let Ok(mut steps) = steps.lock() {
                    steps.push((step.to_owned(), fraction));
                }
                ctx.request_repaint();
            })
        });
    }

    /// Ends the load in progress, keeping its steps.
    pub(super) fn finish_load(&mut self) {
        if let Some(load) = self.jobs.load.take() {
            let steps = load.steps.lock().map(|s| s.iter().map(|(step, _)| step.clone()).collect());
            self.jobs.last_load_steps = steps.unwrap_or_default();
        }
    }

    pub(super) fn push_recent(&mut self, path: PathBuf) {
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.recent.retain(|p| p != &path);
        self.recent.insert(0, path);
        self.recent.truncate(MAX_RECENT);
    }

    pub(crate) fn request(&mut self, action: Action) {
        let discards = !matches!(action, Action::Quit) || !self.quit_confirmed;
        if self.session.is_dirty() && discards {
            self.confirm = Some(action);
        } else {
            self.perform(action);
        }
    }

    pub(super) fn perform(&mut self, action: Action) {
        match action {
            Action::New => self.replace_project(Project::new_empty(), None, "untitled.ron"),
            Action::OpenDialog => {
                let spec = DialogSpec {
                    title: "Open project",
                    filter: "Fogsmith project",
                    extension: "ron",
                    file_name: None,
                    directory: self.dialog_directory(DialogKind::Open),
                };
                self.choose_file(Pick::Open, spec);
            }
            Action::Open(path) => {
                let p = path.clone();
                self.spawn_load(&format!("Opening {}", path.display()), &path, move |progress| JobResult::Loaded {
                    result: load_project_with(&p, progress).map(Box::new).map_err(|e| e.to_string()),
                    path: p,
                });
            }
            Action::Revert => match self.session.path().map(Path::to_owned) {
                Some(path) => self.perform(Action::Open(path)),
                None => self.info("Nothing to revert to: the project has never been saved"),
            },
            Action::Quit => {
                self.quit_confirmed = true;
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }

    pub(crate) fn save(&mut self) {
        match self.session.path().map(Path::to_owned) {
            Some(path) => self.save_to(path),
            None => self.save_as_dialog(),
        }
    }

    pub(super) fn save_as_dialog(&mut self) {
        let name = self.session.name().split(' ').next().unwrap_or("untitled.ron").to_owned();
        let spec = DialogSpec {
            title: "Save project as",
            filter: "Fogsmith project",
            extension: "ron",
            file_name: Some(name),
            directory: self.dialog_directory(DialogKind::SaveAs),
        };
        self.choose_file(Pick::SaveAs, spec);
    }

    /// Where a dialog of `kind` starts: the folder it last chose for this project (or the
    /// folder any dialog of the project last chose), else the project's folder.
    pub(super) fn dialog_directory(&self, kind: DialogKind) -> Option<PathBuf> {
        let project_folder =
            || self.session.path().and_then(Path::parent).filter(|d| !d.as_os_str().is_empty()).map(Path::to_owned);
        self.folders.get(self.session.path(), kind).or_else(project_folder)
    }

    /// Asks for a file with the system's dialog, or the built-in one where that cannot open.
    pub(super) fn choose_file(&mut self, purpose: Pick, spec: DialogSpec) {
        if self.built_in_dialog.is_some() {
            self.info("A file dialog is already open");
            return;
        }
        match &self.file_dialogs {
            FileDialogs::System => {
                let label = if spec.is_save() { "Choosing where to save" } else { "Choosing a file" };
                self.spawn(label, move || {
                    let started = Instant::now();
                    let path = spec.run_system();
                    JobResult::Picked { purpose, path, seconds: started.elapsed().as_secs_f64(), spec: Box::new(spec) }
                });
            }
            FileDialogs::BuiltIn { reason } => {
                if !self.built_in_explained {
                    self.built_in_explained = true;
                    let text = format!("Using Fogsmith's file dialog: {reason}");
                    self.info(text);
                }
                self.open_built_in(purpose, &spec);
            }
        }
    }

    pub(super) fn open_built_in(&mut self, purpose: Pick, spec: &DialogSpec) {
        self.built_in_dialog = Some((purpose, spec.built_in()));
    }

    /// Shows the built-in dialog and acts on its choice.
    pub(super) fn built_in_dialog(&mut self, ctx: &Context) {
        let Some((purpose, dialog)) = &mut self.built_in_dialog else { return };
        let purpose = *purpose;
        dialog.update(ctx);
        let picked = dialog.take_picked();
        let open = matches!(dialog.state(), egui_file_dialog::DialogState::Open);
        if let Some(path) = picked {
            self.built_in_dialog = None;
            self.picked(purpose, path);
        } else if !open {
            self.built_in_dialog = None;
            self.after_save = None;
        }
    }

    /// File → Import VDB…: asks for the file (as Open does), then shows the grid picker.
    pub(crate) fn import_vdb_dialog(&mut self) {
        let spec = DialogSpec {
            title: "Import VDB",
            filter: "OpenVDB",
            extension: "vdb",
            file_name: None,
            directory: self.dialog_directory(DialogKind::ImportVdb),
        };
        self.choose_file(Pick::ImportVdb, spec);
    }

    /// Opens the import window on `path` directly (a dropped file, scripted use).
    pub(crate) fn import_vdb(&mut self, path: PathBuf) {
        self.picked(Pick::ImportVdb, path);
    }

    pub(super) fn import_window(&mut self, ctx: &Context) {
        let Some(import) = &mut self.import else { return };
        let analytic = self.session.project().propagation.scheme == crate::scene::Scheme::Analytic;
        match import.ui(ctx, analytic) {
            Some(true) => {
                let base = import.base_volume(self.session.path());
                self.import = None;
                let mut text =
                    format!("Base volume: grid {:?} of {}, × {}", base.grid, base.path.display(), base.scale);
                // One undo step: the volume and the scheme that can show it.
                let project = self.session.edit(super::session::NEW_STEP);
                project.base_volume = Some(base);
                if analytic {
                    project.propagation.scheme = crate::scene::Scheme::Sweep;
                    text.push_str("; the scheme is now sweep");
                }
                self.info(text);
            }
            Some(false) => self.import = None,
            None => {}
        }
    }

    pub(super) fn picked(&mut self, purpose: Pick, path: PathBuf) {
        let kind = match purpose {
            Pick::Open => DialogKind::Open,
            Pick::SaveAs => DialogKind::SaveAs,
            Pick::Export(_) => DialogKind::Export,
            Pick::ImportVdb => DialogKind::ImportVdb,
        };
        let project = self.session.path().map(Path::to_owned);
        self.folders.remember(project.as_deref(), kind, &path);
        match purpose {
            Pick::Open => self.perform(Action::Open(path)),
            Pick::SaveAs => self.save_to(path),
            Pick::Export(choices) => self.export_to(choices, path),
            Pick::ImportVdb => match super::import::ImportVdb::open(path) {
                Ok(import) => self.import = Some(import),
                Err(e) => self.error(format!("Cannot import: {e}")),
            },
        }
    }

    pub(crate) fn save_to(&mut self, path: PathBuf) {
        let path = if path.extension().is_none() { path.with_extension("ron") } else { path };
        let project = self.session.project().clone();
        let generation = self.session.generation();
        let p = path.clone();
        self.spawn(&format!("Saving {}", path.display()), move || JobResult::Saved {
            result: save_project(&p, &project).map_err(|e| e.to_string()),
            path: p,
            generation,
        });
    }

    pub(super) fn confirm_dialog(&mut self, ctx: &Context) {
        let Some(action) = self.confirm.clone() else { return };
        let what = match &action {
            Action::New => "starting a new project",
            Action::OpenDialog | Action::Open(_) => "opening another project",
            Action::Revert => "reverting",
            Action::Quit => "quitting",
        };
        let mut choice = None;
        egui::Modal::new(Id::new("confirm-discard")).show(ctx, |ui| {
            ui.heading("Unsaved changes");
            ui.label(format!("{} has unsaved changes. Save them before {what}?", self.session.name()));
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    choice = Some(0);
                }
                if ui.button("Discard").clicked() {
                    choice = Some(1);
                }
                if ui.button("Cancel").clicked() {
                    choice = Some(2);
                }
            });
        });
        match choice {
            Some(0) => {
                self.confirm = None;
                self.after_save = Some(action);
                self.save();
            }
            Some(1) => {
                self.confirm = None;
                if action == Action::Quit {
                    self.quit_confirmed = true;
                }
                self.perform(action);
            }
            Some(_) => self.confirm = None,
            None => {}
        }
    }
}

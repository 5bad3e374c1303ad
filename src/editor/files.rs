//! File dialogs. The system's dialog (through rfd: the desktop portal, else zenity) is used
//! where it can open; where it cannot (no D-Bus session, no portal answering, no zenity, as
//! under Xvfb or minimal window managers) Fogsmith's own dialog (egui-file-dialog) takes
//! its place and the window says why, so choosing a file never fails silently.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// Which dialogs the editor uses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FileDialogs {
    /// The system's dialog; if it closes at once without a choice it could not open, and
    /// the built-in dialog takes over.
    System,
    /// The built-in dialog, for the reason given.
    BuiltIn { reason: String },
}

impl FileDialogs {
    /// Decides from the process environment; `FOGSMITH_FILE_DIALOG=builtin|system` overrides.
    pub fn detect() -> Self {
        Self::detect_with(|k| std::env::var_os(k))
    }

    /// Decides from the environment variables `env` returns.
    pub fn detect_with(env: impl Fn(&str) -> Option<OsString>) -> Self {
        match env("FOGSMITH_FILE_DIALOG").as_deref().and_then(|v| v.to_str()) {
            Some("builtin") => return Self::BuiltIn { reason: "FOGSMITH_FILE_DIALOG=builtin".into() },
            Some("system") => return Self::System,
            _ => {}
        }
        if !cfg!(all(unix, not(target_os = "macos"))) {
            return Self::System;
        }
        let bus = env("DBUS_SESSION_BUS_ADDRESS").is_some_and(|v| !v.is_empty())
            || env("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).join("bus").exists());
        let zenity = env("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("zenity").is_file()));
        if bus || zenity {
            Self::System
        } else {
            Self::BuiltIn { reason: "no D-Bus session for a desktop portal and no zenity".into() }
        }
    }
}

/// What a dialog asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DialogSpec {
    pub title: &'static str,
    pub filter: &'static str,
    pub extension: &'static str,
    /// Save dialogs propose this file name; open dialogs have none.
    pub file_name: Option<String>,
    /// Where the dialog starts.
    pub directory: Option<PathBuf>,
}

impl DialogSpec {
    pub fn is_save(&self) -> bool {
        self.file_name.is_some()
    }

    /// Runs the system dialog (blocking; call from a worker thread).
    pub fn run_system(&self) -> Option<PathBuf> {
        let mut d = rfd::FileDialog::new().set_title(self.title).add_filter(self.filter, &[self.extension]);
        if let Some(dir) = &self.directory {
            d = d.set_directory(dir);
        }
        match &self.file_name {
            Some(name) => d.set_file_name(name).save_file(),
            None => d.pick_file(),
        }
    }

    /// The built-in dialog, opened.
    pub fn built_in(&self) -> egui_file_dialog::FileDialog {
        let mut d = egui_file_dialog::FileDialog::new()
            .id(egui::Id::new("fogsmith-file-dialog"))
            .title(self.title)
            .add_file_filter_extensions(self.filter, vec![self.extension])
            .default_file_filter(self.filter)
            .add_save_extension(self.filter, self.extension)
            .default_save_extension(self.filter)
            .default_size([720.0, 440.0]);
        if let Some(dir) = self.directory.clone().or_else(|| std::env::current_dir().ok()) {
            d = d.initial_directory(dir);
        }
        match &self.file_name {
            Some(name) => {
                d = d.default_file_name(name);
                d.save_file();
            }
            None => d.pick_file(),
        }
        d
    }
}

/// A system dialog that returns nothing this quickly never showed: no person cancels a file
/// dialog within a quarter of a second.
pub const NO_DIALOG_SECONDS: f64 = 0.25;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_built_in_dialog_is_chosen_without_a_portal_or_zenity() {
        let none = FileDialogs::detect_with(|_| None);
        assert!(matches!(none, FileDialogs::BuiltIn { .. }), "{none:?}");
        let bus =
            FileDialogs::detect_with(|k| (k == "DBUS_SESSION_BUS_ADDRESS").then(|| "unix:path=/run/user/1/bus".into()));
        if cfg!(all(unix, not(target_os = "macos"))) {
            assert_eq!(bus, FileDialogs::System);
        }
        let forced = FileDialogs::detect_with(|k| match k {
            "FOGSMITH_FILE_DIALOG" => Some("builtin".into()),
            _ => Some("unix:path=/x".into()),
        });
        assert!(matches!(forced, FileDialogs::BuiltIn { .. }));
    }
}

/// The kinds of file dialog, each remembering its own folder.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum DialogKind {
    Open,
    SaveAs,
    Export,
    ImportVdb,
}

/// Folders remembered, most recent first.
const MAX_FOLDERS: usize = 256;

/// The folder where each kind of dialog last chose a file, per project (by its file; the
/// untitled project under `None`), remembered between runs. A dialog starts in its own kind's
/// folder, else in the folder any dialog of the project last chose, else the project's.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DialogFolders {
    entries: Vec<(Option<PathBuf>, DialogKind, PathBuf)>,
}

impl DialogFolders {
    /// Where a dialog of `kind` for `project` starts, if one was remembered and still exists.
    pub fn get(&self, project: Option<&Path>, kind: DialogKind) -> Option<PathBuf> {
        let mine = |e: &&(Option<PathBuf>, DialogKind, PathBuf)| e.0.as_deref() == project && e.2.is_dir();
        let of_kind = self.entries.iter().filter(mine).find(|e| e.1 == kind);
        of_kind.or_else(|| self.entries.iter().find(mine)).map(|e| e.2.clone())
    }

    /// `file` was chosen in a dialog of `kind` for `project`: its folder is remembered.
    pub fn remember(&mut self, project: Option<&Path>, kind: DialogKind, file: &Path) {
        let Some(folder) = file.parent().filter(|d| !d.as_os_str().is_empty()) else { return };
        let folder = std::fs::canonicalize(folder).unwrap_or_else(|_| folder.to_path_buf());
        let project = project.map(Path::to_path_buf);
        self.entries.retain(|e| !(e.0 == project && e.1 == kind));
        self.entries.insert(0, (project, kind, folder));
        self.entries.truncate(MAX_FOLDERS);
    }
}

/// Why files cannot be written in `path`'s folder, in the words a dialog's error needs; None
/// when they can. Checked before an export bakes anything.
pub fn output_folder_problem(path: &Path) -> Option<String> {
    let folder = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    if !folder.exists() {
        return Some(format!(
            "the folder {} does not exist; choose an existing folder (or create it first)",
            folder.display()
        ));
    }
    if !folder.is_dir() {
        return Some(format!("{} is not a folder; choose a folder to write in", folder.display()));
    }
    let probe = folder.join(format!(".fogsmith-write-check-{}", std::process::id()));
    match std::fs::OpenOptions::new().write(true).create_new(true).open(&probe) {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            None
        }
        Err(e) => {
            Some(format!("cannot write in the folder {}: {e}; choose a folder you can write to", folder.display()))
        }
    }
}

#[cfg(test)]
mod folder_tests {
    use super::*;

    #[test]
    fn each_dialog_kind_remembers_its_folder_per_project() {
        let root = std::env::temp_dir().join(format!("fogsmith-folders-{}", std::process::id()));
        let (a, b) = (root.join("a"), root.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        let (a, b) = (std::fs::canonicalize(&a).unwrap(), std::fs::canonicalize(&b).unwrap());
        let p = root.join("p.ron");
        let mut f = DialogFolders::default();
        assert_eq!(f.get(Some(&p), DialogKind::Export), None);
        f.remember(Some(&p), DialogKind::Export, &a.join("fog.vdb"));
        assert_eq!(f.get(Some(&p), DialogKind::Export), Some(a.clone()));
        assert_eq!(
            f.get(Some(&p), DialogKind::Open),
            Some(a.clone()),
            "other kinds start where the project's last dialog chose"
        );
        assert_eq!(f.get(None, DialogKind::Export), None, "another project has its own folders");
        f.remember(Some(&p), DialogKind::SaveAs, &b.join("p2.ron"));
        assert_eq!(f.get(Some(&p), DialogKind::Export), Some(a.clone()));
        assert_eq!(f.get(Some(&p), DialogKind::SaveAs), Some(b.clone()));
        std::fs::remove_dir_all(&a).unwrap();
        assert_eq!(f.get(Some(&p), DialogKind::Export), Some(b), "a folder since removed is skipped");
        assert!(output_folder_problem(&root.join("missing/fog.vdb")).unwrap().contains("does not exist"));
        assert_eq!(output_folder_problem(&root.join("b/fog.vdb")), None);
        let _ = std::fs::remove_dir_all(&root);
    }
}

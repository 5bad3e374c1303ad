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

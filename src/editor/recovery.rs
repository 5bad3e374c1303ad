//! Crash recovery: while there are unsaved changes a recovery file is written every few
//! seconds in the background; at start, work left by an earlier run is offered back.

use super::state::{EditorState, JobResult, RecoveryWritten};
use egui::Context;
use std::path::Path;

/// Seconds between recovery files while there are unsaved changes: `FOGSMITH_AUTOSAVE_SECS`,
/// default 5.
fn recovery_interval_s() -> f64 {
    static SECS: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *SECS.get_or_init(|| {
        std::env::var("FOGSMITH_AUTOSAVE_SECS")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(5.0)
    })
}

impl EditorState {
    /// Turns recovery on: finds what earlier runs left, to offer it back.
    pub(super) fn find_recoveries(&mut self) {
        let dir = crate::scene::recovery::state_dir();
        for found in crate::scene::recovery::find_recoveries(&dir) {
            match found {
                Ok(r) => self.recovery.found.push(r),
                Err(e) => self.error(format!("A recovery file could not be read: {e}")),
            }
        }
        self.recovery.dir = Some(dir);
    }

    /// Removes this session's recovery file: its work was saved or deliberately dropped.
    pub(super) fn drop_recovery(&mut self) {
        if let (Some(dir), Some(_)) = (&self.recovery.dir, self.recovery.written.take()) {
            let path = crate::scene::recovery::recovery_path(dir, self.session.path());
            if let Err(e) = crate::scene::recovery::remove_recovery(&path) {
                self.error(e.to_string());
            }
        }
    }

    /// Every few seconds while there are unsaved changes, writes a recovery file in the
    /// background.
    pub(super) fn write_recovery(&mut self, now: f64) {
        let Some(dir) = self.recovery.dir.clone() else { return };
        if !self.session.is_dirty() {
            return;
        }
        let version = self.content_version();
        if let Some(written) = self.recovery.written {
            if written.version == version || now - written.at < recovery_interval_s() {
                return;
            }
        }
        self.recovery.written = Some(RecoveryWritten { version, at: now });
        let project = self.session.project().clone();
        let original = self.session.path().map(Path::to_owned);
        let tx = self.jobs.tx.clone();
        std::thread::spawn(move || {
            if let Err(e) = crate::scene::recovery::write_recovery(&dir, original.as_deref(), &project) {
                let _ = tx.send(JobResult::Exported {
                    path: dir,
                    result: Err(format!("could not write the recovery file: {e}")),
                });
            }
        });
    }

    pub(super) fn recovery_dialog(&mut self, ctx: &Context) {
        if self.recovery.found.is_empty() {
            return;
        }
        let mut action = None;
        egui::Window::new("Recover unsaved work").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label("Fogsmith did not exit cleanly last time. This work was not saved:");
            for (i, (_, rec)) in self.recovery.found.iter().enumerate() {
                ui.horizontal(|ui| {
                    let name =
                        rec.original.as_ref().map_or("untitled project".to_string(), |p| p.display().to_string());
                    ui.label(format!(
                        "{name} ({} particles, {} lights)",
                        rec.project.particles.len(),
                        rec.project.lights.len()
                    ));
                    if ui
                        .button("Restore")
                        .on_hover_text("Open this work (unsaved) in place of the current project")
                        .clicked()
                    {
                        action = Some((i, true));
                    }
                    if ui.button("Discard").on_hover_text("Delete the recovery file").clicked() {
                        action = Some((i, false));
                    }
                });
            }
        });
        if let Some((i, restore)) = action {
            let (file, rec) = self.recovery.found.remove(i);
            if restore {
                self.replace_project(rec.project, rec.original, "recovered.ron");
                self.session.mark_unsaved();
            }
            if let Err(e) = crate::scene::recovery::remove_recovery(&file) {
                self.error(e.to_string());
            }
        }
    }
}

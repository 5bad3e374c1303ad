//! Crash recovery: while there are unsaved changes a recovery file is written when an edit
//! ends and every few seconds during a long one, on a background thread; at start, work left
//! by an earlier run is offered back.

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
        let dir = self.options.state_dir.clone().unwrap_or_else(crate::scene::recovery::state_dir);
        for found in crate::scene::recovery::list_recoveries(&dir) {
            match found {
                Ok(r) => self.recovery.found.push(r),
                Err(e) => self.error(format!("A recovery file could not be read: {e}")),
            }
        }
        self.recovery.dir = Some(dir);
        self.recovery.writer = Some(crate::scene::recovery::RecoveryWriter::new());
    }

    /// Removes this session's recovery file: its work was saved or deliberately dropped.
    pub(super) fn drop_recovery(&mut self) {
        let (Some(writer), Some(written)) = (&self.recovery.writer, self.recovery.written.take()) else { return };
        if let Err(e) = writer.remove(&written.path) {
            self.error(format!("Could not remove the recovery file: {e}"));
        }
    }

    /// Carries out the recovery writes and removals still queued (at exit).
    pub(super) fn finish_recovery(&mut self) {
        if let Some(writer) = &mut self.recovery.writer {
            writer.finish();
        }
    }

    /// While there are unsaved changes, queues a recovery file of the project: as soon as an
    /// edit ends (a stroke's release, a drag's end, a one-step change), and every
    /// [`recovery_interval_s`] during a long edit. A deferred write asks for a repaint when it
    /// falls due, so an idle editor still writes it.
    pub(super) fn write_recovery(&mut self, ctx: &Context) {
        let Some(writer) = &self.recovery.writer else { return };
        for e in writer.errors() {
            self.error(format!("Could not write the recovery file: {e}"));
        }
        let Some(dir) = self.recovery.dir.clone() else { return };
        if !self.session.is_dirty() {
            return;
        }
        let version = self.content_version();
        let now = ctx.input(|i| i.time);
        if let Some(written) = &self.recovery.written {
            if written.version == version {
                return;
            }
            let editing = self.session.edit_in_progress() || ctx.input(|i| i.pointer.any_down());
            let remaining = recovery_interval_s() - (now - written.at);
            if editing && remaining > 0.0 {
                ctx.request_repaint_after(std::time::Duration::from_secs_f64(remaining));
                return;
            }
        }
        let original = self.session.path().map(Path::to_owned);
        let path = crate::scene::recovery::recovery_path(&dir, original.as_deref());
        // A file written under another name (before a Save As) is replaced by this one.
        if self.recovery.written.as_ref().is_some_and(|w| w.path != path) {
            self.drop_recovery();
        }
        let Some(writer) = &self.recovery.writer else { return };
        match writer.write(&path, original.as_deref(), self.session.project().clone()) {
            Ok(()) => self.recovery.written = Some(RecoveryWritten { path, version, at: now }),
            Err(e) => self.error(format!("Could not write the recovery file: {e}")),
        }
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
                    let particles =
                        rec.project.particle_file.as_ref().map_or(rec.project.particles.len() as u64, |f| f.count);
                    ui.label(format!("{name} ({particles} particles, {} lights)", rec.project.lights.len()));
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
                // Read and checked off the UI thread, with the steps in the status bar; the
                // file goes once its work is in.
                let original = rec.original.clone();
                let shown = original.clone().unwrap_or_else(|| file.clone());
                self.spawn_load("Restoring unsaved work", &shown, move |progress| JobResult::Restored {
                    result: crate::scene::recovery::restore_recovery(&file, rec, progress)
                        .map(Box::new)
                        .map_err(|e| e.to_string()),
                    file,
                    original,
                });
            } else if let Err(e) = crate::scene::recovery::remove_recovery(&file) {
                self.error(e.to_string());
            }
        }
    }
}

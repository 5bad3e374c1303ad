//! The shell around the panels: the status bar, messages and the shortcuts window.

use super::state::EditorState;
use egui::{Context, Id};
use std::sync::atomic::Ordering;

/// How long a load runs before the status bar shows its steps instead of a spinner.
const LOAD_STEPS_AFTER: std::time::Duration = std::time::Duration::from_millis(300);

impl EditorState {
    pub(super) fn status_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            // A load that takes more than a moment shows its steps (reading, parsing, reading
            // particles, validating) as a bar; other jobs show a spinner.
            let load = self.jobs.load.as_ref().filter(|l| l.started.elapsed() >= LOAD_STEPS_AFTER);
            if let Some(load) = load {
                let (step, fraction) =
                    load.steps.lock().ok().and_then(|s| s.last().cloned()).unwrap_or_else(|| ("starting".into(), 0.0));
                ui.add(
                    egui::ProgressBar::new(fraction as f32)
                        .desired_width(200.0)
                        .text(format!("opening {}: {step}", load.name)),
                );
                ui.separator();
            } else if let Some(job) = self.jobs.busy.last() {
                ui.spinner();
                ui.label(job.as_str());
                ui.separator();
            }
            if self.jobs.load.is_some() {
                ui.ctx().request_repaint_after(std::time::Duration::from_millis(100));
            }
            if let Some(job) = &self.jobs.export_job {
                let f = f32::from_bits(job.fraction.load(Ordering::Relaxed));
                let name = job.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                let frame = job.frame.lock().map(|f| f.clone()).unwrap_or_default();
                let name = if frame.is_empty() { name } else { format!("{name}, {frame}") };
                ui.add(
                    egui::ProgressBar::new(f).desired_width(160.0).show_percentage().text(format!("exporting {name}")),
                );
                if job.cancel.load(Ordering::Relaxed) {
                    ui.label("cancelling…");
                } else if ui
                    .button("Cancel")
                    .on_hover_text(if frame.is_empty() {
                        format!("Stop the export; {} stays as it was", job.path.display())
                    } else {
                        "Stop the export after the frames already written; each of them stays complete".to_string()
                    })
                    .clicked()
                {
                    job.cancel.store(true, Ordering::Relaxed);
                }
                ui.separator();
                ui.ctx().request_repaint_after(std::time::Duration::from_millis(100));
            }
            if let Some((_, path)) = &self.jobs.pending_export {
                let path = path.clone();
                ui.label(format!(
                    "{} waits for the bake",
                    path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
                ));
                if ui.button("Cancel").on_hover_text("Do not export").clicked() {
                    self.jobs.pending_export = None;
                    self.info(format!("Export cancelled; {} is unchanged", path.display()));
                }
                ui.separator();
            }
            if let Some(gpu) = self.gpu.as_ref().filter(|g| g.refining()) {
                let p = gpu.progress;
                let stage = p.stage.name();
                ui.add(
                    egui::ProgressBar::new(p.stage_fraction as f32)
                        .desired_width(120.0)
                        .text(format!("preview: {stage}")),
                )
                .on_hover_text("The preview refines over the next frames: optical depths, then full resolution");
                ui.separator();
            }
            let p = self.session.project();
            ui.label(format!(
                "{} particles · {} lights · {} selected · tool: {}",
                p.particles.len(),
                p.lights.len(),
                self.session.selection.len(),
                self.view.tool.label()
            ));
            if self.view.modal.is_some() {
                ui.separator();
                ui.label("Move the mouse; click or Enter to confirm, Esc or right-click to cancel");
            }
        });
    }

    pub(super) fn shortcuts_window(&mut self, ctx: &Context) {
        let mut open = self.view.show_shortcuts;
        // Never taller than the window: the sheet scrolls instead of running off its bottom.
        let height = (ctx.content_rect().height() - 96.0).max(120.0);
        let sheet = egui::Window::new("Shortcuts").open(&mut open).resizable(false).vscroll(true).max_height(height);
        sheet.show(ctx, |ui| {
            egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                for (k, v) in super::commands::help_sheet() {
                    ui.label(k);
                    ui.label(v);
                    ui.end_row();
                }
            });
        });
        self.view.show_shortcuts = open;
    }

    pub(super) fn show_toasts(&mut self, ctx: &Context) {
        let now = ctx.input(|i| i.time);
        self.toasts.retain(|t| t.error || now - t.born < 4.0);
        if self.toasts.iter().any(|t| !t.error) {
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
        }
        let mut dismiss = None;
        let mut dismiss_all = false;
        let hidden = self.toasts.len().saturating_sub(super::state::TOASTS_SHOWN);
        egui::Area::new(Id::new("toasts"))
            .order(egui::Order::Foreground)
            .anchor(egui::Align2::RIGHT_BOTTOM, [-12.0, -36.0])
            .show(ctx, |ui| {
                if hidden > 0 {
                    egui::Frame::popup(ui.style()).show(ui, |ui| {
                        ui.horizontal(|ui| {
                            ui.label(format!("{hidden} earlier message{}", if hidden == 1 { "" } else { "s" }));
                            if ui.small_button("Dismiss all").on_hover_text("Close every message").clicked() {
                                dismiss_all = true;
                            }
                        });
                    });
                }
                for (i, t) in self.toasts.iter().enumerate().skip(hidden) {
                    egui::Frame::popup(ui.style()).show(ui, |ui| {
                        ui.set_max_width(420.0);
                        // The button first and the text wrapped after it, so a long message
                        // grows downwards instead of past the window's edge.
                        ui.horizontal_top(|ui| {
                            if ui.small_button("✕").on_hover_text("Dismiss").clicked() {
                                dismiss = Some(i);
                            }
                            let text = match t.count {
                                1 => egui::RichText::new(&t.text),
                                n => egui::RichText::new(format!("{} (×{n})", t.text)),
                            };
                            let text = if t.error { text.color(ui.visuals().error_fg_color) } else { text };
                            ui.add(egui::Label::new(text).wrap());
                        });
                    });
                }
            });
        if let Some(i) = dismiss {
            self.toasts.remove(i);
        }
        if dismiss_all {
            self.toasts.clear();
        }
    }
}

//! Work in background threads: spawning a job, acting on its result when it comes back,
//! and the exports (read back from the pipeline, written beside the target, moved onto it
//! unless cancelled) and exact optical depths for the slice views.

use super::files::{DialogSpec, FileDialogs};
use super::state::{EditorState, ExactKey, Export, ExportJob, JobResult, Pick};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

/// The result of an export cancelled from the status bar.
const EXPORT_CANCELLED: &str = "cancelled";

impl EditorState {
    /// Runs `job` in a background thread, labelled in the status bar until its result is
    /// handled at the start of a frame.
    pub(super) fn spawn(&mut self, label: &str, job: impl FnOnce() -> JobResult + Send + 'static) {
        self.jobs.busy.push(label.to_owned());
        let tx = self.jobs.tx.clone();
        let ctx = self.ctx.clone();
        std::thread::spawn(move || {
            let _ = tx.send(job());
            ctx.request_repaint();
        });
    }

    pub(crate) fn export_dialog(&mut self, kind: Export) {
        let (filter, ext) = match kind {
            Export::Vdb => ("OpenVDB", "vdb"),
            Export::ExrSlices => ("OpenEXR", "exr"),
        };
        let stem =
            Path::new(self.session.name()).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let name = format!("{}.{ext}", stem.split(' ').next().unwrap_or("fog"));
        let spec = DialogSpec {
            title: "Export",
            filter,
            extension: ext,
            file_name: Some(name),
            directory: self.dialog_directory(),
        };
        self.choose_file(Pick::Export(kind), spec);
    }

    /// Reads the baked volumes back (brief) and writes them in a background thread.
    pub(crate) fn export_to(&mut self, kind: Export, path: PathBuf) {
        let Some(gpu) = &self.gpu else {
            self.error("Nothing to export: the pipeline is not running");
            return;
        };
        if gpu.refining() {
            // The volumes are still being baked: export once they are complete.
            if self.jobs.pending_export.is_none() {
                self.info(format!("Exporting {} once the bake completes…", path.display()));
            }
            self.jobs.pending_export = Some((kind, path));
            self.ctx.request_repaint();
            return;
        }
        let project = self.session.project();
        let volumes = gpu.pipeline.read_ev().and_then(|ev| {
            let opvs = (0..project.lights.len()).map(|i| gpu.pipeline.read_opv(i)).collect::<Result<Vec<_>, _>>()?;
            Ok((ev, opvs))
        });
        let (ev, opvs) = match volumes {
            Ok(v) => v,
            Err(e) => {
                self.error(format!("Export failed: {e}"));
                return;
            }
        };
        let infos = crate::export::light_infos(project);
        let p = path.clone();
        let job = ExportJob {
            path: path.clone(),
            fraction: Arc::new(AtomicU32::new(0)),
            cancel: Arc::new(AtomicBool::new(false)),
        };
        let (fraction, cancel) = (job.fraction.clone(), job.cancel.clone());
        self.jobs.export_job = Some(job);
        self.spawn(&format!("Exporting {}", path.display()), move || {
            // Written beside the target and moved onto it only if not cancelled meanwhile.
            let mut staged = crate::export::Staged::default();
            let set = |f: f32| fraction.store(f.to_bits(), Ordering::Relaxed);
            let result = match kind {
                Export::Vdb => {
                    use crate::export::vdb::{grids_from_volumes, write_vdb_with_progress, GridSelection, VdbOptions};
                    let lights: Vec<_> = opvs.iter().zip(&infos).map(|(v, l)| (v, *l)).collect();
                    let grids = grids_from_volumes(&ev, &lights, GridSelection::default());
                    staged
                        .write(&p, |temp| {
                            write_vdb_with_progress(temp, &grids, &VdbOptions::default(), &mut |f| set(f))
                        })
                        .map(|stats| format!("{} grids, {} bytes", stats.grids.len(), stats.bytes))
                }
                Export::ExrSlices => {
                    let names: Vec<String> = (0..opvs.len()).map(|i| format!("optical_depth_{i}")).collect();
                    let mut channels: Vec<(&str, &crate::scene::Volume)> = vec![("density", &ev)];
                    channels.extend(names.iter().map(String::as_str).zip(opvs.iter()));
                    staged
                        .write(&p, |temp| crate::export::exr::write_slices_exr(temp, &channels))
                        .map(|_| format!("{} volumes", channels.len()))
                }
            };
            let result = match result {
                Ok(_) if cancel.load(Ordering::Relaxed) => Err(EXPORT_CANCELLED.to_string()),
                Ok(summary) => staged.commit().map(|_| summary).map_err(|e| e.to_string()),
                Err(e) => Err(e),
            };
            set(1.0);
            JobResult::Exported { path: p, result }
        });
    }

    pub(super) fn finish_job(&mut self, result: JobResult) {
        self.jobs.busy.pop();
        match result {
            JobResult::Picked { purpose, spec, path: None, seconds } if seconds < super::files::NO_DIALOG_SECONDS => {
                let reason = "the system file dialog did not open (no desktop portal or zenity answered)".to_string();
                self.info(format!("{}; using Fogsmith's file dialog", capitalized(&reason)));
                self.file_dialogs = FileDialogs::BuiltIn { reason };
                self.built_in_explained = true;
                self.open_built_in(purpose, &spec);
            }
            JobResult::Picked { path: None, .. } => self.after_save = None,
            JobResult::Picked { purpose, path: Some(path), .. } => self.picked(purpose, path),
            JobResult::Exported { path, result } if self.jobs.export_job.as_ref().is_some_and(|j| j.path == path) => {
                self.jobs.export_job = None;
                match result {
                    Ok(summary) => self.info(format!("Exported {}: {summary}", path.display())),
                    Err(e) if e == EXPORT_CANCELLED => {
                        self.info(format!("Export cancelled; {} is unchanged", path.display()))
                    }
                    Err(e) => self.error(format!("Export to {} failed: {e}", path.display())),
                }
            }
            JobResult::Exported { path, result: Ok(summary) } => {
                self.info(format!("Exported {}: {summary}", path.display()))
            }
            JobResult::Exported { path, result: Err(e) } => {
                self.error(format!("Export to {} failed: {e}", path.display()))
            }
            JobResult::Loaded { path, result: Ok(project) } => {
                self.replace_project(*project, Some(path.clone()), "");
                self.info(format!("Opened {}", path.display()));
                self.push_recent(path);
            }
            JobResult::Loaded { path, result: Err(e) } => {
                self.recent.retain(|p| p != &path);
                self.error(format!("Could not open the project: {e}"));
            }
            JobResult::Saved { path, generation, result: Ok(()) } => {
                self.drop_recovery();
                self.session.mark_saved(path.clone(), generation);
                self.info(format!("Saved {}", path.display()));
                self.push_recent(path);
                if let Some(action) = self.after_save.take() {
                    self.perform(action);
                }
            }
            JobResult::Saved { result: Err(e), .. } => {
                self.after_save = None;
                self.error(format!("Could not save: {e}"));
            }
            JobResult::Exact { key, result } => {
                if self.view.slice.exact_pending == Some(key) {
                    self.view.slice.exact_pending = None;
                }
                self.view.slice.exact = Some((key, result));
                self.view.slice.key = None;
            }
        }
    }

    /// Starts computing the exact optical depth on a slice's cells, unless it is under way.
    pub(crate) fn request_exact(&mut self, key: ExactKey, cells: Vec<[u32; 3]>) {
        if self.view.slice.exact_pending == Some(key) {
            return;
        }
        self.view.slice.exact_pending = Some(key);
        let project = self.session.project().clone();
        let path = self.session.path().map(Path::to_owned);
        self.spawn("Computing the exact optical depth", move || JobResult::Exact {
            key,
            result: crate::export::load_base_layer(&project, path.as_deref())
                .map_err(|e| format!("The base volume cannot be loaded for the exact reference: {e}"))
                .and_then(|layer| super::slices::exact_optical_depth(&project, layer.as_ref(), key.light, &cells)),
        });
    }
}

fn capitalized(s: &str) -> String {
    let mut c = s.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

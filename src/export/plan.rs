//! What an export writes and the one function that writes it, shared by `fogsmith export` and
//! the editor's Export window so both produce the same files from the same choices.
//!
//! An [`ExportPlan`] names the target files and the [`ExportSettings`] they are written with.
//! [`ExportPlan::problems`] lists what cannot be written before any (long) bake starts;
//! [`write_plan`] then writes every target from read-back data (the EV, the per-light
//! optical depths, the rendered image) into a [`Staged`] set, which the caller commits.

use super::exr::{write_atlas_exr_in_frame, write_baked_atlas_exr, write_render_exr, write_slices_exr, AtlasLayout};
use super::frame::{Frame, Handedness};
use super::ktx::{baked_texture_note, fog_volume_snippet, write_baked_ktx2, write_ktx2, Ktx2Format, Ktx2Info};
use super::nanovdb::write_nanovdb_with_progress;
use super::sequence::FrameTime;
use super::usd::{asset_path, write_usd, UsdField, UsdOptions};
use super::vdb::{
    grids_from_volumes, write_vdb_with_progress, GridSelection, VdbCompression, VdbGrid, VdbOptions, VdbStats,
};
use super::{light_infos, Staged};
use crate::gpu::{BakePhase, Image};
use crate::scene::{Project, Volume, Volume3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How the files are written, whatever their targets.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ExportSettings {
    /// Axes and units of the VDB transform, the USD stage and the EXR atlas metadata.
    pub frame: Frame,
    /// VDB values as half floats.
    pub half: bool,
    /// VDB voxels within this of the background are inactive.
    pub threshold: f32,
    pub grids: GridSelection,
    pub compression: VdbCompression,
    pub ktx2_format: Ktx2Format,
    /// The rendered EXR as half floats.
    pub exr_half: bool,
    /// Bake the lit fog's emission (physics.md §10) into the volume targets, with this phase.
    pub bake_light: Option<BakePhase>,
}

impl Default for ExportSettings {
    fn default() -> Self {
        Self {
            frame: Frame::NATIVE,
            half: false,
            threshold: 0.0,
            grids: GridSelection::default(),
            compression: VdbCompression::Zip,
            ktx2_format: Ktx2Format::R16f,
            exr_half: false,
            bake_light: None,
        }
    }
}

/// The files to write. A USD stage refers to the VDB: `vdb`, else the stage's name with `.vdb`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExportPlan {
    pub vdb: Option<PathBuf>,
    /// The VDB's grids as a NanoVDB file (always 32-bit floats, uncompressed).
    pub nvdb: Option<PathBuf>,
    pub usd: Option<PathBuf>,
    /// The KTX2 texture; its Bevy snippet goes beside it as `NAME.fogvolume.ron`.
    pub ktx2: Option<PathBuf>,
    /// The linear HDR render.
    pub exr_render: Option<PathBuf>,
    /// The render tone-mapped as `fogsmith render` writes a PNG.
    pub png_render: Option<PathBuf>,
    pub exr_slices: Option<PathBuf>,
    pub exr_atlas: Option<PathBuf>,
    /// A Godot 4 scene (`.tscn`) drawing the light bake; its shader, texture and import file
    /// go beside it (see [`super::godot`]). Needs [`ExportSettings::bake_light`].
    pub godot: Option<PathBuf>,
    pub settings: ExportSettings,
}

/// Why a plan cannot be written, found before anything is baked. Callers phrase the fix in
/// their own terms (command-line flags, the Export window's controls).
#[derive(Clone, Debug, PartialEq)]
pub enum ExportProblem {
    /// The stage is not named `.usda` (Fogsmith writes text USD).
    UsdExtension(PathBuf),
    /// USD stages are right-handed; the frame is not.
    UsdLeftHanded(Frame),
    /// The stage's volume needs the density grid, which is not selected.
    UsdNeedsDensity,
    /// The VDB threshold is negative or not finite.
    Threshold(f32),
}

/// Why [`write_plan`] stopped.
#[derive(Debug, thiserror::Error)]
pub enum ExportRunError {
    #[error("cancelled")]
    Cancelled,
    /// A file could not be written; the message names it and the fix.
    #[error("{0}")]
    Failed(String),
}

/// The read-back data a plan is written from.
pub struct ExportInputs<'a> {
    pub project: &'a Project,
    /// The extinction volume and the optical depth per light, indexed like the lights.
    pub volumes: Option<(&'a Volume, &'a [Volume])>,
    /// The rendered image, for the render targets.
    pub image: Option<&'a Image>,
    /// The baked emission, when the settings ask for a light bake.
    pub emission: Option<&'a Volume3>,
    /// The render size the USD camera's aspect ratio follows.
    pub render_size: [u32; 2],
    /// The animation frame the data is of, recorded in the VDB's metadata; None for a still.
    pub time: Option<FrameTime>,
}

/// Where an export stands: the file being written, the fraction of it done, and the fraction
/// of all the plan's files done.
#[derive(Clone, Copy, Debug)]
pub struct ExportProgress {
    pub stage: &'static str,
    pub fraction: f32,
    pub overall: f32,
}

/// What [`write_plan`] wrote, per target.
#[derive(Clone, Debug, Default)]
pub struct Written {
    /// The VDB (the plan's, or the one beside the stage), its stats and milliseconds taken.
    pub vdb: Option<(PathBuf, VdbStats, f64)>,
    /// The VDB's grids as the fields of a USD volume.
    pub vdb_fields: Vec<UsdField>,
    /// The NanoVDB file, its stats and milliseconds taken.
    pub nvdb: Option<(PathBuf, VdbStats, f64)>,
    pub usd: Option<WrittenUsd>,
    /// The texture, what it holds, and its snippet's path.
    pub ktx2: Option<(PathBuf, Ktx2Info, PathBuf)>,
    /// Render targets with the image's size.
    pub exr_render: Option<(PathBuf, [u32; 2])>,
    pub png_render: Option<(PathBuf, [u32; 2])>,
    /// The slices file and the quantities in it.
    pub exr_slices: Option<(PathBuf, usize)>,
    pub exr_atlas: Option<(PathBuf, AtlasLayout)>,
    /// The Godot scene, its texture's layout and the shader's emission gain.
    pub godot: Option<(PathBuf, AtlasLayout, f32)>,
}

/// The stage written, and what it refers to.
#[derive(Clone, Debug)]
pub struct WrittenUsd {
    pub path: PathBuf,
    pub vdb_asset: String,
    pub fields: usize,
    /// Visible lights on the stage.
    pub lights: usize,
}

impl ExportPlan {
    /// No target given.
    pub fn is_empty(&self) -> bool {
        self.vdb.is_none()
            && self.nvdb.is_none()
            && self.usd.is_none()
            && self.ktx2.is_none()
            && self.exr_render.is_none()
            && self.png_render.is_none()
            && self.exr_slices.is_none()
            && self.exr_atlas.is_none()
            && self.godot.is_none()
    }

    /// The VDB written: the plan's, or the stage's name with `.vdb` when only a stage is asked for.
    pub fn vdb_path(&self) -> Option<PathBuf> {
        self.vdb.clone().or_else(|| self.usd.as_ref().map(|u| u.with_extension("vdb")))
    }

    /// The snippet written beside a KTX2 texture.
    pub fn ktx2_snippet(ktx2: &Path) -> PathBuf {
        ktx2.with_extension("fogvolume.ron")
    }

    /// Whether a target needs the rendered image.
    pub fn needs_image(&self) -> bool {
        self.exr_render.is_some() || self.png_render.is_some()
    }

    /// Whether a target needs the baked volumes.
    pub fn needs_volumes(&self) -> bool {
        self.vdb.is_some()
            || self.nvdb.is_some()
            || self.usd.is_some()
            || self.ktx2.is_some()
            || self.exr_slices.is_some()
            || self.exr_atlas.is_some()
            || self.godot.is_some()
    }

    /// The files of a Godot scene: the scene, its shader, its texture and the texture's
    /// import settings.
    pub fn godot_files(tscn: &Path) -> [PathBuf; 4] {
        let atlas = tscn.with_extension("exr");
        let mut import = atlas.clone().into_os_string();
        import.push(".import");
        [tscn.to_path_buf(), tscn.with_extension("gdshader"), atlas, PathBuf::from(import)]
    }

    /// Every file the plan writes, in the order written.
    pub fn files(&self) -> Vec<PathBuf> {
        let mut out: Vec<PathBuf> =
            self.vdb_path().into_iter().chain(self.nvdb.clone()).chain(self.usd.clone()).collect();
        if let Some(k) = &self.ktx2 {
            out.extend([k.clone(), Self::ktx2_snippet(k)]);
        }
        out.extend(
            [&self.exr_render, &self.png_render, &self.exr_slices, &self.exr_atlas].into_iter().flatten().cloned(),
        );
        if let Some(t) = &self.godot {
            out.extend(Self::godot_files(t));
        }
        out
    }

    /// Creates the folders the plan's files go into, as Houdini and Blender do; the error
    /// names the file and the folder that cannot be made.
    pub fn create_folders(&self) -> Result<(), String> {
        for file in self.files() {
            if let Some(dir) = file.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir)
                    .map_err(|e| format!("{}: cannot create its folder {}: {e}", file.display(), dir.display()))?;
            }
        }
        Ok(())
    }

    /// What cannot be written, in the order `fogsmith export` checks it; empty when all can.
    pub fn problems(&self) -> Vec<ExportProblem> {
        let s = &self.settings;
        let mut out = Vec::new();
        if let Some(usd) = &self.usd {
            if usd.extension().and_then(|e| e.to_str()) != Some("usda") {
                out.push(ExportProblem::UsdExtension(usd.clone()));
            }
            if s.frame.handedness == Handedness::Left {
                out.push(ExportProblem::UsdLeftHanded(s.frame));
            }
            if !s.grids.density {
                out.push(ExportProblem::UsdNeedsDensity);
            }
        }
        if !s.threshold.is_finite() || s.threshold < 0.0 {
            out.push(ExportProblem::Threshold(s.threshold));
        }
        out
    }
}

/// Writes every target of `plan` from `inputs` into `staged` (the caller commits it, or drops it
/// to leave every existing file as it was). `progress` hears of each file as it is written;
/// `cancelled` is asked before each file, and a true answer stops with
/// [`ExportRunError::Cancelled`].
pub fn write_plan(
    plan: &ExportPlan,
    inputs: &ExportInputs,
    staged: &mut Staged,
    progress: &mut dyn FnMut(ExportProgress),
    cancelled: &dyn Fn() -> bool,
) -> Result<Written, ExportRunError> {
    let s = &plan.settings;
    let frame = s.frame;
    let project = inputs.project;
    let check = || if cancelled() { Err(ExportRunError::Cancelled) } else { Ok(()) };
    let missing = |what: &str| ExportRunError::Failed(format!("nothing to export: {what} is not available"));
    let volumes = || inputs.volumes.ok_or_else(|| missing("the baked volumes"));
    let vdb_path = plan.vdb_path();
    let mut steps = Steps { progress, done: 0.0, total: plan.files().len().max(1) as f32 };
    let mut written = Written::default();
    plan.create_folders().map_err(ExportRunError::Failed)?;

    let mut fields = Vec::new();
    if vdb_path.is_some() || plan.nvdb.is_some() {
        let (ev, opvs) = volumes()?;
        let infos = light_infos(project);
        let lights: Vec<_> = opvs.iter().zip(&infos).map(|(v, l)| (v, l.in_frame(&frame))).collect();
        let mut grids = grids_from_volumes(ev, &lights, s.grids);
        if s.bake_light.is_some() {
            let emission = inputs.emission.ok_or_else(|| missing("the baked emission"))?;
            grids.push(VdbGrid::from_volume3("emission", emission));
        }
        let opts = VdbOptions {
            compression: s.compression,
            half: s.half,
            threshold: s.threshold,
            frame,
            time: inputs.time,
            medium: Some((project.medium.albedo, project.medium.anisotropy)),
            ..VdbOptions::default()
        };
        if let Some(path) = &vdb_path {
            let t = Instant::now();
            check()?;
            let stats = staged
                .write(path, |p| write_vdb_with_progress(p, &grids, &opts, &mut |f| steps.report("write VDB", f)))
                .map_err(ExportRunError::Failed)?;
            steps.finished(1.0);
            fields = grids
                .iter()
                .map(|g| UsdField { name: g.name.clone(), density: g.name == "density", vector: g.components == 3 })
                .collect();
            written.vdb = Some((path.clone(), stats, t.elapsed().as_secs_f64() * 1e3));
            written.vdb_fields = fields.clone();
        }
        if let Some(path) = &plan.nvdb {
            let t = Instant::now();
            check()?;
            let stats = staged
                .write(path, |p| {
                    write_nanovdb_with_progress(p, &grids, &opts, &mut |f| steps.report("write NanoVDB", f))
                })
                .map_err(ExportRunError::Failed)?;
            steps.finished(1.0);
            written.nvdb = Some((path.clone(), stats, t.elapsed().as_secs_f64() * 1e3));
        }
    }
    if let (Some(path), Some(vdb)) = (&plan.usd, &vdb_path) {
        let opts = UsdOptions {
            vdb_asset: asset_path(path, vdb),
            fields: fields.clone(),
            frame,
            width: inputs.render_size[0],
            height: inputs.render_size[1],
        };
        check()?;
        steps.report("write USD", 0.0);
        staged.write(path, |p| write_usd(p, project, &opts)).map_err(ExportRunError::Failed)?;
        steps.finished(1.0);
        let lights = project.lights.iter().filter(|l| !l.hidden).count();
        written.usd = Some(WrittenUsd { path: path.clone(), vdb_asset: opts.vdb_asset, fields: fields.len(), lights });
    }
    if let (Some(path), Some(_)) = (&plan.ktx2, s.bake_light) {
        let (ev, _) = volumes()?;
        let emission = inputs.emission.ok_or_else(|| missing("the baked emission"))?;
        check()?;
        steps.report("write KTX2", 0.0);
        let info = staged.write(path, |p| write_baked_ktx2(p, ev, emission)).map_err(ExportRunError::Failed)?;
        let snippet_path = ExportPlan::ktx2_snippet(path);
        staged
            .write(&snippet_path, |p| super::write_text(p, &baked_texture_note(&info)))
            .map_err(ExportRunError::Failed)?;
        steps.finished(2.0);
        let info = Ktx2Info { format: s.ktx2_format, scale: info.emission_scale, bytes: info.bytes };
        written.ktx2 = Some((path.clone(), info, snippet_path));
    } else if let Some(path) = &plan.ktx2 {
        let (ev, _) = volumes()?;
        check()?;
        steps.report("write KTX2", 0.0);
        let info = staged.write(path, |p| write_ktx2(p, ev, s.ktx2_format)).map_err(ExportRunError::Failed)?;
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let snippet_path = ExportPlan::ktx2_snippet(path);
        staged
            .write(&snippet_path, |p| super::write_text(p, &fog_volume_snippet(ev, &project.medium, &info, &name)))
            .map_err(ExportRunError::Failed)?;
        steps.finished(2.0);
        written.ktx2 = Some((path.clone(), info, snippet_path));
    }
    for (target, png) in [(&plan.exr_render, false), (&plan.png_render, true)] {
        let Some(path) = target else { continue };
        let image = inputs.image.ok_or_else(|| missing("the rendered image"))?;
        check()?;
        steps.report("write image", 0.0);
        let size = [image.width, image.height];
        if png {
            staged
                .write(path, |p| super::image::write_image(p, image, project.render.exposure))
                .map_err(ExportRunError::Failed)?;
            written.png_render = Some((path.clone(), size));
        } else {
            staged
                .write(path, |p| {
                    write_render_exr(p, image.width as usize, image.height as usize, &image.rgba, s.exr_half)
                })
                .map_err(ExportRunError::Failed)?;
            written.exr_render = Some((path.clone(), size));
        }
        steps.finished(1.0);
    }
    if let Some(path) = &plan.exr_slices {
        let (ev, opvs) = volumes()?;
        let names: Vec<String> = (0..opvs.len()).map(|l| format!("optical_depth_{l}")).collect();
        let mut layers: Vec<(&str, &Volume)> = vec![("density", ev)];
        layers.extend(names.iter().map(String::as_str).zip(opvs.iter()));
        check()?;
        steps.report("write EXR slices", 0.0);
        staged.write(path, |p| write_slices_exr(p, &layers)).map_err(ExportRunError::Failed)?;
        steps.finished(1.0);
        written.exr_slices = Some((path.clone(), layers.len()));
    }
    if let (Some(path), Some(_)) = (&plan.exr_atlas, s.bake_light) {
        let (ev, _) = volumes()?;
        let emission = inputs.emission.ok_or_else(|| missing("the baked emission"))?;
        check()?;
        steps.report("write EXR atlas", 0.0);
        let (layout, _) =
            staged.write(path, |p| write_baked_atlas_exr(p, ev, emission, &frame)).map_err(ExportRunError::Failed)?;
        steps.finished(1.0);
        written.exr_atlas = Some((path.clone(), layout));
    } else if let Some(path) = &plan.exr_atlas {
        let (ev, _) = volumes()?;
        check()?;
        steps.report("write EXR atlas", 0.0);
        let layout = staged.write(path, |p| write_atlas_exr_in_frame(p, ev, &frame)).map_err(ExportRunError::Failed)?;
        steps.finished(1.0);
        written.exr_atlas = Some((path.clone(), layout));
    }
    if let Some(tscn) = &plan.godot {
        let (ev, _) = volumes()?;
        let emission = inputs.emission.ok_or_else(|| {
            ExportRunError::Failed(format!("{}: a Godot scene draws the light bake: turn the bake on", tscn.display()))
        })?;
        check()?;
        steps.report("write Godot scene", 0.0);
        let [tscn, shader_path, atlas, import] = ExportPlan::godot_files(tscn);
        let name = |p: &Path| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let (layout, scales) =
            staged.write(&atlas, |p| write_baked_atlas_exr(p, ev, emission, &frame)).map_err(ExportRunError::Failed)?;
        let gain = super::godot::emission_gain(emission.max_value());
        let texts = [
            (&import, super::godot::import_file(&layout, &name(&atlas))),
            (&shader_path, super::godot::shader(&layout, scales, gain)),
            (&tscn, super::godot::scene(&ev.grid, &name(&shader_path), &name(&atlas))),
        ];
        for (path, text) in texts {
            staged.write(path, |p| super::write_text(p, &text)).map_err(ExportRunError::Failed)?;
        }
        steps.finished(4.0);
        written.godot = Some((tscn, layout, gain));
    }
    check()?;
    Ok(written)
}

/// Files written so far out of all, for [`ExportProgress::overall`].
struct Steps<'p> {
    progress: &'p mut dyn FnMut(ExportProgress),
    done: f32,
    total: f32,
}

impl Steps<'_> {
    fn report(&mut self, stage: &'static str, fraction: f32) {
        let overall = ((self.done + fraction) / self.total).min(1.0);
        (self.progress)(ExportProgress { stage, fraction, overall });
    }

    fn finished(&mut self, files: f32) {
        self.done += files;
    }
}

//! The export choices: the format, its options, the frames and the destination that File →
//! Export… picks, what plan they make for [`crate::export::write_plan`] and what stops them
//! being written. Plain data, read by the window (`export`), the jobs and the remembered
//! choices (`export_memory`).

use crate::export::frame::Preset;
use crate::export::plan::{ExportPlan, ExportProblem, ExportSettings};
use crate::export::sequence::{suggest_pattern, FramePattern};
use crate::scene::Project;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the Export window writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ExportFormat {
    /// Density and per-light grids as OpenVDB.
    #[default]
    Vdb,
    /// The same grids as NanoVDB.
    Nvdb,
    /// A `.usda` stage referring to a VDB beside it.
    Usd,
    /// The extinction as a KTX2 3D texture plus a Bevy `FogVolume` snippet.
    Ktx2,
    /// The extinction as a 2D atlas of z-slices.
    ExrAtlas,
    /// Every z slice of density and optical depth per light in one multi-layer EXR.
    ExrSlices,
    /// The render at the project's output size.
    Image,
}

/// The rendered image's file format.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ImageFormat {
    /// Tone-mapped, as `fogsmith render` writes it.
    #[default]
    Png,
    /// Linear HDR RGBA.
    Exr,
}

impl ExportFormat {
    pub const ALL: [ExportFormat; 7] = [
        ExportFormat::Vdb,
        ExportFormat::Nvdb,
        ExportFormat::Usd,
        ExportFormat::Ktx2,
        ExportFormat::ExrAtlas,
        ExportFormat::ExrSlices,
        ExportFormat::Image,
    ];

    pub fn label(self) -> &'static str {
        match self {
            ExportFormat::Vdb => "OpenVDB (.vdb)",
            ExportFormat::Nvdb => "NanoVDB (.nvdb)",
            ExportFormat::Usd => "USD stage (.usda + .vdb)",
            ExportFormat::Ktx2 => "KTX2 texture (.ktx2 + .fogvolume.ron)",
            ExportFormat::ExrAtlas => "EXR atlas (.exr)",
            ExportFormat::ExrSlices => "EXR slices (.exr)",
            ExportFormat::Image => "Rendered image (.png / .exr)",
        }
    }

    pub fn description(self) -> &'static str {
        match self {
            ExportFormat::Vdb => "The extinction as a fog-volume grid and each light's optical depth, for Houdini, Blender and engines",
            ExportFormat::Nvdb => "The same grids as NanoVDB (32-bit floats, uncompressed), for renderers and engines that load NanoVDB",
            ExportFormat::Usd => "The scene as an OpenUSD stage (fog volume, lights, camera, surfaces); its volume's fields are the grids of a VDB written beside it",
            ExportFormat::Ktx2 => "The extinction as a 3D texture for game engines, and a matching Bevy FogVolume (always Y-up, metres)",
            ExportFormat::ExrAtlas => "The extinction's z-slices tiled in one 2D image; the tile layout is in the header",
            ExportFormat::ExrSlices => "Every z-slice of the extinction and of each light's optical depth, one layer each",
            ExportFormat::Image => "The preview rendered to convergence at the project's output size (the Inspector's Render section), as `fogsmith render` does",
        }
    }

    /// The axes and units apply (the VDB transform, the USD stage, the atlas header).
    pub fn uses_frame(self) -> bool {
        matches!(self, ExportFormat::Vdb | ExportFormat::Nvdb | ExportFormat::Usd | ExportFormat::ExrAtlas)
    }

    /// Whether the format can hold the light bake (volume files).
    pub fn can_bake_light(self) -> bool {
        matches!(
            self,
            ExportFormat::Vdb | ExportFormat::Nvdb | ExportFormat::Usd | ExportFormat::Ktx2 | ExportFormat::ExrAtlas
        )
    }

    /// A VDB is written, with its grid options.
    pub fn writes_vdb(self) -> bool {
        matches!(self, ExportFormat::Vdb | ExportFormat::Usd)
    }

    /// The VDB's grids are written (as OpenVDB or NanoVDB), with their selection and threshold.
    pub fn writes_grids(self) -> bool {
        self.writes_vdb() || self == ExportFormat::Nvdb
    }
}

/// Which frames of an animated project an export writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameRange {
    /// The frame on show, as it shows (with its unkeyed edits).
    #[default]
    ThisFrame,
    /// Every frame from `first` to `last`, each its `Project::at_frame`.
    Frames { first: i32, last: i32 },
}

/// Everything the Export window asks, remembered per project.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ExportChoices {
    pub format: ExportFormat,
    /// The preset the frame was set from; None when no preset gives it.
    pub preset: Option<Preset>,
    pub settings: ExportSettings,
    pub image: ImageFormat,
    pub frames: FrameRange,
}

impl ExportChoices {
    /// The destination's extension and the file dialog's filter name.
    pub fn extension(&self) -> (&'static str, &'static str) {
        match self.format {
            ExportFormat::Vdb => ("vdb", "OpenVDB"),
            ExportFormat::Nvdb => ("nvdb", "NanoVDB"),
            ExportFormat::Usd => ("usda", "USD stage"),
            ExportFormat::Ktx2 => ("ktx2", "KTX2 texture"),
            ExportFormat::ExrAtlas | ExportFormat::ExrSlices => ("exr", "OpenEXR"),
            ExportFormat::Image => match self.image {
                ImageFormat::Png => ("png", "PNG image"),
                ImageFormat::Exr => ("exr", "OpenEXR"),
            },
        }
    }

    /// The frames to export from `project`, within its animation range; None for the frame
    /// on show (a still, or "This frame").
    pub fn sequence(&self, project: &Project) -> Option<(i32, i32)> {
        let a = project.animation?;
        match self.frames {
            FrameRange::ThisFrame => None,
            FrameRange::Frames { first, last } => {
                let first = first.clamp(a.start, a.end);
                Some((first, last.clamp(first, a.end)))
            }
        }
    }

    /// What to write to `path`.
    pub fn plan(&self, path: &Path) -> ExportPlan {
        let mut plan = ExportPlan { settings: self.settings, ..ExportPlan::default() };
        let target = Some(path.to_path_buf());
        match self.format {
            ExportFormat::Vdb => plan.vdb = target,
            ExportFormat::Nvdb => plan.nvdb = target,
            ExportFormat::Usd => plan.usd = target,
            ExportFormat::Ktx2 => plan.ktx2 = target,
            ExportFormat::ExrAtlas => plan.exr_atlas = target,
            ExportFormat::ExrSlices => plan.exr_slices = target,
            ExportFormat::Image => match self.image {
                ImageFormat::Png => plan.png_render = target,
                ImageFormat::Exr => plan.exr_render = target,
            },
        }
        if !self.format.can_bake_light() {
            plan.settings.bake_light = None;
        }
        plan
    }

    /// Why `project` cannot be exported to `path` with these choices, each with what to change;
    /// empty when it can.
    pub fn problems(&self, project: &Project, path: &Path) -> Vec<String> {
        let mut out: Vec<String> = self.plan(path).problems().iter().map(problem_text).collect();
        if let Some((first, last)) = self.sequence(project) {
            let named = FramePattern::new(path).has_frame();
            let file = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if self.format == ExportFormat::Usd && named {
                out.push(format!(
                    "{file}: one stage holds every frame (it points at each frame's VDB, written as NAME.####.vdb \
                     beside it); name the stage without a frame number."
                ));
            } else if self.format != ExportFormat::Usd && !named && last > first {
                out.push(format!(
                    "{file} has no frame number, so every frame would overwrite one file: put one in the name, \
                     e.g. {} (or %04d, or $F4).",
                    suggest_pattern(Path::new(&file)).display()
                ));
            }
        }
        let g = self.settings.grids;
        if self.format.writes_grids() {
            if !(g.density || g.optical_depth || g.transmittance) {
                out.push("No grid is ticked: tick at least one under Grids.".into());
            } else if !g.density && project.lights.is_empty() {
                out.push("The project has no lights, so it has no optical depth or transmittance grids: tick “density grid”.".into());
            }
        }
        if self.plan(path).settings.bake_light.is_some() && !project.lights.iter().any(|l| !l.hidden) {
            out.push(
                "Nothing to bake: the project has no visible light. Add a light or untick “Bake lighting for engines”."
                    .into(),
            );
        }
        out
    }

    /// `path` with the format's extension added when it has none; an error when it has another.
    pub fn destination(&self, path: PathBuf) -> Result<PathBuf, String> {
        let (ext, name) = self.extension();
        match path.extension().and_then(|e| e.to_str()) {
            None => Ok(path.with_extension(ext)),
            Some(e) if e.eq_ignore_ascii_case(ext) => Ok(path),
            Some(_) => Err(format!(
                "{}: a {name} file ends in .{ext}; name it with that extension, or choose another format in the Export window",
                path.display()
            )),
        }
    }
}

/// A problem found before the export, in the Export window's terms.
fn problem_text(problem: &ExportProblem) -> String {
    match problem {
        ExportProblem::UsdExtension(path) => {
            format!("{}: Fogsmith writes text USD; name the file with the .usda extension.", path.display())
        }
        ExportProblem::UsdLeftHanded(frame) => format!(
            "USD stages are right-handed, and the frame is {frame}: choose right-handed (for Unreal: Z-up, \
             centimetres, right-handed; its USD importer converts to its own axes)."
        ),
        ExportProblem::UsdNeedsDensity => {
            "The USD stage's volume is the density grid: tick “density grid” under Grids.".into()
        }
        ExportProblem::Threshold(t) => format!("The threshold must be a finite number ≥ 0, got {t}."),
    }
}

/// The plan of each frame of a sequence exported with `plan`: every path with the frame's
/// number in place of its pattern; a stage's VDBs go to `NAME.####.vdb` beside it, and the
/// stage itself is written once at the end.
pub(crate) fn sequence_plans(plan: &ExportPlan, frames: &[i32]) -> Vec<ExportPlan> {
    let vdb = plan.vdb.clone().or_else(|| plan.usd.as_ref().map(|u| suggest_pattern(&u.with_extension("vdb"))));
    let at = |path: &Option<PathBuf>, frame: i32| path.as_ref().map(|p| FramePattern::new(p).path(frame));
    frames
        .iter()
        .map(|&f| ExportPlan {
            vdb: at(&vdb, f),
            nvdb: at(&plan.nvdb, f),
            usd: None,
            ktx2: at(&plan.ktx2, f),
            exr_render: at(&plan.exr_render, f),
            png_render: at(&plan.png_render, f),
            exr_slices: at(&plan.exr_slices, f),
            exr_atlas: at(&plan.exr_atlas, f),
            godot: at(&plan.godot, f),
            settings: plan.settings,
        })
        .collect()
}

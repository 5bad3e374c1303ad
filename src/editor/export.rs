//! File → Export…: one window to pick a format and its options, then a destination. The
//! window shows only the options of the chosen format and says what to change when a
//! combination cannot be written, before anything is written; the export itself runs as a
//! background job (`jobs`) through [`crate::export::write_plan`], as `fogsmith export` does.
//! An animated project exports the frame on show or a range of frames, each frame's file
//! named by a frame pattern (`fog.####.vdb`) as `fogsmith export --frames` names them.

use super::export_memory::ExportMemory;
use super::files::DialogSpec;
use super::state::{EditorState, Pick};
use crate::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use crate::export::ktx::Ktx2Format;
use crate::export::plan::{ExportPlan, ExportProblem, ExportSettings};
use crate::export::sequence::{suggest_pattern, FramePattern};
use crate::export::vdb::VdbCompression;
use crate::gpu::BakePhase;
use crate::scene::Project;
use egui::Context;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the Export window writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ExportFormat {
    /// Density and per-light grids as OpenVDB.
    #[default]
    Vdb,
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
    pub const ALL: [ExportFormat; 6] = [
        ExportFormat::Vdb,
        ExportFormat::Usd,
        ExportFormat::Ktx2,
        ExportFormat::ExrAtlas,
        ExportFormat::ExrSlices,
        ExportFormat::Image,
    ];

    pub fn label(self) -> &'static str {
        match self {
            ExportFormat::Vdb => "OpenVDB (.vdb)",
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
            ExportFormat::Usd => "The scene as an OpenUSD stage (fog volume, lights, camera, surfaces); its volume's fields are the grids of a VDB written beside it",
            ExportFormat::Ktx2 => "The extinction as a 3D texture for game engines, and a matching Bevy FogVolume (always Y-up, metres)",
            ExportFormat::ExrAtlas => "The extinction's z-slices tiled in one 2D image; the tile layout is in the header",
            ExportFormat::ExrSlices => "Every z-slice of the extinction and of each light's optical depth, one layer each",
            ExportFormat::Image => "The preview rendered to convergence at the project's output size (the Inspector's Render section), as `fogsmith render` does",
        }
    }

    /// The axes and units apply (the VDB transform, the USD stage, the atlas header).
    pub fn uses_frame(self) -> bool {
        matches!(self, ExportFormat::Vdb | ExportFormat::Usd | ExportFormat::ExrAtlas)
    }

    /// A VDB is written, with its grid options.
    /// Whether the format can hold the light bake (volume files).
    pub fn can_bake_light(self) -> bool {
        matches!(self, ExportFormat::Vdb | ExportFormat::Usd | ExportFormat::Ktx2 | ExportFormat::ExrAtlas)
    }

    pub fn writes_vdb(self) -> bool {
        matches!(self, ExportFormat::Vdb | ExportFormat::Usd)
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
        if self.format.writes_vdb() {
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

/// The Export window while open, and the remembered choices.
pub(crate) struct ExportUi {
    pub window: Option<ExportChoices>,
    pub memory: ExportMemory,
}

impl ExportUi {
    pub fn new(state_dir: PathBuf) -> Self {
        Self { window: None, memory: ExportMemory::new(state_dir) }
    }
}

impl EditorState {
    /// File → Export…: opens the window on the choices last used for this project.
    pub(crate) fn open_export_window(&mut self) {
        if self.export.window.is_some() {
            return;
        }
        let path = self.session.path().map(Path::to_owned);
        let (choices, note) = self.export.memory.recall(path.as_deref());
        if let Some(note) = note {
            self.info(note);
        }
        self.export.window = Some(choices);
    }

    /// The file name the destination dialog proposes: the project's stem and the format's
    /// extension, with a frame pattern between them for a range of frames.
    fn export_file_name(&self, choices: &ExportChoices) -> String {
        let stem =
            Path::new(self.session.name()).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let stem = stem.split(' ').next().filter(|s| !s.is_empty()).unwrap_or("fog");
        let sequence = choices.sequence(self.session.project()).is_some();
        match choices.extension().0 {
            ext if sequence && choices.format != ExportFormat::Usd => format!("{stem}.####.{ext}"),
            ext => format!("{stem}.{ext}"),
        }
    }

    /// Remembers `choices` for this project and asks where to write.
    fn choose_export_destination(&mut self, choices: ExportChoices) {
        let path = self.session.path().map(Path::to_owned);
        if let Err(e) = self.export.memory.remember(path.as_deref(), choices) {
            self.error(e);
        }
        let (extension, filter) = choices.extension();
        let spec = DialogSpec {
            title: "Export",
            filter,
            extension,
            file_name: Some(self.export_file_name(&choices)),
            directory: self.dialog_directory(),
        };
        self.choose_file(Pick::Export(choices), spec);
    }

    pub(super) fn export_window(&mut self, ctx: &Context) {
        let Some(mut choices) = self.export.window else { return };
        let project = self.session.project();
        let name = self.export_file_name(&choices);
        let problems = choices.problems(project, Path::new(&name));
        let files = match choices.sequence(project) {
            Some(_) if choices.format == ExportFormat::Usd => {
                vec![PathBuf::from(&name), suggest_pattern(&Path::new(&name).with_extension("vdb"))]
            }
            _ => choices.plan(Path::new(&name)).files(),
        };
        let size = [project.render.width, project.render.height];
        let lights = project.lights.len();
        let animation = project.animation;
        let this_frame = self.session.frame();
        let mut open = true;
        let mut go = false;
        let mut cancel = false;
        egui::Window::new("Export").open(&mut open).collapsible(false).resizable(false).show(ctx, |ui| {
            ui.set_max_width(460.0);
            ui.strong("Format");
            for f in ExportFormat::ALL {
                ui.radio_value(&mut choices.format, f, f.label()).on_hover_text(f.description());
            }
            ui.add(egui::Label::new(egui::RichText::new(choices.format.description()).weak()).wrap());
            ui.separator();
            if let Some(a) = animation {
                frame_range(ui, &mut choices.frames, a, this_frame);
                ui.separator();
            }
            options(ui, &mut choices, size, lights);
            ui.separator();
            let names: Vec<String> =
                files.iter().filter_map(|f| f.file_name()).map(|n| n.to_string_lossy().into_owned()).collect();
            ui.label(format!("Writes {}; the folder and name are chosen next", names.join(" and ")));
            for p in &problems {
                ui.add(egui::Label::new(egui::RichText::new(p).color(ui.visuals().error_fg_color)).wrap());
            }
            ui.horizontal(|ui| {
                let button = ui
                    .add_enabled(problems.is_empty(), egui::Button::new("Export to…"))
                    .on_hover_text("Choose where to write, then export in the background")
                    .on_disabled_hover_text("Change what the message above says first");
                go = button.clicked();
                cancel = ui.button("Cancel").clicked();
            });
        });
        if !open || cancel {
            self.export.window = None;
        } else if go {
            self.export.window = None;
            self.choose_export_destination(choices);
        } else {
            self.export.window = Some(choices);
        }
    }
}

/// "This frame" or "Frames A–B" (within the animation range).
fn frame_range(ui: &mut egui::Ui, range: &mut FrameRange, a: crate::scene::animation::Animation, this_frame: i32) {
    ui.horizontal(|ui| {
        ui.strong("Which frames");
        ui.radio_value(range, FrameRange::ThisFrame, format!("This frame ({this_frame})"))
            .on_hover_text("The frame on show, with any unkeyed edits");
        let (mut first, mut last) = match *range {
            FrameRange::Frames { first, last } => (first, last),
            FrameRange::ThisFrame => (a.start, a.end),
        };
        let sequence = matches!(range, FrameRange::Frames { .. });
        if ui
            .radio(sequence, "Frames")
            .on_hover_text("Each frame baked in the background, one file per frame named by the frame pattern")
            .clicked()
        {
            *range = FrameRange::Frames { first, last };
        }
        let a_ = ui.add_enabled(sequence, egui::DragValue::new(&mut first).range(a.start..=a.end).speed(0.2));
        ui.label("–");
        let b_ = ui.add_enabled(sequence, egui::DragValue::new(&mut last).range(a.start..=a.end).speed(0.2));
        if sequence && (a_.changed() || b_.changed()) {
            *range = FrameRange::Frames { first: first.min(last), last: last.max(first) };
        }
    });
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

/// The options of the chosen format, and only those.
fn options(ui: &mut egui::Ui, c: &mut ExportChoices, size: [u32; 2], lights: usize) {
    let s = &mut c.settings;
    egui::Grid::new("export-options").num_columns(2).spacing([12.0, 6.0]).show(ui, |ui| {
        if c.format.uses_frame() {
            ui.label("preset");
            ui.horizontal(|ui| {
                for (p, name) in [
                    (Preset::Blender, "Blender"),
                    (Preset::Houdini, "Houdini"),
                    (Preset::Unreal, "Unreal"),
                    (Preset::Godot, "Godot"),
                    (Preset::Unity, "Unity"),
                ] {
                    let f = Frame::preset(p);
                    if ui.selectable_label(c.preset == Some(p), name).on_hover_text(f.to_string()).clicked() {
                        c.preset = Some(p);
                        s.frame = f;
                    }
                }
            });
            ui.end_row();
            let before = s.frame;
            ui.label("up axis");
            ui.horizontal(|ui| {
                ui.radio_value(&mut s.frame.up, UpAxis::Y, "Y-up");
                ui.radio_value(&mut s.frame.up, UpAxis::Z, "Z-up");
            });
            ui.end_row();
            ui.label("units");
            ui.horizontal(|ui| {
                ui.radio_value(&mut s.frame.units, Units::M, "metres");
                ui.radio_value(&mut s.frame.units, Units::Cm, "centimetres");
            });
            ui.end_row();
            ui.label("handedness");
            ui.horizontal(|ui| {
                ui.radio_value(&mut s.frame.handedness, Handedness::Right, "right-handed");
                ui.radio_value(&mut s.frame.handedness, Handedness::Left, "left-handed");
            });
            ui.end_row();
            if s.frame != before && c.preset.is_some_and(|p| Frame::preset(p) != s.frame) {
                c.preset = None;
            }
        }
        if c.format.writes_vdb() {
            ui.label("grids");
            ui.horizontal(|ui| {
                ui.checkbox(&mut s.grids.density, "density grid")
                    .on_hover_text("The extinction, 1/m (class fog volume)");
                ui.checkbox(&mut s.grids.optical_depth, "optical depth per light")
                    .on_hover_text(format!("optical_depth_<i> for each of the {lights} lights"));
                ui.checkbox(&mut s.grids.transmittance, "transmittance per light")
                    .on_hover_text("transmittance_<i> = exp(−optical depth), background 1");
            });
            ui.end_row();
            ui.label("values");
            ui.horizontal(|ui| {
                ui.checkbox(&mut s.half, "half floats").on_hover_text("16-bit values (as OpenVDB's saveFloatAsHalf)");
                ui.label("threshold");
                ui.add(egui::DragValue::new(&mut s.threshold).speed(0.001).range(0.0..=f32::MAX))
                    .on_hover_text("Voxels within this of the background are inactive and read back as the background");
            });
            ui.end_row();
            ui.label("compression");
            ui.horizontal(|ui| {
                ui.radio_value(&mut s.compression, VdbCompression::Zip, "zip");
                ui.radio_value(&mut s.compression, VdbCompression::None, "none");
            });
            ui.end_row();
        }
        if c.format.can_bake_light() {
            ui.label("lighting");
            ui.horizontal(|ui| {
                let mut on = s.bake_light.is_some();
                ui.checkbox(&mut on, "Bake lighting for engines").on_hover_text(
                    "Each cell's emitted radiance (the light it scatters, shadowed by the fog): engines draw it \
                     as emission and absorption with no lights (an emission grid in the VDB, RGBA in textures)",
                );
                if on != s.bake_light.is_some() {
                    s.bake_light = on.then_some(BakePhase::Isotropic);
                }
                if let Some(phase) = &mut s.bake_light {
                    ui.radio_value(phase, BakePhase::Isotropic, "isotropic")
                        .on_hover_text("Phase 1/(4π): right from any view when g = 0");
                    ui.radio_value(phase, BakePhase::Camera, "towards the camera")
                        .on_hover_text("Henyey–Greenstein towards the project's camera: right for that view, any g");
                }
            });
            ui.end_row();
        }
        match c.format {
            ExportFormat::Ktx2 => {
                ui.label("texels");
                ui.horizontal(|ui| {
                    ui.radio_value(&mut s.ktx2_format, Ktx2Format::R16f, "r16f")
                        .on_hover_text("16-bit float: the extinction in 1/m");
                    ui.radio_value(&mut s.ktx2_format, Ktx2Format::R8, "r8")
                        .on_hover_text("8-bit, times the scale recorded in the file and the snippet");
                });
                ui.end_row();
            }
            ExportFormat::Image => {
                ui.label("file");
                ui.horizontal(|ui| {
                    ui.radio_value(&mut c.image, ImageFormat::Png, "PNG")
                        .on_hover_text("Tone-mapped with the exposure");
                    ui.radio_value(&mut c.image, ImageFormat::Exr, "EXR").on_hover_text("Linear HDR RGBA");
                    if c.image == ImageFormat::Exr {
                        ui.checkbox(&mut s.exr_half, "half floats");
                    }
                });
                ui.end_row();
                ui.label("size");
                ui.label(format!(
                    "{}×{} px (the project's output size, set in the Inspector's Render section)",
                    size[0], size[1]
                ));
                ui.end_row();
            }
            _ => {}
        }
    });
}

//! File → Export…: one window to pick a format and its options, then a destination. The
//! window shows only the options of the chosen format and says what to change when a
//! combination cannot be written, before anything is written; the export itself runs as a
//! background job (`jobs`) through [`crate::export::write_plan`], as `fogsmith export` does.
//! An animated project exports the frame on show or a range of frames, each frame's file
//! named by a frame pattern (`fog.####.vdb`) as `fogsmith export --frames` names them.

use super::export_choices::{ExportChoices, ExportFormat, FrameRange, ImageFormat};
use super::files::DialogSpec;
use super::state::{EditorState, Pick};
use crate::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use crate::export::ktx::Ktx2Format;
use crate::export::sequence::suggest_pattern;
use crate::export::vdb::VdbCompression;
use crate::gpu::BakePhase;
use egui::Context;
use std::path::{Path, PathBuf};

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
            directory: self.dialog_directory(super::files::DialogKind::Export),
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
        if c.format.writes_grids() {
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
                if c.format.writes_vdb() {
                    ui.checkbox(&mut s.half, "half floats")
                        .on_hover_text("16-bit values (as OpenVDB's saveFloatAsHalf)");
                }
                ui.label("threshold");
                ui.add(egui::DragValue::new(&mut s.threshold).speed(0.001).range(0.0..=f32::MAX))
                    .on_hover_text("Voxels within this of the background are inactive and read back as the background");
            });
            ui.end_row();
            if c.format.writes_vdb() {
                ui.label("compression");
                ui.horizontal(|ui| {
                    ui.radio_value(&mut s.compression, VdbCompression::Zip, "zip");
                    ui.radio_value(&mut s.compression, VdbCompression::None, "none");
                });
                ui.end_row();
            }
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

//! `fogsmith export`: bake a project on the GPU and write VDB / EXR / USD / KTX2 files, for
//! one frame or for each frame of `--frames` (one pipeline bakes them in order, each frame's
//! files are in place before the next frame starts, and one USD stage refers to them all).
//! With `--resume` it skips the frames whose files are complete (see [`crate::farm::check`]),
//! which is what makes a render-farm task safe to run again.

use super::progress::{check, interrupted, Bar, Cancelled};
use super::{frames, open, still, BakeArgs};
use crate::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use crate::export::ktx::Ktx2Format;
use crate::export::plan::{
    write_plan, ExportInputs, ExportPlan, ExportProblem, ExportRunError, ExportSettings, Written,
};
use crate::export::sequence::{suggest_pattern, FramePattern, FrameSet, FrameTime, SequenceError};
use crate::export::usd::{asset_path, write_usd_sequence, StageFrame, UsdField, UsdOptions};
use crate::export::vdb::{GridSelection, VdbCompression};
use crate::export::Staged;
use crate::farm::check::{file_state, remove_leftovers, write_sidecar, FileState};
use crate::gpu::BakePhase;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub bake: BakeArgs,
    /// OpenVDB file with the density grid and per-light optical depth grids.
    #[arg(long)]
    pub vdb: Option<PathBuf>,
    /// NanoVDB file (.nvdb, version 32.4, uncompressed 32-bit floats) with the same grids as
    /// --vdb (--grids, --threshold and --bake-light apply; --half and --compression do not).
    #[arg(long)]
    pub nvdb: Option<PathBuf>,
    /// Store VDB values as half floats (as OpenVDB's saveFloatAsHalf).
    #[arg(long)]
    pub half: bool,
    /// VDB voxels whose value differs from the background by at most this are inactive.
    #[arg(long, default_value_t = 0.0)]
    pub threshold: f32,
    /// VDB grids to write: density, optical_depth, transmittance (comma-separated).
    #[arg(long, default_value = "density,optical_depth")]
    pub grids: GridSelection,
    /// VDB compression.
    #[arg(long, value_enum, default_value_t = Compression::Zip)]
    pub compression: Compression,
    /// The linear HDR render as an RGBA EXR.
    #[arg(long)]
    pub exr_render: Option<PathBuf>,
    /// The EV and per-light optical depths as one multi-layer EXR (`<quantity>.z<k>.Y`).
    #[arg(long)]
    pub exr_slices: Option<PathBuf>,
    /// The EV as a 2D atlas of z-slices (tile layout in the header and printed).
    #[arg(long)]
    pub exr_atlas: Option<PathBuf>,
    /// Write EXR renders as half floats.
    #[arg(long)]
    pub exr_half: bool,
    /// Axes and units of the tool the files are for: blender (Z-up, m), houdini (Y-up, m),
    /// unreal (Z-up, cm, left-handed), godot (Y-up, m), unity (Y-up, m, left-handed).
    /// Applies to the VDB transform, the USD stage and the EXR atlas metadata.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Up axis of the exported world (default: the preset's, else y).
    #[arg(long, value_enum)]
    pub up: Option<UpAxis>,
    /// Length unit of the exported world (default: the preset's, else m).
    #[arg(long, value_enum)]
    pub units: Option<Units>,
    /// Handedness of the exported world (default: the preset's, else right).
    #[arg(long, value_enum)]
    pub handedness: Option<Handedness>,
    /// The whole scene as an OpenUSD stage (.usda): the fog as a Volume whose fields are the
    /// VDB's grids (the --vdb file, else NAME.vdb beside the stage), lights, camera, surfaces.
    #[arg(long)]
    pub usd: Option<PathBuf>,
    /// The extinction as a KTX2 3D texture for game engines, plus NAME.fogvolume.ron with a
    /// matching Bevy FogVolume (always Y-up, metres: the presets do not apply).
    #[arg(long)]
    pub ktx2: Option<PathBuf>,
    /// KTX2 texel format: r16f (the extinction in 1/m) or r8 (times the scale it records).
    #[arg(long, value_enum, default_value_t = Ktx2Format::R16f)]
    pub ktx2_format: Ktx2Format,
    /// Bake the lit fog for engines without volumetric self-shadowing: the radiance each
    /// cell scatters (W·m⁻³·sr⁻¹ per channel) as a vec3s `emission` grid beside `density` in
    /// the VDB, and a field of the USD volume. Render it as emission and absorption, no lights.
    #[arg(long)]
    pub bake_light: bool,
    /// The bake's phase function: isotropic (1/(4π), right from any view when g = 0) or
    /// camera (Henyey–Greenstein towards the project's camera, right for that view, any g).
    #[arg(long, value_enum, default_value_t = BakePhaseArg::Isotropic, requires = "bake_light")]
    pub bake_phase: BakePhaseArg,
    /// A Godot 4 scene (.tscn) with a FogVolume drawing the light bake (needs --bake-light),
    /// plus its fog shader (NAME.gdshader) and texture (NAME.exr, with NAME.exr.import).
    #[arg(long)]
    pub godot: Option<PathBuf>,
    /// Skip each frame whose files are all complete (their checksum sidecars match, or they
    /// read back), and write a NAME.crc32 sidecar beside every file written: rerunning an
    /// interrupted command bakes only what is missing or damaged.
    #[arg(long)]
    pub resume: bool,
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum BakePhaseArg {
    Isotropic,
    Camera,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum Compression {
    None,
    Zip,
}

impl ExportArgs {
    /// The export frame: the preset's (or Fogsmith's own), then each explicit option.
    pub fn frame(&self) -> Frame {
        let mut f = self.preset.map(Frame::preset).unwrap_or(Frame::NATIVE);
        if let Some(up) = self.up {
            f.up = up;
        }
        if let Some(units) = self.units {
            f.units = units;
        }
        if let Some(h) = self.handedness {
            f.handedness = h;
        }
        f
    }

    /// The files asked for and how to write them.
    pub fn plan(&self) -> ExportPlan {
        ExportPlan {
            vdb: self.vdb.clone(),
            nvdb: self.nvdb.clone(),
            usd: self.usd.clone(),
            ktx2: self.ktx2.clone(),
            exr_render: self.exr_render.clone(),
            png_render: None,
            exr_slices: self.exr_slices.clone(),
            exr_atlas: self.exr_atlas.clone(),
            godot: self.godot.clone(),
            settings: ExportSettings {
                frame: self.frame(),
                half: self.half,
                threshold: self.threshold,
                grids: self.grids,
                compression: match self.compression {
                    Compression::None => VdbCompression::None,
                    Compression::Zip => VdbCompression::Zip,
                },
                ktx2_format: self.ktx2_format,
                exr_half: self.exr_half,
                bake_light: self.bake_light.then_some(match self.bake_phase {
                    BakePhaseArg::Isotropic => BakePhase::Isotropic,
                    BakePhaseArg::Camera => BakePhase::Camera,
                }),
            },
        }
    }
}

/// A problem found before the bake, in the command line's terms.
fn problem_message(problem: &ExportProblem) -> String {
    match problem {
        ExportProblem::UsdExtension(usd) => {
            format!("--usd {}: Fogsmith writes text USD; name the file with the .usda extension", usd.display())
        }
        ExportProblem::UsdLeftHanded(frame) => format!(
            "--usd: USD stages are right-handed, and the export frame is {frame}. Use --handedness right \
             (for Unreal: --up z --units cm; its USD importer converts to its own axes)"
        ),
        ExportProblem::UsdNeedsDensity => "--usd needs the density grid in the VDB: add density to --grids".into(),
        ExportProblem::Threshold(t) => format!("--threshold must be a finite number ≥ 0, got {t}"),
    }
}

/// Every target of `plan` for each frame: the paths with their frame numbers filled in. A
/// sequence's stage is one file for all frames; its VDBs default to `NAME.####.vdb`.
fn frame_plans(plan: &ExportPlan, frames: &FrameSet) -> Result<Vec<ExportPlan>, Box<dyn std::error::Error>> {
    if let Some(usd) = &plan.usd {
        if FramePattern::new(usd).has_frame() {
            return Err(format!(
                "--usd {}: one stage holds every frame (it points at each frame's VDB); name it without a frame number",
                usd.display()
            )
            .into());
        }
    }
    let vdb = plan.vdb.clone().or_else(|| plan.usd.as_ref().map(|u| suggest_pattern(&u.with_extension("vdb"))));
    let each = |flag: &str, path: &Option<PathBuf>| -> Result<Vec<Option<PathBuf>>, SequenceError> {
        match path {
            Some(p) => Ok(FramePattern::new(p).paths(flag, frames)?.into_iter().map(Some).collect()),
            None => Ok(vec![None; frames.len()]),
        }
    };
    let vdbs = each("--vdb", &vdb)?;
    let nvdbs = each("--nvdb", &plan.nvdb)?;
    let ktx2 = each("--ktx2", &plan.ktx2)?;
    let render = each("--exr-render", &plan.exr_render)?;
    let slices = each("--exr-slices", &plan.exr_slices)?;
    let atlas = each("--exr-atlas", &plan.exr_atlas)?;
    let godot = each("--godot", &plan.godot)?;
    Ok((0..frames.len())
        .map(|k| ExportPlan {
            vdb: vdbs[k].clone(),
            nvdb: nvdbs[k].clone(),
            usd: None,
            ktx2: ktx2[k].clone(),
            exr_render: render[k].clone(),
            png_render: None,
            exr_slices: slices[k].clone(),
            exr_atlas: atlas[k].clone(),
            godot: godot[k].clone(),
            settings: plan.settings,
        })
        .collect())
}

pub fn run(args: ExportArgs) -> Result<(), Box<dyn std::error::Error>> {
    let plan = args.plan();
    if plan.is_empty() {
        return Err(
            "nothing to export: give --vdb, --nvdb, --usd, --ktx2, --exr-render, --exr-slices, --exr-atlas and/or --godot"
                .into(),
        );
    }
    // Refuse what cannot be written before the (long) bake.
    if let Some(problem) = plan.problems().first() {
        return Err(problem_message(problem).into());
    }
    if plan.godot.is_some() && plan.settings.bake_light.is_none() {
        return Err("--godot draws the light bake: add --bake-light".into());
    }
    let bake_targets = [&plan.vdb_path(), &plan.nvdb, &plan.ktx2, &plan.exr_atlas, &plan.godot];
    if plan.settings.bake_light.is_some() && bake_targets.iter().all(|t| t.is_none()) {
        return Err(
            "--bake-light writes the emission into volume files: give --vdb, --nvdb, --usd, --ktx2, --exr-atlas or --godot"
                .into(),
        );
    }
    let frame = plan.settings.frame;
    let mut session = open(&args.bake)?;
    let (frames, set) = frames(&session.project, &args.bake.project, args.bake.frames.as_deref(), "--frames")?;
    let plans = match &set {
        Some(set) => frame_plans(&plan, set)?,
        None => vec![plan.clone()],
    };
    plan.create_folders()?;
    let fps = session.project.animation.map(|a| a.fps);
    let mut bar = Bar::new(args.bake.quiet);
    let mut summaries = Vec::new();
    let mut notes = Vec::new();
    let mut stage_frames = Vec::new();
    let mut fields = Vec::new();
    for (k, (&number, plan)) in frames.iter().zip(&plans).enumerate() {
        let started = std::time::Instant::now();
        let project = still(&session.project, number);
        if args.resume && plan.files().iter().all(|f| file_state(f) == FileState::Done) {
            if let (Some(vdb), Some(number)) = (plan.vdb_path(), number) {
                if fields.is_empty() {
                    fields = crate::export::vdb_read::list_vdb_grids(&vdb)?
                        .into_iter()
                        .map(|g| UsdField {
                            density: g.name == "density",
                            vector: g.tree_type.contains("vec3"),
                            name: g.name,
                        })
                        .collect();
                }
                stage_frames.push((number, vdb, project));
            }
            if !args.json {
                bar.suspend(|| eprintln!("frame {}: complete, skipped", number.unwrap_or(0)));
            }
            let mut summary = serde_json::Map::new();
            summary.insert("frame".into(), serde_json::json!(number));
            summary.insert("skipped".into(), serde_json::json!(true));
            summaries.push(summary);
            continue;
        }
        if args.resume {
            plan.files().iter().for_each(|f| remove_leftovers(f));
        }
        bar.frame(k, frames.len(), number);
        let report = session.bake(&project, &mut |p| bar.pipeline(p))?;
        // Every file goes beside its target first and replaces it only once all of the frame's are written.
        let mut staged = Staged::default();
        let ev = session.pipeline.read_ev()?;
        let opvs = (0..project.lights.len()).map(|l| session.pipeline.read_opv(l)).collect::<Result<Vec<_>, _>>()?;
        let image = if plan.needs_image() { Some(session.pipeline.read_image()?) } else { None };
        let mut bake_summary = None;
        let emission = match plan.settings.bake_light {
            Some(phase) => {
                let t = std::time::Instant::now();
                let emission = session.pipeline.bake_emission(&project, &session.request, phase).map_err(bake_error)?;
                if project.medium.albedo == 0.0 && k == 0 {
                    eprintln!(
                        "warning: medium.albedo is 0: the fog scatters no light, so the baked emission is 0 everywhere"
                    );
                }
                let ms = t.elapsed().as_secs_f64() * 1e3;
                bake_summary = Some(serde_json::json!({"phase": phase.name(), "ms": ms, "max": emission.max_value()}));
                Some(emission)
            }
            None => None,
        };
        let inputs = ExportInputs {
            project: &project,
            volumes: Some((&ev, &opvs)),
            image: image.as_ref(),
            emission: emission.as_ref(),
            render_size: [session.request.width, session.request.height],
            time: set.as_ref().zip(number).zip(fps).map(|((_, frame), fps)| FrameTime { frame, fps }),
        };
        let written = match write_plan(
            plan,
            &inputs,
            &mut staged,
            &mut |p| bar.stage(p.stage, p.fraction as f64),
            &interrupted,
        ) {
            Ok(w) => w,
            Err(ExportRunError::Cancelled) => return Err(Cancelled.into()),
            Err(ExportRunError::Failed(e)) => return Err(e.into()),
        };
        check()?;
        staged.commit()?;
        if args.resume {
            for file in plan.files() {
                write_sidecar(&file).map_err(|e| format!("{}: writing its checksum: {e}", file.display()))?;
            }
        }
        // A sequence says what each frame wrote as it goes.
        let mut file_notes = Vec::new();
        let mut summary = summarize(&written, &project, frame, bake_summary, &mut file_notes);
        if set.is_none() {
            notes.append(&mut file_notes);
        }
        summary.insert("timings_ms".into(), serde_json::json!(report.timings_ms));
        if set.is_some() {
            summary.insert("frame".into(), serde_json::json!(number));
            summary.insert("counters".into(), serde_json::json!(report.counters));
            summary.insert("seconds".into(), serde_json::json!(started.elapsed().as_secs_f64()));
            if !args.json {
                let files = plan.files().iter().map(|f| f.display().to_string()).collect::<Vec<_>>().join(", ");
                let seconds = started.elapsed().as_secs_f64();
                let n = frames.len();
                bar.suspend(|| {
                    eprintln!("frame {} ({}/{n}): wrote {files} in {seconds:.2} s", number.unwrap_or(0), k + 1)
                });
            }
        }
        if let (Some(vdb), Some(number)) = (&written.vdb, number) {
            stage_frames.push((number, vdb.0.clone(), project));
        }
        fields = written.vdb_fields;
        summaries.push(summary);
    }
    bar.finish();

    let mut out = serde_json::Map::new();
    out.insert("project".into(), serde_json::json!(args.bake.project));
    if let (Some(set), Some(usd)) = (&set, plan.usd.as_ref()) {
        let opts = UsdOptions {
            vdb_asset: String::new(),
            fields,
            frame,
            width: session.request.width,
            height: session.request.height,
        };
        let stage: Vec<StageFrame> = stage_frames
            .iter()
            .map(|(number, vdb, project)| StageFrame { frame: *number, project, vdb_asset: asset_path(usd, vdb) })
            .collect();
        let mut staged = Staged::default();
        staged.write(usd, |p| write_usd_sequence(p, &stage, fps.unwrap_or(24.0), &opts))?;
        check()?;
        staged.commit()?;
        if args.resume {
            write_sidecar(usd).map_err(|e| format!("{}: writing its checksum: {e}", usd.display()))?;
        }
        out.insert(
            "usd".into(),
            serde_json::json!({"path": usd, "frames": set.len(), "fields": opts.fields.len(), "frame": frame.to_string()}),
        );
        notes.push(format!(
            "wrote {} ({} frames of {} at {} fps, {frame})",
            usd.display(),
            set.len(),
            stage.first().map_or(String::new(), |f| f.vdb_asset.clone()),
            fps.unwrap_or(24.0)
        ));
    }
    if set.is_some() {
        out.insert(
            "frames".into(),
            serde_json::Value::Array(summaries.into_iter().map(serde_json::Value::Object).collect()),
        );
    } else if let Some(summary) = summaries.pop() {
        out.extend(summary);
    }
    if args.json {
        println!("{}", serde_json::Value::Object(out));
    } else {
        for note in notes {
            eprintln!("{note}");
        }
    }
    Ok(())
}

/// The JSON summary of one frame's files, and a line per file for the terminal.
fn summarize(
    written: &Written,
    project: &crate::scene::Project,
    frame: Frame,
    bake: Option<serde_json::Value>,
    notes: &mut Vec<String>,
) -> serde_json::Map<String, serde_json::Value> {
    let mut summary = serde_json::Map::new();
    if let Some(b) = bake {
        notes.push(format!(
            "baked the lighting ({} phase) in {:.0} ms",
            b["phase"].as_str().unwrap_or(""),
            b["ms"].as_f64().unwrap_or(0.0)
        ));
        summary.insert("bake".into(), b);
    }
    if let Some((path, stats, ms)) = &written.vdb {
        let grids_json: Vec<_> = stats
            .grids
            .iter()
            .map(|g| serde_json::json!({"name": g.name, "active_voxels": g.active_voxels, "leaves": g.leaves, "tiles": g.tiles, "bytes": g.bytes}))
            .collect();
        summary.insert(
            "vdb".into(),
            serde_json::json!({"path": path, "bytes": stats.bytes, "grids": grids_json, "ms": ms}),
        );
        notes.push(format!("wrote {} ({} bytes, {} grids, {frame})", path.display(), stats.bytes, stats.grids.len()));
    }
    if let Some((path, stats, ms)) = &written.nvdb {
        let grids_json: Vec<_> = stats
            .grids
            .iter()
            .map(|g| serde_json::json!({"name": g.name, "active_voxels": g.active_voxels, "leaves": g.leaves, "tiles": g.tiles, "bytes": g.bytes}))
            .collect();
        summary.insert(
            "nvdb".into(),
            serde_json::json!({"path": path, "bytes": stats.bytes, "grids": grids_json, "ms": ms}),
        );
        notes.push(format!(
            "wrote {} (NanoVDB, {} bytes, {} grids, {frame})",
            path.display(),
            stats.bytes,
            stats.grids.len()
        ));
    }
    if let Some(usd) = &written.usd {
        summary.insert(
            "usd".into(),
            serde_json::json!({"path": usd.path, "vdb": usd.vdb_asset, "fields": usd.fields, "frame": frame.to_string()}),
        );
        notes.push(format!(
            "wrote {} (volume from {}, {} lights, {frame})",
            usd.path.display(),
            usd.vdb_asset,
            usd.lights
        ));
    }
    if let Some((path, info, snippet_path)) = &written.ktx2 {
        summary.insert(
            "ktx2".into(),
            serde_json::json!({"path": path, "bytes": info.bytes, "scale": info.scale, "snippet": snippet_path}),
        );
        notes.push(format!(
            "wrote {} ({} bytes, texel × {} = extinction 1/m) and {}",
            path.display(),
            info.bytes,
            info.scale,
            snippet_path.display()
        ));
    }
    if let Some((path, [width, height])) = &written.exr_render {
        summary.insert("exr_render".into(), serde_json::json!({"path": path, "width": width, "height": height}));
        notes.push(format!("wrote {} ({width}×{height} linear RGBA)", path.display()));
    }
    if let Some((path, quantities)) = &written.exr_slices {
        summary.insert("exr_slices".into(), serde_json::json!({"path": path, "quantities": quantities}));
        notes.push(format!(
            "wrote {} ({quantities} quantities × {} z-slices)",
            path.display(),
            project.grid.resolution.z
        ));
    }
    if let Some((path, layout)) = &written.exr_atlas {
        summary.insert("exr_atlas".into(), serde_json::json!({"path": path, "layout": layout.to_string()}));
        notes.push(format!("wrote {}: {layout}", path.display()));
    }
    if let Some((path, layout, gain)) = &written.godot {
        summary.insert(
            "godot".into(),
            serde_json::json!({"path": path, "layout": layout.to_string(), "emission_gain": gain}),
        );
        notes.push(format!("wrote {} with its shader and texture ({layout}; emission gain {gain})", path.display()));
    }
    summary
}

/// A bake refused for want of lights says so in the user's terms, without the GPU's prefix.
fn bake_error(e: crate::gpu::GpuError) -> Box<dyn std::error::Error> {
    match e {
        crate::gpu::GpuError::Invalid(message) => message.into(),
        other => other.into(),
    }
}

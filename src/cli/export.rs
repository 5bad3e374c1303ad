//! `fogsmith export`: bake a project on the GPU and write VDB / EXR / USD / KTX2 files.

use super::progress::{check, Bar};
use super::{bake, BakeArgs};
use crate::export::exr::{write_atlas_exr_in_frame, write_render_exr, write_slices_exr};
use crate::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use crate::export::ktx::{fog_volume_snippet, write_ktx2, Ktx2Format};
use crate::export::light_infos;
use crate::export::usd::{asset_path, write_usd, UsdField, UsdOptions};
use crate::export::vdb::{grids_from_volumes, write_vdb_with_progress, GridSelection, VdbCompression, VdbOptions};
use crate::export::Staged;
use std::path::PathBuf;
use std::time::Instant;

#[derive(clap::Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub bake: BakeArgs,
    /// OpenVDB file with the density grid and per-light optical depth grids.
    #[arg(long)]
    pub vdb: Option<PathBuf>,
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
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
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
}

pub fn run(args: ExportArgs) -> Result<(), Box<dyn std::error::Error>> {
    if args.vdb.is_none()
        && args.exr_render.is_none()
        && args.exr_slices.is_none()
        && args.exr_atlas.is_none()
        && args.usd.is_none()
        && args.ktx2.is_none()
    {
        return Err(
            "nothing to export: give --vdb, --usd, --ktx2, --exr-render, --exr-slices and/or --exr-atlas".into()
        );
    }
    let frame = args.frame();
    // Refuse what cannot be written before the (long) bake.
    let vdb_path = args.vdb.clone().or_else(|| args.usd.as_ref().map(|u| u.with_extension("vdb")));
    if let Some(usd) = &args.usd {
        if usd.extension().and_then(|e| e.to_str()) != Some("usda") {
            return Err(format!(
                "--usd {}: Fogsmith writes text USD; name the file with the .usda extension",
                usd.display()
            )
            .into());
        }
        if frame.handedness == Handedness::Left {
            return Err(format!(
                "--usd: USD stages are right-handed, and the export frame is {frame}. Use --handedness right \
                 (for Unreal: --up z --units cm; its USD importer converts to its own axes)"
            )
            .into());
        }
        if !args.grids.density {
            return Err("--usd needs the density grid in the VDB: add density to --grids".into());
        }
    }
    if !args.threshold.is_finite() || args.threshold < 0.0 {
        return Err(format!("--threshold must be a finite number ≥ 0, got {}", args.threshold).into());
    }
    let baked = bake(&args.bake)?;
    let project = &baked.project;
    // Every file goes beside its target first and replaces it only once all are written.
    let mut staged = Staged::default();
    let mut bar = Bar::new(args.bake.quiet);
    let mut notes = Vec::new();
    let ev = baked.pipeline.read_ev()?;
    let opvs = (0..project.lights.len()).map(|l| baked.pipeline.read_opv(l)).collect::<Result<Vec<_>, _>>()?;
    let infos = light_infos(project);
    let mut summary = serde_json::Map::new();
    summary.insert("project".into(), serde_json::json!(args.bake.project));
    summary.insert("timings_ms".into(), serde_json::json!(baked.report.timings_ms));

    let mut fields = Vec::new();
    if let Some(path) = &vdb_path {
        let t = Instant::now();
        let lights: Vec<_> = opvs.iter().zip(&infos).map(|(v, l)| (v, l.in_frame(&frame))).collect();
        let grids = grids_from_volumes(&ev, &lights, args.grids);
        let opts = VdbOptions {
            compression: match args.compression {
                Compression::None => VdbCompression::None,
                Compression::Zip => VdbCompression::Zip,
            },
            half: args.half,
            threshold: args.threshold,
            frame,
            ..VdbOptions::default()
        };
        check()?;
        let stats = staged
            .write(path, |p| write_vdb_with_progress(p, &grids, &opts, &mut |f| bar.stage("write VDB", f as f64)))?;
        fields = grids.iter().map(|g| UsdField { name: g.name.clone(), density: g.name == "density" }).collect();
        let grids_json: Vec<_> = stats
            .grids
            .iter()
            .map(|g| serde_json::json!({"name": g.name, "active_voxels": g.active_voxels, "leaves": g.leaves, "tiles": g.tiles, "bytes": g.bytes}))
            .collect();
        summary.insert(
            "vdb".into(),
            serde_json::json!({"path": path, "bytes": stats.bytes, "grids": grids_json, "ms": t.elapsed().as_secs_f64() * 1e3}),
        );
        if !args.json {
            notes.push(format!(
                "wrote {} ({} bytes, {} grids, {frame})",
                path.display(),
                stats.bytes,
                stats.grids.len()
            ));
        }
    }
    if let (Some(path), Some(vdb)) = (&args.usd, &vdb_path) {
        let opts = UsdOptions {
            vdb_asset: asset_path(path, vdb),
            fields: fields.clone(),
            frame,
            width: baked.request.width,
            height: baked.request.height,
        };
        check()?;
        staged.write(path, |p| write_usd(p, project, &opts))?;
        summary.insert("usd".into(), serde_json::json!({"path": path, "vdb": opts.vdb_asset, "fields": fields.len(), "frame": frame.to_string()}));
        if !args.json {
            notes.push(format!(
                "wrote {} (volume from {}, {} lights, {frame})",
                path.display(),
                opts.vdb_asset,
                project.lights.iter().filter(|l| !l.hidden).count()
            ));
        }
    }
    if let Some(path) = &args.ktx2 {
        check()?;
        let info = staged.write(path, |p| write_ktx2(p, &ev, args.ktx2_format))?;
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let snippet_path = path.with_extension("fogvolume.ron");
        staged.write(&snippet_path, |p| {
            crate::export::write_text(p, &fog_volume_snippet(&ev, &project.medium, &info, &name))
        })?;
        summary.insert(
            "ktx2".into(),
            serde_json::json!({"path": path, "bytes": info.bytes, "scale": info.scale, "snippet": snippet_path}),
        );
        if !args.json {
            notes.push(format!(
                "wrote {} ({} bytes, texel × {} = extinction 1/m) and {}",
                path.display(),
                info.bytes,
                info.scale,
                snippet_path.display()
            ));
        }
    }
    if let Some(path) = &args.exr_render {
        let image = baked.pipeline.read_image()?;
        check()?;
        staged.write(path, |p| {
            write_render_exr(p, image.width as usize, image.height as usize, &image.rgba, args.exr_half)
        })?;
        summary.insert(
            "exr_render".into(),
            serde_json::json!({"path": path, "width": image.width, "height": image.height}),
        );
        if !args.json {
            notes.push(format!("wrote {} ({}×{} linear RGBA)", path.display(), image.width, image.height));
        }
    }
    if let Some(path) = &args.exr_slices {
        let names: Vec<String> = (0..opvs.len()).map(|l| format!("optical_depth_{l}")).collect();
        let mut layers: Vec<(&str, &crate::scene::Volume)> = vec![("density", &ev)];
        layers.extend(names.iter().map(String::as_str).zip(opvs.iter()));
        check()?;
        staged.write(path, |p| write_slices_exr(p, &layers))?;
        summary.insert("exr_slices".into(), serde_json::json!({"path": path, "quantities": layers.len()}));
        if !args.json {
            notes.push(format!(
                "wrote {} ({} quantities × {} z-slices)",
                path.display(),
                layers.len(),
                project.grid.resolution.z
            ));
        }
    }
    if let Some(path) = &args.exr_atlas {
        check()?;
        let layout = staged.write(path, |p| write_atlas_exr_in_frame(p, &ev, &frame))?;
        summary.insert("exr_atlas".into(), serde_json::json!({"path": path, "layout": layout.to_string()}));
        if !args.json {
            notes.push(format!("wrote {}: {layout}", path.display()));
        }
    }
    check()?;
    bar.finish();
    staged.commit()?;
    for note in notes {
        eprintln!("{note}");
    }
    if args.json {
        println!("{}", serde_json::Value::Object(summary));
    }
    Ok(())
}

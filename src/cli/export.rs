//! `fogsmith export`: bake a project on the GPU and write VDB / EXR files.

use super::{bake, BakeArgs};
use crate::export::exr::{write_atlas_exr, write_render_exr, write_slices_exr};
use crate::export::vdb::{grids_from_volumes, write_vdb, GridSelection, VdbCompression, VdbOptions};
use crate::export::light_infos;
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
    /// Print a JSON summary on stdout.
    #[arg(long)]
    pub json: bool,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum Compression {
    None,
    Zip,
}

pub fn run(args: ExportArgs) -> Result<(), Box<dyn std::error::Error>> {
    if args.vdb.is_none() && args.exr_render.is_none() && args.exr_slices.is_none() && args.exr_atlas.is_none() {
        return Err("nothing to export: give --vdb, --exr-render, --exr-slices and/or --exr-atlas".into());
    }
    if !args.threshold.is_finite() || args.threshold < 0.0 {
        return Err(format!("--threshold must be a finite number ≥ 0, got {}", args.threshold).into());
    }
    let baked = bake(&args.bake)?;
    let project = &baked.project;
    let ev = baked.pipeline.read_ev()?;
    let opvs = (0..project.lights.len()).map(|l| baked.pipeline.read_opv(l)).collect::<Result<Vec<_>, _>>()?;
    let infos = light_infos(project);
    let mut summary = serde_json::Map::new();
    summary.insert("project".into(), serde_json::json!(args.bake.project));
    summary.insert("timings_ms".into(), serde_json::json!(baked.report.timings_ms));

    if let Some(path) = &args.vdb {
        let t = Instant::now();
        let lights: Vec<_> = opvs.iter().zip(&infos).map(|(v, l)| (v, *l)).collect();
        let grids = grids_from_volumes(&ev, &lights, args.grids);
        let opts = VdbOptions {
            compression: match args.compression {
                Compression::None => VdbCompression::None,
                Compression::Zip => VdbCompression::Zip,
            },
            half: args.half,
            threshold: args.threshold,
            ..VdbOptions::default()
        };
        let stats = write_vdb(path, &grids, &opts)?;
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
            eprintln!("wrote {} ({} bytes, {} grids)", path.display(), stats.bytes, stats.grids.len());
        }
    }
    if let Some(path) = &args.exr_render {
        let image = baked.pipeline.read_image()?;
        write_render_exr(path, image.width as usize, image.height as usize, &image.rgba, args.exr_half)?;
        summary.insert("exr_render".into(), serde_json::json!({"path": path, "width": image.width, "height": image.height}));
        if !args.json {
            eprintln!("wrote {} ({}×{} linear RGBA)", path.display(), image.width, image.height);
        }
    }
    if let Some(path) = &args.exr_slices {
        let names: Vec<String> = (0..opvs.len()).map(|l| format!("optical_depth_{l}")).collect();
        let mut layers: Vec<(&str, &crate::scene::Volume)> = vec![("density", &ev)];
        layers.extend(names.iter().map(String::as_str).zip(opvs.iter()));
        write_slices_exr(path, &layers)?;
        summary.insert("exr_slices".into(), serde_json::json!({"path": path, "quantities": layers.len()}));
        if !args.json {
            eprintln!("wrote {} ({} quantities × {} z-slices)", path.display(), layers.len(), project.grid.resolution.z);
        }
    }
    if let Some(path) = &args.exr_atlas {
        let layout = write_atlas_exr(path, &ev)?;
        summary.insert("exr_atlas".into(), serde_json::json!({"path": path, "layout": layout.to_string()}));
        if !args.json {
            eprintln!("wrote {}: {layout}", path.display());
        }
    }
    if args.json {
        println!("{}", serde_json::Value::Object(summary));
    }
    Ok(())
}

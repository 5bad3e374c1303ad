//! Measures export file sizes and times for the demo projects.
//!
//! `cargo run --example export_sizes [projects/*.ron]` (set `FOGSMITH_SIZES_OUT=DIR` to keep
//! the files).
//!
//! The GPU pipeline is not needed: the extinction is evaluated on the CPU at cell centres
//! (base + Σ c·exp(−d²/r²), particles cut off below 1e-4 1/m) and each light's optical depth
//! by marching from the light to every cell centre (step ½ cell, nearest-cell lookups), which
//! is close enough to the baked grids for file sizes.

use fogsmith::export::exr::{write_atlas_exr, write_slices_exr};
use fogsmith::export::vdb::{grids_from_volumes, write_vdb, GridSelection, VdbCompression, VdbOptions};
use fogsmith::export::LightInfo;
use fogsmith::scene::{load_project, Project, Volume};
use std::path::PathBuf;
use std::time::Instant;

fn extinction(p: &Project) -> Volume {
    let g = p.grid;
    let mut data = vec![p.medium.base_extinction; g.cell_count() as usize];
    let h = g.cell_size();
    let r = g.resolution;
    for part in p.particles.iter().filter(|q| !q.hidden) {
        let cut = part.cutoff_radius(1e-4);
        let lo = ((part.center - cut - g.min) / h).floor().max(glam::Vec3::ZERO).as_uvec3();
        let hi = ((part.center + cut - g.min) / h).ceil().min(r.as_vec3()).as_uvec3();
        for k in lo.z..hi.z {
            for j in lo.y..hi.y {
                for i in lo.x..hi.x {
                    let d2 = (g.cell_center(i, j, k) - part.center).length_squared();
                    data[g.index(i, j, k)] += part.density * (-d2 / (part.radius * part.radius)).exp();
                }
            }
        }
    }
    Volume::new(g, data)
}

fn optical_depth(ev: &Volume, light: glam::Vec3) -> Volume {
    let g = ev.grid;
    let h = g.cell_size();
    let step = h.min_element() * 0.5;
    let r = g.resolution;
    let mut data = vec![0.0; g.cell_count() as usize];
    for k in 0..r.z {
        for j in 0..r.y {
            for i in 0..r.x {
                let c = g.cell_center(i, j, k);
                let d = c - light;
                let n = (d.length() / step).ceil().max(1.0) as u32;
                let ds = d.length() / n as f32;
                let mut t = 0.0;
                for s in 0..n {
                    let x = light + d * ((s as f32 + 0.5) / n as f32);
                    let q = ((x - g.min) / h).floor();
                    if q.cmpge(glam::Vec3::ZERO).all() && q.cmplt(r.as_vec3()).all() {
                        t += ev.get(q.x as u32, q.y as u32, q.z as u32) * ds;
                    }
                }
                data[g.index(i, j, k)] = t;
            }
        }
    }
    Volume::new(g, data)
}

fn main() {
    let args: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let projects = if args.is_empty() {
        ["cloud", "cornell", "street"].map(|n| PathBuf::from(format!("projects/{n}.ron"))).to_vec()
    } else {
        args
    };
    // FOGSMITH_SIZES_OUT=DIR keeps the files (last variant of each kind) for inspection.
    let keep = std::env::var_os("FOGSMITH_SIZES_OUT").map(PathBuf::from);
    let dir = keep.clone().unwrap_or_else(|| std::env::temp_dir().join(format!("fogsmith-sizes-{}", std::process::id())));
    std::fs::create_dir_all(&dir).expect("temp dir");
    println!("| scene | grid | grids | variant | bytes | active voxels | leaves | tiles | write ms |");
    println!("|---|---|---|---|---:|---:|---:|---:|---:|");
    for path in projects {
        let project = load_project(&path).unwrap_or_else(|e| panic!("{e}"));
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let ev = extinction(&project);
        let opvs: Vec<Volume> = project.lights.iter().map(|l| optical_depth(&ev, l.position)).collect();
        let lights: Vec<(&Volume, LightInfo)> = opvs
            .iter()
            .zip(&project.lights)
            .map(|(v, l)| (v, LightInfo { position: l.position.to_array(), intensity: l.intensity, color: l.color.to_array() }))
            .collect();
        let r = project.grid.resolution;
        let grid = format!("{}×{}×{}", r.x, r.y, r.z);
        let grids = grids_from_volumes(&ev, &lights, GridSelection::default());
        let dense = 4 * project.grid.cell_count() * grids.len() as u64;
        println!("| {name} | {grid} | {} | dense f32 (reference: 4 B × cells × grids) | {dense} | | | | |", grids.len());
        let variants = [
            ("float, none", VdbOptions { compression: VdbCompression::None, ..Default::default() }),
            ("float, zip", VdbOptions::default()),
            ("half, none", VdbOptions { compression: VdbCompression::None, half: true, ..Default::default() }),
            ("half, zip", VdbOptions { half: true, ..Default::default() }),
            ("float, zip, threshold 1e-3", VdbOptions { threshold: 1e-3, ..Default::default() }),
            ("half, zip, threshold 1e-3", VdbOptions { threshold: 1e-3, half: true, ..Default::default() }),
        ];
        for (label, opts) in variants {
            let out = dir.join(format!("{name}_{}.vdb", label.replace([',', ' ', '.'], "_")));
            let t0 = Instant::now();
            let stats = write_vdb(&out, &grids, &opts).expect("write vdb");
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let active: u64 = stats.grids.iter().map(|g| g.active_voxels).sum();
            let leaves: u64 = stats.grids.iter().map(|g| g.leaves).sum();
            let tiles: u64 = stats.grids.iter().map(|g| g.tiles).sum();
            println!("| {name} | {grid} | {} | VDB {label} | {} | {active} | {leaves} | {tiles} | {ms:.1} |", grids.len(), stats.bytes);
        }
        let density_only = grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: false, transmittance: false });
        let out = dir.join(format!("{name}_density.vdb"));
        let t0 = Instant::now();
        let stats = write_vdb(&out, &density_only, &VdbOptions::default()).expect("write vdb");
        println!(
            "| {name} | {grid} | 1 | VDB density only, float, zip | {} | {} | {} | {} | {:.1} |",
            stats.bytes, stats.grids[0].active_voxels, stats.grids[0].leaves, stats.grids[0].tiles, t0.elapsed().as_secs_f64() * 1e3
        );
        // Import it back as a base layer (read + resample onto the same grid).
        let t0 = Instant::now();
        let imported = fogsmith::export::vdb_read::import_density(&out, Some("density"), &project.grid, 1.0).expect("import");
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        assert_eq!(imported.data, ev.data, "import gives the EV back exactly");
        println!("| {name} | {grid} | 1 | import density (read + resample, exact) | {} | | | | {ms:.1} |", stats.bytes);
        let mut named: Vec<(String, &Volume)> = vec![("density".into(), &ev)];
        named.extend(opvs.iter().enumerate().map(|(i, v)| (format!("optical_depth_{i}"), v)));
        let named_refs: Vec<(&str, &Volume)> = named.iter().map(|(n, v)| (n.as_str(), *v)).collect();
        let out = dir.join(format!("{name}_slices.exr"));
        let t0 = Instant::now();
        write_slices_exr(&out, &named_refs).expect("slices");
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let bytes = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
        println!("| {name} | {grid} | {} | EXR slices (f32, zip) | {bytes} | | | | {ms:.1} |", named.len());
        let out = dir.join(format!("{name}_atlas.exr"));
        let t0 = Instant::now();
        let layout = write_atlas_exr(&out, &ev).expect("atlas");
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let bytes = std::fs::metadata(&out).map(|m| m.len()).unwrap_or(0);
        println!("| {name} | {grid} | 1 | EXR atlas {}×{} tiles (f32, zip) | {bytes} | | | | {ms:.1} |", layout.tiles_x, layout.tiles_y);
    }
    if keep.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
}

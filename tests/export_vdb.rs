//! VDB export and import: our writer read back by our reader and by OpenVDB itself
//! (python3-openvdb), and files written by OpenVDB imported by our reader.

use fogsmith::export::vdb::{
    grids_from_volumes, half_round, write_vdb, GridSelection, VdbCompression, VdbGrid, VdbOptions,
};
use fogsmith::export::vdb_read::{read_vdb_grid, list_vdb_grids, resample_into};
use fogsmith::export::LightInfo;
use fogsmith::scene::{GridSpec, Volume};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const PY: &str = "/usr/bin/python3";

fn openvdb_available() -> bool {
    let ok = Command::new(PY).args(["-c", "import pyopenvdb"]).output().map(|o| o.status.success()).unwrap_or(false);
    if !ok {
        eprintln!("\n\n!!!!!!!! SKIPPED: /usr/bin/python3 cannot import pyopenvdb; install python3-openvdb (setup.sh) to check VDB files against OpenVDB itself !!!!!!!!\n\n");
    }
    ok
}

fn tests_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests")
}

/// A blob of fog with exact zeros around it, a constant 8³ block (a tile) and leaves cut by
/// the grid's edge (37 × 20 × 17 cells).
fn test_volume(min: Vec3, max: Vec3) -> Volume {
    let grid = GridSpec { min, max, resolution: UVec3::new(37, 20, 17) };
    let mut data = vec![0.0f32; grid.cell_count() as usize];
    for k in 0..17u32 {
        for j in 0..20u32 {
            for i in 0..37u32 {
                let d2 = (i as f32 - 8.3).powi(2) + (j as f32 - 6.1).powi(2) + (k as f32 - 9.7).powi(2);
                let mut v = 2.0 * (-d2 / 16.0).exp();
                if v < 0.01 {
                    v = 0.0;
                }
                if (16..24).contains(&i) && (8..16).contains(&j) && k < 8 {
                    v = 0.5;
                }
                if i == 36 && j == 19 && k == 16 {
                    v = 3.25; // the far corner, in a leaf cut by all three edges
                }
                data[grid.index(i, j, k)] = v;
            }
        }
    }
    Volume::new(grid, data)
}

fn light() -> LightInfo {
    LightInfo { position: [1.5, 3.0, -0.25], intensity: 40.0, color: [1.0, 0.9, 0.8] }
}

fn opv_of(ev: &Volume) -> Volume {
    // Any smooth positive field does: the writer does not care where it came from.
    let data = ev.data.iter().enumerate().map(|(n, v)| if n % 7 == 0 { 0.0 } else { v * 0.37 + (n % 11) as f32 * 0.01 }).collect();
    Volume::new(ev.grid, data)
}

fn run_check(path: &Path, grid: &GridSpec) -> Value {
    let r = grid.resolution;
    let out = Command::new(PY)
        .arg(tests_dir().join("vdb_check.py"))
        .arg(path)
        .args([r.x.to_string(), r.y.to_string(), r.z.to_string()])
        .output()
        .expect("run vdb_check.py");
    assert!(out.status.success(), "OpenVDB could not read {}: {}", path.display(), String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).expect("vdb_check.py prints JSON")
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

/// What a voxel reads back as after export with `opts`.
fn expected(v: f32, bg: f32, opts: &VdbOptions) -> (f32, bool) {
    let active = !((v - bg).abs() <= opts.threshold);
    let stored = if active { v } else { bg };
    (if opts.half { half_round(stored) } else { stored }, active)
}

fn check_against_openvdb(tag: &str, min: Vec3, max: Vec3, opts: VdbOptions) {
    let ev = test_volume(min, max);
    let opv = opv_of(&ev);
    let lights = [(&opv, light())];
    let grids = grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: true, transmittance: true });
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(format!("{tag}.vdb"));
    let stats = write_vdb(&path, &grids, &opts).unwrap();
    assert_eq!(stats.bytes, std::fs::metadata(&path).unwrap().len());
    eprintln!("{tag}: {} bytes, {:?}", stats.bytes, stats.grids.iter().map(|g| (&g.name, g.active_voxels, g.leaves, g.tiles)).collect::<Vec<_>>());

    // Our own reader first: every voxel, active or not.
    for g in &grids {
        let back = read_vdb_grid(&path, Some(&g.name)).unwrap();
        let r = g.spec.resolution;
        let mut active = 0u64;
        for k in 0..r.z {
            for j in 0..r.y {
                for i in 0..r.x {
                    let (want, on) = expected(g.values[g.spec.index(i, j, k)], g.background, &opts);
                    let p = [i as i32, j as i32, k as i32];
                    assert_eq!(back.value_at(p).to_bits(), want.to_bits(), "{tag} {} ours at {p:?}", g.name);
                    assert_eq!(back.is_active(p), on, "{tag} {} ours active at {p:?}", g.name);
                    active += on as u64;
                }
            }
        }
        assert_eq!(back.active_voxel_count(), active, "{tag} {}", g.name);
        // Resampling onto the grid it came from gives the values back exactly.
        let resampled = resample_into(&g.spec, &back, 1.0);
        for (n, v) in resampled.iter().enumerate() {
            let (want, _) = expected(g.values[n], g.background, &opts);
            assert_eq!(v.to_bits(), want.to_bits(), "{tag} {} resampled cell {n}", g.name);
        }
    }

    if !openvdb_available() {
        return;
    }
    let report = run_check(&path, &ev.grid);
    let read = report["grids"].as_array().unwrap();
    let names: Vec<&str> = read.iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["density", "optical_depth_0", "transmittance_0"], "{tag}");
    assert_eq!(report["file_metadata"]["creator"], "fogsmith");
    for (g, s) in grids.iter().zip(&stats.grids) {
        let o = read.iter().find(|o| o["name"] == g.name.as_str()).unwrap();
        assert_eq!(o["value_type"], "float", "{tag} {}", g.name);
        assert_eq!(o["half"].as_bool().unwrap(), opts.half, "{tag} {}", g.name);
        assert_eq!(o["meta"]["class"], "fog volume");
        assert_eq!(o["meta"]["creator"], "fogsmith");
        assert_eq!(f(&o["background"]) as f32, g.background);
        if g.name != "density" {
            let p: Vec<f64> = o["meta"]["light_position"].as_array().unwrap().iter().map(f).collect();
            assert_eq!(p, light().position.map(f64::from), "{tag} {}", g.name);
            assert_eq!(f(&o["meta"]["light_intensity"]), 40.0);
        }
        // Active voxels, leaves and the active bbox.
        assert_eq!(o["active"].as_u64().unwrap(), s.active_voxels, "{tag} {} active voxels", g.name);
        assert_eq!(o["leaves"].as_u64().unwrap(), s.leaves, "{tag} {} leaves", g.name);
        let r = g.spec.resolution;
        let (mut lo, mut hi) = ([i64::MAX; 3], [i64::MIN; 3]);
        for k in 0..r.z {
            for j in 0..r.y {
                for i in 0..r.x {
                    if expected(g.values[g.spec.index(i, j, k)], g.background, &opts).1 {
                        for (a, c) in [i, j, k].into_iter().enumerate() {
                            lo[a] = lo[a].min(c as i64);
                            hi[a] = hi[a].max(c as i64);
                        }
                    }
                }
            }
        }
        let bbox: Vec<Vec<i64>> = o["bbox"].as_array().unwrap().iter().map(|c| c.as_array().unwrap().iter().map(|x| x.as_i64().unwrap()).collect()).collect();
        assert_eq!(bbox, vec![lo.to_vec(), hi.to_vec()], "{tag} {} bbox", g.name);
        // Transform: voxel size and index -> world of a few voxels = the cell centres.
        let h = g.spec.cell_size();
        let vs: Vec<f64> = o["voxel_size"].as_array().unwrap().iter().map(f).collect();
        for a in 0..3 {
            assert!((vs[a] - h[a] as f64).abs() <= 1e-6 * h[a] as f64, "{tag} voxel size {vs:?} vs {h}");
        }
        for w in o["world"].as_array().unwrap() {
            let ijk: Vec<u32> = w[0].as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as u32).collect();
            let xyz: Vec<f64> = w[1].as_array().unwrap().iter().map(f).collect();
            let c = g.spec.cell_center(ijk[0], ijk[1], ijk[2]);
            for a in 0..3 {
                assert!((xyz[a] - c[a] as f64).abs() < 1e-5, "{tag} index {ijk:?} -> {xyz:?}, cell centre {c}");
            }
        }
        // Every voxel's value and active state.
        let values = o["values"].as_array().unwrap();
        let act = o["active_mask"].as_array().unwrap();
        for (n, v) in g.values.iter().enumerate() {
            let (want, on) = expected(*v, g.background, &opts);
            assert_eq!(f(&values[n]) as f32, want, "{tag} {} OpenVDB value at cell {n}", g.name);
            assert_eq!(act[n].as_bool().unwrap(), on, "{tag} {} OpenVDB active at cell {n}", g.name);
        }
    }
}

const CUBE_MIN: Vec3 = Vec3::new(-1.0, 0.5, 2.0);
fn cube_max() -> Vec3 {
    CUBE_MIN + 0.125 * Vec3::new(37.0, 20.0, 17.0)
}

#[test]
fn openvdb_reads_float_uncompressed() {
    check_against_openvdb("float_none", CUBE_MIN, cube_max(), VdbOptions { compression: VdbCompression::None, ..Default::default() });
}

#[test]
fn openvdb_reads_float_zip() {
    check_against_openvdb("float_zip", CUBE_MIN, cube_max(), VdbOptions::default());
}

#[test]
fn openvdb_reads_half_zip_and_half_uncompressed() {
    check_against_openvdb("half_zip", CUBE_MIN, cube_max(), VdbOptions { half: true, ..Default::default() });
    check_against_openvdb("half_none", CUBE_MIN, cube_max(), VdbOptions { half: true, compression: VdbCompression::None, ..Default::default() });
}

#[test]
fn openvdb_reads_threshold_no_tiles_and_non_cubic_cells() {
    check_against_openvdb("threshold", CUBE_MIN, cube_max(), VdbOptions { threshold: 0.05, tiles: false, ..Default::default() });
    check_against_openvdb("non_cubic", Vec3::new(-3.0, 0.0, 1.0), Vec3::new(1.0, 2.5, 2.0), VdbOptions::default());
}

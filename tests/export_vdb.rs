//! VDB export and import: our writer read back by our reader and by OpenVDB itself
//! (python3-openvdb), and files written by OpenVDB imported by our reader.

mod common;

use fogsmith::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use fogsmith::export::vdb::{
    grids_from_volumes, half_round, write_vdb, GridClass, GridSelection, VdbCompression, VdbGrid, VdbOptions,
};
use fogsmith::export::vdb_read::{list_vdb_grids, read_vdb_grid, resample_into};
use fogsmith::export::LightInfo;
use fogsmith::scene::{GridSpec, Volume};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const PY: &str = "/usr/bin/python3";

/// The OpenVDB checks are part of the suite: a machine without the validator fails them loudly.
fn require_openvdb() {
    let ok = Command::new(PY).args(["-c", "import pyopenvdb"]).output().map(|o| o.status.success()).unwrap_or(false);
    assert!(ok, "/usr/bin/python3 cannot import pyopenvdb: run ./setup.sh (it installs python3-openvdb) to check VDB files against OpenVDB itself");
}

fn tests_dir() -> PathBuf {
    common::root().join("tests")
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
    LightInfo { id: 7, position: [1.5, 3.0, -0.25], intensity: 40.0, color: [1.0, 0.9, 0.8] }
}

fn opv_of(ev: &Volume) -> Volume {
    // Any smooth positive field does: the writer does not care where it came from.
    let data = ev
        .data
        .iter()
        .enumerate()
        .map(|(n, v)| if n % 7 == 0 { 0.0 } else { v * 0.37 + (n % 11) as f32 * 0.01 })
        .collect();
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
    assert!(
        out.status.success(),
        "OpenVDB could not read {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("vdb_check.py prints JSON")
}

fn f(v: &Value) -> f64 {
    v.as_f64().expect("number")
}

/// What a voxel reads back as after export with `opts`.
fn expected(v: f32, bg: f32, opts: &VdbOptions) -> (f32, bool) {
    let active = (v - bg).abs() > opts.threshold || (v - bg).is_nan();
    let stored = if active { v } else { bg };
    (if opts.half { half_round(stored) } else { stored }, active)
}

fn check_against_openvdb(tag: &str, min: Vec3, max: Vec3, opts: VdbOptions) {
    let ev = test_volume(min, max);
    let opv = opv_of(&ev);
    let frame = opts.frame;
    let lights = [(&opv, light().in_frame(&frame))];
    let grids =
        grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: true, transmittance: true });
    let dir = common::temp_dir();
    let path = dir.path().join(format!("{tag}.vdb"));
    let stats = write_vdb(&path, &grids, &opts).unwrap();
    assert_eq!(stats.bytes, std::fs::metadata(&path).unwrap().len());
    eprintln!(
        "{tag}: {} bytes, {:?}",
        stats.bytes,
        stats.grids.iter().map(|g| (&g.name, g.active_voxels, g.leaves, g.tiles)).collect::<Vec<_>>()
    );

    // Our own reader first: every voxel, active or not.
    for g in &grids {
        let back = read_vdb_grid(&path, Some(&g.name)).unwrap();
        assert_eq!(back.frame, frame, "{tag} {}", g.name);
        let class = back.metadata.iter().find(|m| m.0 == "class").map(|m| String::from_utf8_lossy(&m.2).into_owned());
        assert_eq!(class.as_deref(), Some(g.class.as_str()), "{tag} {}", g.name);
        // Index -> world: every corner of the grid lands on its cell centre in the frame.
        let r = g.spec.resolution;
        for (i, j, k) in
            [(0, 0, 0), (r.x - 1, 0, 0), (0, r.y - 1, 0), (0, 0, r.z - 1), (r.x - 1, r.y - 1, r.z - 1), (3, 5, 7)]
        {
            // The centre in f64: min + (i + ½)·(max − min)/res, carried into the frame.
            let (lo, hi) = (g.spec.min.as_dvec3(), g.spec.max.as_dvec3());
            let ijk = [i, j, k];
            let centre = [0, 1, 2].map(|a| lo[a] + (ijk[a] as f64 + 0.5) * (hi[a] - lo[a]) / r[a] as f64);
            let c = frame.point(centre);
            let w = back.transform.index_to_world([i as f64, j as f64, k as f64]);
            for a in 0..3 {
                assert!(
                    (w[a] - c[a]).abs() <= 1e-9 * frame.scale() * 10.0,
                    "{tag} {} index {:?} -> {w:?}, want {c:?}",
                    g.name,
                    (i, j, k)
                );
            }
        }
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

    require_openvdb();
    let report = run_check(&path, &ev.grid);
    let read = report["grids"].as_array().unwrap();
    let names: Vec<&str> = read.iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["density", "optical_depth_0", "transmittance_0"], "{tag}");
    assert_eq!(report["file_metadata"]["creator"], "fogsmith");
    assert_eq!(report["file_metadata"]["up_axis"], frame.up_name(), "{tag}");
    assert_eq!(report["file_metadata"]["handedness"], frame.handedness_name(), "{tag}");
    assert_eq!(
        report["file_metadata"]["meters_per_unit"].as_str().unwrap().parse::<f64>().unwrap(),
        frame.meters_per_unit(),
        "{tag}"
    );
    for (g, s) in grids.iter().zip(&stats.grids) {
        let o = read.iter().find(|o| o["name"] == g.name.as_str()).unwrap();
        assert_eq!(o["value_type"], "float", "{tag} {}", g.name);
        assert_eq!(o["half"].as_bool().unwrap(), opts.half, "{tag} {}", g.name);
        assert_eq!(o["meta"]["class"], g.class.as_str(), "{tag} {}", g.name);
        assert_eq!(o["meta"]["up_axis"], frame.up_name(), "{tag}");
        assert_eq!(o["meta"]["handedness"], frame.handedness_name(), "{tag}");
        assert_eq!(f(&o["meta"]["meters_per_unit"]), frame.meters_per_unit(), "{tag}");
        assert_eq!(o["meta"]["creator"], "fogsmith");
        assert_eq!(f(&o["background"]) as f32, g.background);
        if g.name != "density" {
            let p: Vec<f64> = o["meta"]["light_position"].as_array().unwrap().iter().map(f).collect();
            assert_eq!(p, frame.point_f32(light().position).map(f64::from), "{tag} {}", g.name);
            assert_eq!(f(&o["meta"]["light_intensity"]), 40.0);
            assert_eq!(f(&o["meta"]["light_id"]), 7.0, "{tag} {}: the light's stable id", g.name);
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
        let bbox: Vec<Vec<i64>> = o["bbox"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_array().unwrap().iter().map(|x| x.as_i64().unwrap()).collect())
            .collect();
        assert_eq!(bbox, vec![lo.to_vec(), hi.to_vec()], "{tag} {} bbox", g.name);
        // Transform: voxel size and index -> world of a few voxels = the cell centres, carried
        // into the export frame.
        let h = g.spec.cell_size().as_dvec3() * frame.scale();
        let vs: Vec<f64> = o["voxel_size"].as_array().unwrap().iter().map(f).collect();
        for a in 0..3 {
            assert!((vs[a] - h[a]).abs() <= 1e-6 * h[a], "{tag} voxel size {vs:?} vs {h}");
        }
        for w in o["world"].as_array().unwrap() {
            let ijk: Vec<u32> = w[0].as_array().unwrap().iter().map(|x| x.as_u64().unwrap() as u32).collect();
            let xyz: Vec<f64> = w[1].as_array().unwrap().iter().map(f).collect();
            let c = frame.point(g.spec.cell_center(ijk[0], ijk[1], ijk[2]).to_array().map(f64::from));
            for a in 0..3 {
                assert!(
                    (xyz[a] - c[a]).abs() < 1e-5 * frame.scale(),
                    "{tag} index {ijk:?} -> {xyz:?}, cell centre {c:?}"
                );
            }
        }
        // Every voxel's value and active state.
        let values = o["values"].as_array().unwrap();
        let act = o["active_mask"].as_array().unwrap();
        for (n, v) in g.values.iter().enumerate() {
            let (want, on) = expected(*v, g.background, &opts);
            assert_eq!(
                values[n].as_u64().unwrap() as u32,
                want.to_bits(),
                "{tag} {} OpenVDB value at cell {n}: {} vs {want}",
                g.name,
                f32::from_bits(values[n].as_u64().unwrap() as u32)
            );
            assert_eq!(act[n].as_bool().unwrap(), on, "{tag} {} OpenVDB active at cell {n}", g.name);
        }
    }
}

/// A grid longer than one root node (4096 voxels) and an empty grid: several root children
/// in OpenVDB's order, and a tree with none.
#[test]
fn openvdb_reads_several_root_nodes_and_an_empty_grid() {
    let grid = GridSpec {
        min: Vec3::new(-100.0, 0.0, 0.0),
        max: Vec3::new(105.0, 0.1, 0.05),
        resolution: UVec3::new(4100, 2, 1),
    };
    let mut data = vec![0.0f32; grid.cell_count() as usize];
    for (n, i) in [0u32, 7, 8, 4095, 4096, 4099].into_iter().enumerate() {
        data[grid.index(i, 1, 0)] = 1.0 + n as f32;
    }
    let long = Volume::new(grid, data);
    let empty = Volume::new(grid, vec![0.0; grid.cell_count() as usize]);
    let grids = vec![VdbGrid::from_volume("density", &long), VdbGrid::from_volume("empty", &empty)];
    let dir = common::temp_dir();
    let path = dir.path().join("long.vdb");
    let stats = write_vdb(&path, &grids, &VdbOptions::default()).unwrap();
    assert_eq!(stats.grids[0].active_voxels, 6);
    assert_eq!(stats.grids[0].leaves, 4); // leaves at x = 0, 8, 4088, 4096
    assert_eq!(stats.grids[1].active_voxels, 0);
    let back = read_vdb_grid(&path, Some("density")).unwrap();
    assert_eq!(back.value_at([4099, 1, 0]), 6.0);
    assert_eq!(back.active_bbox(), Some(([0, 1, 0], [4099, 1, 0])));
    let e = read_vdb_grid(&path, Some("empty")).unwrap();
    assert_eq!((e.active_voxel_count(), e.active_bbox(), e.value_at([5, 1, 0])), (0, None, 0.0));
    require_openvdb();
    let report = run_check(&path, &grid);
    let g = &report["grids"].as_array().unwrap().iter().find(|g| g["name"] == "density").unwrap();
    assert_eq!(g["active"], 6);
    let values = g["values"].as_array().unwrap();
    for (n, v) in long.data.iter().enumerate() {
        assert_eq!(values[n].as_u64().unwrap() as u32, v.to_bits(), "cell {n}");
    }
    let e = &report["grids"].as_array().unwrap().iter().find(|g| g["name"] == "empty").unwrap();
    assert_eq!(e["active"], 0);
    assert_eq!(e["leaves"], 0);
}

const CUBE_MIN: Vec3 = Vec3::new(-1.0, 0.5, 2.0);
fn cube_max() -> Vec3 {
    CUBE_MIN + 0.125 * Vec3::new(37.0, 20.0, 17.0)
}

#[test]
fn openvdb_reads_float_uncompressed() {
    check_against_openvdb(
        "float_none",
        CUBE_MIN,
        cube_max(),
        VdbOptions { compression: VdbCompression::None, ..Default::default() },
    );
}

#[test]
fn openvdb_reads_float_zip() {
    check_against_openvdb("float_zip", CUBE_MIN, cube_max(), VdbOptions::default());
}

#[test]
fn openvdb_reads_half_zip_and_half_uncompressed() {
    check_against_openvdb("half_zip", CUBE_MIN, cube_max(), VdbOptions { half: true, ..Default::default() });
    check_against_openvdb(
        "half_none",
        CUBE_MIN,
        cube_max(),
        VdbOptions { half: true, compression: VdbCompression::None, ..Default::default() },
    );
}

#[test]
fn openvdb_reads_threshold_no_tiles_and_non_cubic_cells() {
    check_against_openvdb(
        "threshold",
        CUBE_MIN,
        cube_max(),
        VdbOptions { threshold: 0.05, tiles: false, ..Default::default() },
    );
    check_against_openvdb("non_cubic", Vec3::new(-3.0, 0.0, 1.0), Vec3::new(1.0, 2.5, 2.0), VdbOptions::default());
}

/// Every export frame (up axis × units × handedness, the presets among them) on cubic and
/// non-cubic cells: OpenVDB and our reader place every voxel at its cell centre in the frame,
/// read the frame from the metadata, and our import puts the values back on the project grid.
#[test]
fn openvdb_and_our_reader_read_every_export_frame() {
    let mut frames = Vec::new();
    for up in [UpAxis::Y, UpAxis::Z] {
        for units in [Units::M, Units::Cm] {
            for handedness in [Handedness::Right, Handedness::Left] {
                frames.push(Frame { up, units, handedness });
            }
        }
    }
    for p in [Preset::Blender, Preset::Houdini, Preset::Unreal, Preset::Godot, Preset::Unity] {
        assert!(frames.contains(&Frame::preset(p)));
    }
    for frame in frames {
        let tag = format!("{}{}{}", frame.up_name(), frame.meters_per_unit(), frame.handedness_name());
        check_against_openvdb(
            &format!("cubic_{tag}"),
            CUBE_MIN,
            cube_max(),
            VdbOptions { frame, ..Default::default() },
        );
        check_against_openvdb(
            &format!("non_cubic_{tag}"),
            Vec3::new(-3.0, 0.0, 1.0),
            Vec3::new(1.0, 2.5, 2.0),
            VdbOptions { frame, half: true, ..Default::default() },
        );
    }
}

#[test]
fn optical_depth_grids_are_not_fog_volumes() {
    let ev = test_volume(CUBE_MIN, cube_max());
    let opv = opv_of(&ev);
    let lights = [(&opv, light())];
    let grids =
        grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: true, transmittance: true });
    let classes: Vec<_> = grids.iter().map(|g| (g.name.as_str(), g.class)).collect();
    assert_eq!(
        classes,
        [
            ("density", GridClass::FogVolume),
            ("optical_depth_0", GridClass::Unknown),
            ("transmittance_0", GridClass::Unknown)
        ]
    );
}

// ---------------------------------------------------------------------------------------
// Import: files written by OpenVDB itself.

fn ints(v: &Value) -> Vec<i64> {
    v.as_array().unwrap().iter().map(|x| x.as_i64().unwrap()).collect()
}

#[test]
fn imports_files_written_by_openvdb() {
    require_openvdb();
    let dir = common::temp_dir();
    let out = Command::new(PY).arg(tests_dir().join("vdb_make.py")).arg(dir.path()).output().expect("run vdb_make.py");
    assert!(out.status.success(), "vdb_make.py failed: {}", String::from_utf8_lossy(&out.stderr));
    let report: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(
        report["vdb_tool"].as_bool().unwrap(),
        "vdb_tool is missing, so zip and uncompressed OpenVDB files cannot be tested: run ./setup.sh (it installs libopenvdb-tools)"
    );
    let mut checked = 0;
    for (file, grids) in report["files"].as_object().unwrap() {
        let path = dir.path().join(file);
        let listed = list_vdb_grids(&path).unwrap();
        assert_eq!(listed.len(), grids.as_array().unwrap().len(), "{file}");
        for g in grids.as_array().unwrap() {
            let name = g["name"].as_str().unwrap();
            let result = read_vdb_grid(&path, Some(name));
            if g["value_type"] != "float" {
                let err = result.expect_err("non-float grids are refused").to_string();
                assert!(err.contains("only float grids") && err.contains(file.as_str()), "{file} {name}: {err}");
                assert!(!listed.iter().find(|l| l.name == name).unwrap().importable);
                continue;
            }
            if file == "rotated.vdb" {
                let err = result.expect_err("rotated grids are refused").to_string();
                assert!(err.contains("not axis-aligned") && err.contains("rotated.vdb"), "{err}");
                continue;
            }
            if file == "frustum.vdb" {
                let err = result.expect_err("frustum grids are refused").to_string();
                assert!(err.contains("frustum") && err.contains("frustum.vdb"), "{err}");
                continue;
            }
            let ours = result.unwrap_or_else(|e| panic!("{file} {name}: {e}"));
            assert_eq!(ours.half, g["half"].as_bool().unwrap(), "{file}");
            assert_eq!(ours.background as f64, f(&g["background"]));
            assert_eq!(ours.active_voxel_count(), g["active"].as_u64().unwrap(), "{file} {name} active voxels");
            let (lo, hi) = ours.active_bbox().unwrap();
            let bbox = g["bbox"].as_array().unwrap();
            assert_eq!(lo.map(i64::from).to_vec(), ints(&bbox[0]), "{file} {name} bbox");
            assert_eq!(hi.map(i64::from).to_vec(), ints(&bbox[1]), "{file} {name} bbox");
            let vs: Vec<f64> = g["voxel_size"].as_array().unwrap().iter().map(f).collect();
            assert_eq!(ours.transform.scale.to_vec(), vs, "{file} {name} voxel size");
            let origin: Vec<f64> = g["origin"].as_array().unwrap().iter().map(f).collect();
            assert_eq!(ours.transform.index_to_world([0.0; 3]).to_vec(), origin, "{file} {name} translation");
            for s in g["samples"].as_array().unwrap() {
                let p = [s[0].as_i64().unwrap() as i32, s[1].as_i64().unwrap() as i32, s[2].as_i64().unwrap() as i32];
                assert_eq!(ours.value_at(p).to_bits() as u64, s[5].as_u64().unwrap(), "{file} {name} value at {p:?}");
                assert_eq!(ours.is_active(p), s[4].as_bool().unwrap(), "{file} {name} active at {p:?}");
            }

            // Resampled into a project grid whose cell centres are the voxel centres of the
            // active bbox (plus a margin): exactly OpenVDB's values.
            let h = ours.transform.scale;
            let t = ours.transform.translation;
            let margin = 2;
            let lo_w = [0, 1, 2].map(|a| (t[a] + (lo[a] - margin) as f64 * h[a] - 0.5 * h[a]) as f32);
            let res = [0, 1, 2].map(|a| (hi[a] - lo[a] + 1 + 2 * margin) as u32);
            if res.iter().map(|r| *r as u64).product::<u64>() <= 2_000_000 {
                let spec = GridSpec {
                    min: Vec3::from_array(lo_w),
                    max: Vec3::from_array([0, 1, 2].map(|a| lo_w[a] + (res[a] as f64 * h[a]) as f32)),
                    resolution: UVec3::from_array(res),
                };
                let dense = resample_into(&spec, &ours, 2.0);
                for s in g["samples"].as_array().unwrap() {
                    let p = [0, 1, 2].map(|a| s[a].as_i64().unwrap() - (lo[a] - margin) as i64);
                    if (0..3).all(|a| p[a] >= 0 && p[a] < res[a] as i64) {
                        let v = dense[spec.index(p[0] as u32, p[1] as u32, p[2] as u32)];
                        assert_eq!(
                            v.to_bits(),
                            (2.0 * f32::from_bits(s[5].as_u64().unwrap() as u32)).to_bits(),
                            "{file} {name} resampled at {p:?}"
                        );
                    }
                }
            }
            checked += 1;
        }
    }
    assert!(checked >= 6, "only {checked} grids checked");

    // Between voxel centres: a grid shifted by half a voxel on every axis samples the mean
    // of the 8 surrounding voxels as OpenVDB reads them (trilinear at the midpoint).
    let blob = &report["files"]["blob_blosc.vdb"][0];
    let grid = read_vdb_grid(&dir.path().join("blob_blosc.vdb"), Some("density")).unwrap();
    let value: std::collections::HashMap<[i64; 3], f32> = blob["samples"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| ([0, 1, 2].map(|a| s[a].as_i64().unwrap()), f32::from_bits(s[5].as_u64().unwrap() as u32)))
        .collect();
    let (lo, hi) = grid.active_bbox().unwrap();
    let (h, t) = (grid.transform.scale, grid.transform.translation);
    // Cell (i, j, k) of the shifted grid is centred at voxel lo + (i, j, k) + 0.5.
    let res = [0, 1, 2].map(|a| (hi[a] - lo[a]) as u32);
    let min = [0, 1, 2].map(|a| (t[a] + lo[a] as f64 * h[a]) as f32);
    let spec = GridSpec {
        min: Vec3::from_array(min),
        max: Vec3::from_array([0, 1, 2].map(|a| (t[a] + (lo[a] as f64 + res[a] as f64) * h[a]) as f32)),
        resolution: UVec3::from_array(res),
    };
    let dense = resample_into(&spec, &grid, 1.0);
    for k in 0..res[2] {
        for j in 0..res[1] {
            for i in 0..res[0] {
                let base = [lo[0] as i64 + i as i64, lo[1] as i64 + j as i64, lo[2] as i64 + k as i64];
                let mut mean = 0.0f64;
                for c in 0..8 {
                    let p = [base[0] + (c & 1), base[1] + ((c >> 1) & 1), base[2] + ((c >> 2) & 1)];
                    mean += 0.125 * value[&p] as f64;
                }
                let got = dense[spec.index(i, j, k)] as f64;
                assert!(
                    (got - mean).abs() <= 1e-5 * mean.abs().max(1e-3),
                    "trilinear at cell {:?}: {got} vs {mean}",
                    [i, j, k]
                );
            }
        }
    }
    // With no name, `density` is picked.
    let two = read_vdb_grid(&dir.path().join("two_grids.vdb"), None).unwrap();
    assert_eq!(two.name, "density");
    let err = read_vdb_grid(&dir.path().join("two_grids.vdb"), Some("smoke")).unwrap_err().to_string();
    assert!(err.contains("no grid named \"smoke\"") && err.contains("temperature"), "{err}");

    // Truncated copies of OpenVDB's blosc file: an error naming the file, never a panic.
    let bytes = std::fs::read(dir.path().join("blob_blosc.vdb")).unwrap();
    for cut in (0..bytes.len()).step_by(97) {
        let r = fogsmith::export::vdb_read::read_vdb_grid_from_bytes(Path::new("cut.vdb"), &bytes[..cut], None);
        let err = r.expect_err("a truncated file is refused").to_string();
        assert!(err.starts_with("cut.vdb"), "{err}");
    }
    // Flipped bytes in OpenVDB's blosc and half files: Ok or Err, never a panic.
    for file in ["blob_blosc.vdb", "blob_half.vdb"] {
        let bytes = std::fs::read(dir.path().join(file)).unwrap();
        let mut rng = common::Lcg(99);
        for _ in 0..1500 {
            let x = rng.next_u64();
            let mut bad = bytes.clone();
            let at = (x >> 33) as usize % bad.len();
            bad[at] ^= 1 << ((x >> 20) % 8);
            let _ = fogsmith::export::vdb_read::read_vdb_grid_from_bytes(Path::new(file), &bad, None);
        }
    }
}

// ---------------------------------------------------------------------------------------
// Damaged files: clear errors, no panics, no huge allocations.

fn our_file(opts: VdbOptions) -> Vec<u8> {
    let ev = test_volume(CUBE_MIN, cube_max());
    let grids = vec![VdbGrid::from_volume("density", &ev)];
    fogsmith::export::vdb::encode_vdb(Path::new("x.vdb"), &grids, &opts).unwrap().0
}

#[test]
fn damaged_files_give_errors_not_panics() {
    use fogsmith::export::vdb_read::read_vdb_grid_from_bytes as read;
    let p = Path::new("damaged.vdb");
    for opts in
        [VdbOptions::default(), VdbOptions { compression: VdbCompression::None, half: true, ..Default::default() }]
    {
        let good = our_file(opts);
        assert!(read(p, &good, None).is_ok());
        // Every truncation.
        for cut in 0..good.len() {
            if cut % 7 != 0 && cut > 400 {
                continue;
            }
            let err = read(p, &good[..cut], None).expect_err("truncated").to_string();
            assert!(err.starts_with("damaged.vdb: "), "{err}");
        }
        // Flipped bytes anywhere: Ok or Err, never a panic.
        let mut rng = common::Lcg(0x1234_5678);
        for _ in 0..3000 {
            let x = rng.next_u64();
            let mut bad = good.clone();
            let at = (x >> 33) as usize % bad.len();
            bad[at] ^= 1 << ((x >> 20) % 8);
            let _ = read(p, &bad, None);
            bad[at] = 0xFF;
            let _ = read(p, &bad, None);
        }
    }

    // Huge declared sizes are refused before anything is allocated.
    let good = our_file(VdbOptions::default());
    let meta_len = |name: &str, ty: &str, bytes: usize| 4 + name.len() + 4 + ty.len() + 4 + bytes;
    let file_meta = meta_len("creator", "string", "fogsmith".len())
        + meta_len("handedness", "string", "right".len())
        + meta_len("meters_per_unit", "double", 8)
        + meta_len("up_axis", "string", 1);
    let grid_count_at = 8 + 4 + 8 + 1 + 36 + 4 + file_meta;
    assert_eq!(&good[grid_count_at..grid_count_at + 4], &1u32.to_le_bytes());
    let mut bad = good.clone();
    bad[grid_count_at..grid_count_at + 4].copy_from_slice(&u32::MAX.to_le_bytes());
    let err = read(p, &bad, None).unwrap_err().to_string();
    assert!(err.contains("grid count") && err.contains("damaged.vdb"), "{err}");
    // The grid name's length.
    let mut bad = good.clone();
    bad[grid_count_at + 4..grid_count_at + 8].copy_from_slice(&0xFFFF_FFF0u32.to_le_bytes());
    let err = read(p, &bad, None).unwrap_err().to_string();
    assert!(err.contains("are left") && err.contains("a grid name"), "{err}");
    // A zip block claiming i64::MAX bytes: find the first zip block of a leaf (block pos).
    let name_len = 4 + "density".len() + 4 + "Tree_float_5_4_3".len() + 4;
    let offsets = grid_count_at + 4 + name_len;
    let block_pos = i64::from_le_bytes(good[offsets + 8..offsets + 16].try_into().unwrap()) as usize;
    let mut bad = good.clone();
    let size_at = block_pos + 64 + 1;
    bad[size_at..size_at + 8].copy_from_slice(&i64::MAX.to_le_bytes());
    let err = read(p, &bad, None).unwrap_err().to_string();
    assert!(err.contains("compressed block") && err.contains(&format!("at byte {size_at}")), "{err}");
    // Offsets past the end.
    let mut bad = good.clone();
    bad[offsets..offsets + 8].copy_from_slice(&(1i64 << 50).to_le_bytes());
    let err = read(p, &bad, None).unwrap_err().to_string();
    assert!(err.contains("do not fit"), "{err}");
    // Not a VDB at all.
    let err = read(p, b"hello world, not a vdb", None).unwrap_err().to_string();
    assert!(err.contains("not an OpenVDB file"), "{err}");
}

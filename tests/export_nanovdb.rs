//! NanoVDB export checked by NanoVDB's own tools (Debian's libnanovdb-tools, NanoVDB 32.4.2):
//! `nanovdb_validate` finds every grid valid, `nanovdb_print` reports the voxel count, bbox
//! and transform of our `.vdb` of the same grids, `nanovdb_convert` turns the file back into
//! a VDB whose every voxel OpenVDB (python3-openvdb) reads as in our `.vdb`, and NanoVDB's
//! own conversion of our `.vdb` gives the same grid buffers, byte for byte but for rounding
//! in the statistics and the inverse map. Then `fogsmith export --nvdb`, still and sequence.

mod common;
use common::root;

use fogsmith::export::frame::{Frame, Preset};
use fogsmith::export::nanovdb::{write_nanovdb, GRID_DATA_SIZE, NANOVDB_MAGIC};
use fogsmith::export::vdb::{
    grids_from_volumes, index_to_world_matrix, write_vdb, GridSelection, VdbCompression, VdbGrid, VdbOptions,
};
use fogsmith::export::LightInfo;
use fogsmith::scene::{GridSpec, Volume, Volume3};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const PY: &str = "/usr/bin/python3";

/// The checks need NanoVDB's tools and OpenVDB: a machine without them fails loudly.
fn require_tools() {
    for tool in ["nanovdb_validate", "nanovdb_print", "nanovdb_convert"] {
        let ok = Command::new(tool).arg("--version").output().map(|o| o.status.success()).unwrap_or(false);
        assert!(ok, "{tool} is missing: run ./setup.sh (it installs libnanovdb-tools) to check NanoVDB files");
    }
    let ok = Command::new(PY).args(["-c", "import pyopenvdb"]).output().map(|o| o.status.success()).unwrap_or(false);
    assert!(ok, "/usr/bin/python3 cannot import pyopenvdb: run ./setup.sh (it installs python3-openvdb)");
}

fn run_tool(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e}"));
    let text = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{cmd:?} failed: {text}");
    text
}

/// A blob of fog with exact zeros around it, a constant 8³ block (a tile) and leaves cut by
/// the grid's edge, over `res` cells.
fn test_volume(min: Vec3, max: Vec3, res: UVec3) -> Volume {
    let grid = GridSpec { min, max, resolution: res };
    let mut data = vec![0.0f32; grid.cell_count() as usize];
    for k in 0..res.z {
        for j in 0..res.y {
            for i in 0..res.x {
                let d2 = (i as f32 - 8.3).powi(2) + (j as f32 - 6.1).powi(2) + (k as f32 - 9.7).powi(2);
                let mut v = 2.0 * (-d2 / 16.0).exp();
                if v < 0.01 {
                    v = 0.0;
                }
                if (16..24).contains(&i) && (8..16).contains(&j) && k < 8 {
                    v = 0.5;
                }
                if i == res.x - 1 && j == res.y - 1 && k == res.z - 1 {
                    v = 3.25; // the far corner, in a leaf cut by all three edges
                }
                data[grid.index(i, j, k)] = v;
            }
        }
    }
    Volume::new(grid, data)
}

fn opv_of(ev: &Volume) -> Volume {
    let data = ev
        .data
        .iter()
        .enumerate()
        .map(|(n, v)| if n % 7 == 0 { 0.0 } else { v * 0.37 + (n % 11) as f32 * 0.01 })
        .collect();
    Volume::new(ev.grid, data)
}

fn emission_of(ev: &Volume) -> Volume3 {
    let data =
        ev.data.iter().enumerate().map(|(n, &v)| [v * 0.8, v * 0.1 + (n % 5) as f32 * 0.02 * v, v * 0.3]).collect();
    Volume3 { grid: ev.grid, data }
}

fn vdb_check(path: &Path, grid: &GridSpec) -> Value {
    let r = grid.resolution;
    let out = run_tool(Command::new(PY).arg(root().join("tests/vdb_check.py")).arg(path).args([
        r.x.to_string(),
        r.y.to_string(),
        r.z.to_string(),
    ]));
    serde_json::from_str(out.lines().last().unwrap_or("")).expect("vdb_check.py prints JSON")
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

fn f64s(v: &Value) -> Vec<f64> {
    fn walk(v: &Value, out: &mut Vec<f64>) {
        match v {
            Value::Array(a) => a.iter().for_each(|x| walk(x, out)),
            Value::Number(n) => out.push(n.as_f64().unwrap()),
            _ => {}
        }
    }
    let mut out = Vec::new();
    walk(v, &mut out);
    out
}

/// The numbers in a text such as "(0.1,2,3) -> (4,5,6)".
fn numbers(text: &str) -> Vec<f64> {
    text.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e' || c == '+'))
        .filter(|s| !s.is_empty() && s != &"-" && s != &">" && s != &"->")
        .filter_map(|s| s.trim_end_matches('-').parse().ok())
        .collect()
}

/// What OpenVDB reads from `vdb` (our export) equals what it reads from the VDB that
/// nanovdb_convert makes of `nvdb`, voxel for voxel; and nanovdb_validate and nanovdb_print
/// agree.
fn check_nvdb_against_vdb(tag: &str, nvdb: &Path, vdb: &Path, spec: &GridSpec, frame: &Frame, dir: &Path) {
    // Valid, every grid.
    let ours = vdb_check(vdb, spec);
    let grids = ours["grids"].as_array().unwrap();
    let text = run_tool(Command::new("nanovdb_validate").arg("-v").arg(nvdb));
    assert!(!text.contains("failed"), "{tag}: {text}");
    for g in grids {
        let name = g["name"].as_str().unwrap();
        assert!(text.contains(&format!("Grid named \"{name}\": passed")), "{tag}: {name} not validated: {text}");
    }

    // nanovdb_print: voxel count, resolution, index bbox, voxel size and world bbox.
    let text = run_tool(Command::new("nanovdb_print").arg("-l").arg(nvdb));
    let rows: Vec<Vec<&str>> = text
        .lines()
        .map(|l| l.split("  ").map(str::trim).filter(|c| !c.is_empty()).collect::<Vec<_>>())
        .filter(|cols| cols.len() >= 14 && cols[0].parse::<usize>().is_ok())
        .collect();
    assert_eq!(rows.len(), grids.len(), "{tag}: {text}");
    let by_name = |list: &[Value], name: &str| -> Value {
        list.iter().find(|g| g["name"] == name).cloned().unwrap_or_else(|| panic!("{tag}: no grid {name}"))
    };
    for row in &rows {
        let name = row[1];
        let g = &by_name(grids, name);
        let vec3 = g["value_type"] == "vec3s";
        assert_eq!(row[2], if vec3 { "Vec3f" } else { "float" }, "{tag} {name}: {text}");
        let class = if g["meta"]["class"] == "fog volume" { "FOG" } else { "?" };
        assert_eq!(row[3], class, "{tag} {name}: {text}");
        assert_eq!(row[4], "32.4.2", "{tag} {name}: {text}");
        assert_eq!(row[5], "NONE", "{tag} {name}: {text}");
        let scale = numbers(row[8]);
        let want_scale = f64s(&g["voxel_size"]);
        assert!(
            scale.iter().zip(&want_scale).all(|(a, b)| close(*a, *b, 6e-3)),
            "{tag} {name}: {scale:?} vs {want_scale:?}"
        );
        assert_eq!(row[9], g["active"].to_string(), "{tag} {name}: voxel count: {text}");
        let bbox = f64s(&g["bbox"]);
        let active = g["active"].as_u64().unwrap();
        if active == 0 {
            assert_eq!((row[10], row[13], row[14]), ("0 x 0 x 0", "empty grid", "empty grid"), "{tag} {name}: {text}");
            continue;
        }
        let res: Vec<f64> = (0..3).map(|a| bbox[3 + a] - bbox[a] + 1.0).collect();
        assert_eq!(numbers(row[10]), res, "{tag} {name}: resolution: {text}");
        assert_eq!(numbers(row[13]), bbox, "{tag} {name}: index bbox: {text}");
        // World bbox: the index bbox's corners [min, max + 1] through the export's map,
        // printed to 3 significant digits.
        let m = index_to_world_matrix(spec, frame);
        let (mut lo, mut hi) = ([f64::MAX; 3], [f64::MIN; 3]);
        for corner in 0..8 {
            let p: Vec<f64> = (0..3).map(|a| if corner >> a & 1 == 1 { bbox[3 + a] + 1.0 } else { bbox[a] }).collect();
            for w in 0..3 {
                let x = m[3][w] + (0..3).map(|a| p[a] * m[a][w]).sum::<f64>();
                lo[w] = lo[w].min(x);
                hi[w] = hi[w].max(x);
            }
        }
        let want: Vec<f64> = lo.iter().chain(&hi).copied().collect();
        let world = numbers(row[14]);
        let extent = want.iter().fold(0.0f64, |e, v| e.max(v.abs()));
        assert!(
            world.len() == 6
                && world.iter().zip(&want).all(|(a, b)| (a - b).abs() <= 6e-3 * b.abs().max(extent * 1e-2)),
            "{tag} {name}: world bbox {world:?}, want {want:?}: {text}"
        );
    }

    // Back to OpenVDB: every voxel, active state and the transform.
    let back = dir.join(format!("{tag}.back.vdb"));
    run_tool(Command::new("nanovdb_convert").arg("-f").arg(nvdb).arg(&back));
    let theirs = vdb_check(&back, spec);
    let back_grids = theirs["grids"].as_array().unwrap();
    assert_eq!(back_grids.len(), grids.len(), "{tag}");
    for g in grids {
        let name = g["name"].as_str().unwrap();
        let b = &by_name(back_grids, name);
        for key in ["value_type", "background", "active", "leaves", "bbox"] {
            assert_eq!(b[key], g[key], "{tag} {name}: {key}");
        }
        assert_eq!(b["meta"]["class"], g["meta"]["class"], "{tag} {name}: class");
        // The transform: index → world of the three voxels vdb_check.py samples. NanoVDB's
        // NanoToOpenVDB before 32.8 (OpenVDB 12.1) discards the transpose of the 3×3 it reads
        // (`mat.transpose();` without assigning it), so with a rotated export frame the VDB it
        // writes maps index i to t + i·Aᵀ instead of t + i·A. The NanoVDB file's own map was
        // checked above (NanoVDB's conversion of our VDB, and its world bbox).
        let m = index_to_world_matrix(spec, frame);
        for (ours, back) in g["world"].as_array().unwrap().iter().zip(b["world"].as_array().unwrap()) {
            let (i, w, wb) = (f64s(&ours[0]), f64s(&ours[1]), f64s(&back[1]));
            assert_eq!(f64s(&back[0]), i, "{tag} {name}");
            for k in 0..3 {
                let want = m[3][k] + (0..3).map(|a| i[a] * m[a][k]).sum::<f64>();
                let tool = m[3][k] + (0..3).map(|a| i[a] * m[k][a]).sum::<f64>();
                assert!(close(w[k], want, 1e-9), "{tag} {name}: our VDB maps {i:?} to {w:?}");
                assert!(close(wb[k], tool, 1e-9), "{tag} {name}: back from NanoVDB {i:?} maps to {wb:?}, want {tool}");
            }
        }
        let size: Vec<f64> = (0..3).map(|a| (0..3).map(|k| m[k][a] * m[k][a]).sum::<f64>().sqrt()).collect();
        let vb = f64s(&b["voxel_size"]);
        assert!(vb.iter().zip(&size).all(|(x, y)| close(*x, *y, 1e-9)), "{tag} {name}: voxel size {vb:?} vs {size:?}");
        assert!(b["values"] == g["values"], "{tag} {name}: voxel values differ");
        assert!(b["active_mask"] == g["active_mask"], "{tag} {name}: active voxels differ");
    }
}

/// Grid buffers of a NanoVDB file by name: walks its segments (header, metadata records,
/// grids).
fn grid_buffers(path: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let u16_at = |at: usize| u16::from_le_bytes([bytes[at], bytes[at + 1]]) as usize;
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    let mut at = 0;
    let mut out = Vec::new();
    while at < bytes.len() {
        assert_eq!(u64_at(at), NANOVDB_MAGIC, "{} at {at}", path.display());
        let count = u16_at(at + 12);
        at += 16;
        let mut metas = Vec::new();
        for _ in 0..count {
            let (size, name_size) = (u64_at(at) as usize, u32_at(at + 136));
            let name = String::from_utf8(bytes[at + 176..at + 176 + name_size - 1].to_vec()).unwrap();
            metas.push((name, size));
            at += 176 + name_size;
        }
        for (name, size) in metas {
            out.push((name, bytes[at..at + size].to_vec()));
            at += size;
        }
    }
    out
}

/// Our grid buffers equal those NanoVDB's converter makes of our `.vdb`, but for the
/// checksum (which covers the root's statistics) and these fields, which may differ in their
/// last bits: NanoVDB sums statistics in parallel and inverts the map with OpenVDB's 4×4
/// inverse.
fn compare_with_nanovdb_conversion(tag: &str, ours: &Path, vdb: &Path, dir: &Path) {
    let reference = dir.join(format!("{tag}.ref.nvdb"));
    run_tool(Command::new("nanovdb_convert").arg("-f").arg(vdb).arg(&reference));
    let a = grid_buffers(ours);
    let b = grid_buffers(&reference);
    assert_eq!(a.len(), b.len(), "{tag}");
    for (name, x) in &a {
        let y = &b.iter().find(|(n, _)| n == name).unwrap_or_else(|| panic!("{tag}: NanoVDB made no {name}")).1;
        assert_eq!(x.len(), y.len(), "{tag} {name}: grid size");
        let vec3 = u32::from_le_bytes(x[636..640].try_into().unwrap()) == 6;
        let nc = if vec3 { 3 } else { 1 };
        // (start, end, f64?) ranges of floating-point fields allowed to differ slightly.
        let mut loose: Vec<(usize, usize, bool)> =
            vec![(296 + 36, 296 + 72, false), (296 + 160, 296 + 232, true), (560, 632, true)];
        let u64_at = |at: usize| u64::from_le_bytes(x[at..at + 8].try_into().unwrap()) as usize;
        let u32_at = |at: usize| u32::from_le_bytes(x[at..at + 4].try_into().unwrap()) as usize;
        let tree = GRID_DATA_SIZE;
        let root = tree + u64_at(tree + 24);
        loose.push((root + 28 + 4 * nc, root + 36 + 12 * nc, false)); // min, max, avg, std
        let counts = [u32_at(tree + 32), u32_at(tree + 36), u32_at(tree + 40)];
        let sizes = if vec3 { [6272, 66624, 532544] } else { [2144, 33856, 270400] };
        let stats_at = [80, 32 + 2 * 512, 32 + 2 * 4096];
        for level in 0..3 {
            let first = tree + u64_at(tree + 8 * level);
            for n in 0..counts[level] {
                let s = first + n * sizes[level] + stats_at[level];
                loose.push((s, s + 8 * nc + 8, false));
            }
        }
        let mut worst = 0.0f64;
        let mut w = 16;
        while w < x.len() {
            if let Some(&(start, _, wide)) = loose.iter().find(|r| (r.0..r.1).contains(&w)) {
                let size = if wide { 8 } else { 4 };
                let (p, q) = if wide {
                    (
                        f64::from_le_bytes(x[w..w + 8].try_into().unwrap()),
                        f64::from_le_bytes(y[w..w + 8].try_into().unwrap()),
                    )
                } else {
                    (
                        f32::from_le_bytes(x[w..w + 4].try_into().unwrap()) as f64,
                        f32::from_le_bytes(y[w..w + 4].try_into().unwrap()) as f64,
                    )
                };
                let _ = start;
                let rel = (p - q).abs() / p.abs().max(q.abs()).max(1e-30);
                assert!(rel < 1e-5 || (p - q).abs() < 1e-9, "{tag} {name}: byte {w}: {p} vs NanoVDB's {q}");
                worst = worst.max(if p == q { 0.0 } else { rel });
                w += size;
            } else {
                assert_eq!(x[w], y[w], "{tag} {name}: byte {w} of {} differs from NanoVDB's conversion", x.len());
                w += 1;
            }
        }
        eprintln!("{tag} {name}: equal to NanoVDB's conversion (worst relative difference {worst:e})");
    }
}

fn light() -> LightInfo {
    LightInfo { id: 7, position: [1.5, 3.0, -0.25], intensity: 40.0, color: [1.0, 0.9, 0.8] }
}

fn check_writer(tag: &str, min: Vec3, max: Vec3, res: UVec3, opts: VdbOptions) {
    require_tools();
    let ev = test_volume(min, max, res);
    let opv = opv_of(&ev);
    let emission = emission_of(&ev);
    let lights = [(&opv, light().in_frame(&opts.frame))];
    let mut grids =
        grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: true, transmittance: true });
    grids.push(VdbGrid::from_volume3("emission", &emission));
    let dir = common::temp_dir();
    let vdb = dir.path().join(format!("{tag}.vdb"));
    let nvdb = dir.path().join(format!("{tag}.nvdb"));
    write_vdb(&vdb, &grids, &VdbOptions { compression: VdbCompression::None, ..opts }).unwrap();
    let stats = write_nanovdb(&nvdb, &grids, &opts).unwrap();
    assert_eq!(stats.bytes, std::fs::metadata(&nvdb).unwrap().len());
    compare_with_nanovdb_conversion(tag, &nvdb, &vdb, dir.path());
    check_nvdb_against_vdb(tag, &nvdb, &vdb, &ev.grid, &opts.frame, dir.path());
}

#[test]
fn nanovdb_tools_read_every_grid_as_our_vdb() {
    check_writer(
        "native",
        Vec3::new(-1.0, 0.0, -0.5),
        Vec3::new(1.0, 1.0, 0.5),
        UVec3::new(37, 20, 17),
        VdbOptions::default(),
    );
}

#[test]
fn nanovdb_tools_read_every_export_frame_threshold_and_non_cubic_cells() {
    for preset in [Preset::Blender, Preset::Unreal, Preset::Unity] {
        let opts = VdbOptions { frame: Frame::preset(preset), ..VdbOptions::default() };
        check_writer(
            &format!("{preset:?}"),
            Vec3::new(-2.0, 0.5, 1.0),
            Vec3::new(1.7, 2.5, 2.7),
            UVec3::new(37, 20, 17),
            opts,
        );
    }
    let opts = VdbOptions { threshold: 0.05, tiles: false, ..VdbOptions::default() };
    check_writer("non-cubic", Vec3::ZERO, Vec3::new(1.0, 2.0, 0.5), UVec3::new(37, 20, 17), opts);
}

#[test]
fn nanovdb_tools_read_several_root_nodes_and_an_empty_grid() {
    require_tools();
    // 4200 cells along x: two 4096³ root children.
    let spec = GridSpec { min: Vec3::ZERO, max: Vec3::new(42.0, 0.03, 0.02), resolution: UVec3::new(4200, 3, 2) };
    let data = (0..spec.cell_count()).map(|n| if n % 13 == 0 { 1.0 + n as f32 * 1e-3 } else { 0.0 }).collect();
    let v = Volume::new(spec, data);
    let empty = Volume::new(spec, vec![0.0; spec.cell_count() as usize]);
    let grids = [VdbGrid::from_volume("density", &v), VdbGrid::from_volume("nothing", &empty)];
    let dir = common::temp_dir();
    let vdb = dir.path().join("roots.vdb");
    let nvdb = dir.path().join("roots.nvdb");
    write_vdb(&vdb, &grids, &VdbOptions { compression: VdbCompression::None, ..VdbOptions::default() }).unwrap();
    write_nanovdb(&nvdb, &grids, &VdbOptions::default()).unwrap();
    check_nvdb_against_vdb("roots", &nvdb, &vdb, &spec, &Frame::NATIVE, dir.path());
    compare_with_nanovdb_conversion("roots", &nvdb, &vdb, dir.path());
}

#[test]
fn bad_grids_and_paths_are_refused_naming_the_file() {
    let spec = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(4) };
    let v = Volume::new(spec, vec![1.0; 64]);
    let dir = common::temp_dir();
    let long = VdbGrid::from_volume("x".repeat(300), &v);
    let err = write_nanovdb(&dir.path().join("a.nvdb"), &[long], &VdbOptions::default()).unwrap_err().to_string();
    assert!(err.contains("a.nvdb") && err.contains("255"), "{err}");
    let err = write_nanovdb(
        &dir.path().join("missing/b.nvdb"),
        &[VdbGrid::from_volume("density", &v)],
        &VdbOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("b.nvdb") && err.contains("cannot write"), "{err}");
    assert!(!dir.path().join("a.nvdb").exists());
}

// ---------------------------------------------------------------------------------------
// `fogsmith export --nvdb`

fn fogsmith() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fogsmith"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn json_of(out: &std::process::Output) -> Value {
    assert!(out.status.success(), "failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

fn save(dir: &Path, project: &fogsmith::scene::Project) -> PathBuf {
    let path = dir.join("fog.ron");
    fogsmith::scene::io::save_project(&path, project).unwrap();
    path
}

#[test]
fn export_writes_nanovdb_beside_vdb_with_the_light_bake_and_folders() {
    require_tools();
    let dir = common::temp_dir();
    let project = common::small_scene(24, &[Vec3::new(1.6, 1.2, 0.5)]);
    let path = save(dir.path(), &project);
    let vdb = dir.path().join("out/fog.vdb");
    let nvdb = dir.path().join("new/deeper/fog.nvdb");
    let args = [
        "export",
        s(&path),
        "--vdb",
        s(&vdb),
        "--nvdb",
        s(&nvdb),
        "--bake-light",
        "--preset",
        "blender",
        "--compression",
        "none",
        "--json",
    ];
    let v = json_of(&fogsmith().args(args).output().unwrap());
    assert_eq!(v["nvdb"]["path"], s(&nvdb), "{v}");
    let names: Vec<&str> = v["nvdb"]["grids"].as_array().unwrap().iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["density", "optical_depth_0", "emission"], "{v}");
    for (n, g) in v["nvdb"]["grids"].as_array().unwrap().iter().zip(v["vdb"]["grids"].as_array().unwrap()) {
        for key in ["name", "active_voxels", "leaves", "tiles"] {
            assert_eq!(n[key], g[key], "{key}: {v}");
        }
    }
    check_nvdb_against_vdb("cli", &nvdb, &vdb, &project.grid, &Frame::preset(Preset::Blender), dir.path());
}

#[test]
fn export_sequence_writes_one_nanovdb_per_frame() {
    require_tools();
    let dir = common::temp_dir();
    let mut project = common::small_scene(16, &[Vec3::new(1.6, 1.2, 0.5)]);
    project.animation = Some(fogsmith::scene::animation::Animation { fps: 24.0, start: 1, end: 3 });
    let path = save(dir.path(), &project);
    let pattern = dir.path().join("seq/fog.####.nvdb");
    let vdbs = dir.path().join("seq/fog.####.vdb");
    let out = fogsmith()
        .args([
            "export",
            s(&path),
            "--frames",
            "2-3",
            "--nvdb",
            s(&pattern),
            "--vdb",
            s(&vdbs),
            "--compression",
            "none",
            "--json",
        ])
        .output()
        .unwrap();
    let v = json_of(&out);
    for f in 2..=3 {
        let nvdb = dir.path().join(format!("seq/fog.{f:04}.nvdb"));
        let vdb = dir.path().join(format!("seq/fog.{f:04}.vdb"));
        assert!(nvdb.exists(), "{}: {v}", nvdb.display());
        check_nvdb_against_vdb(&format!("frame{f}"), &nvdb, &vdb, &project.grid, &Frame::NATIVE, dir.path());
    }
    // Without a frame number every frame would overwrite one file.
    let out = fogsmith()
        .args(["export", s(&path), "--frames", "2-3", "--nvdb", s(&dir.path().join("one.nvdb"))])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("--nvdb") && !err.contains("panicked"), "{err}");
}

#[test]
fn export_to_an_unwritable_place_names_the_file_in_one_line() {
    let dir = common::temp_dir();
    let project = common::small_scene(8, &[Vec3::new(1.6, 1.2, 0.5)]);
    let path = save(dir.path(), &project);
    // A folder that cannot be made: its parent is a file.
    let blocker = dir.path().join("not-a-folder");
    std::fs::write(&blocker, b"x").unwrap();
    let target = blocker.join("fog.nvdb");
    let out = fogsmith().args(["export", s(&path), "--nvdb", s(&target)]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    let last = err.trim().lines().last().unwrap_or("");
    assert!(last.contains("fog.nvdb") && last.contains("cannot create its folder"), "{err}");
}

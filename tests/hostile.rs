//! Hostile inputs: mutated project text and mutated VDB files never panic and end in a clear
//! error naming the file (and, for projects, the line and column); accepted projects are
//! valid and survive a save/load round trip; bad paths fail cleanly.
//!
//! The mutation runs use fixed seeds and case counts so CI is reproducible and quick. For a
//! longer run: `FOGSMITH_FUZZ_CASES=300000 FOGSMITH_FUZZ_SEED=7 cargo test --release --test hostile`.

mod common;

use fogsmith::export::vdb::{encode_vdb, VdbCompression, VdbGrid, VdbOptions};
use fogsmith::export::vdb_read::{import_density, read_vdb_grid_from_bytes, resample_into, MAX_LEAVES};
use fogsmith::scene::io::to_ron_string;
use fogsmith::scene::{parse_project, GridSpec, ProjectError, Volume, MAX_RESOLUTION_DEFAULT};
use glam::{UVec3, Vec3};
use proptest::prelude::*;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

fn corpus(ext: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let mut out: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, bytes)
        })
        .collect();
    out.sort();
    assert!(out.len() >= 2, "tests/corpus holds at least two .{ext} seeds");
    out
}

fn cases(default: u32) -> u32 {
    std::env::var("FOGSMITH_FUZZ_CASES").ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

/// Fixed seed unless `FOGSMITH_FUZZ_SEED` picks another (for longer runs).
fn runner(cases: u32) -> TestRunner {
    let config = Config { cases, failure_persistence: None, ..Config::default() };
    let rng = match std::env::var("FOGSMITH_FUZZ_SEED").ok().and_then(|v| v.parse::<u64>().ok()) {
        Some(seed) => {
            let mut bytes = [0u8; 32];
            bytes[..8].copy_from_slice(&seed.to_le_bytes());
            TestRng::from_seed(RngAlgorithm::ChaCha, &bytes)
        }
        None => TestRng::deterministic_rng(RngAlgorithm::ChaCha),
    };
    TestRunner::new_with_rng(config, rng)
}

/// Edits that keep most of a document's structure so the parser goes deep.
#[derive(Clone, Debug)]
enum Edit {
    Delete(usize, usize),
    Insert(usize, &'static str),
    ReplaceNumber(usize, &'static str),
    Duplicate(usize, usize),
    Truncate(usize),
}

const TOKENS: &[&str] = &[
    "(",
    ")",
    "[",
    "]",
    "{",
    "}",
    ",",
    ":",
    "\"",
    "//",
    "/*",
    "*/",
    "-",
    ".",
    "e",
    "\n",
    "é",
    "\u{0}",
    "\\",
    "Some(",
    "None",
    "true",
    "r#\"",
    "'",
    "#![enable(implicit_some)]",
    "particles: [",
    "lights: []",
    "resolution: (4096, 4096, 4096)",
    "resolution: (0, 1, 1)",
    "version: 3",
    "version: 2",
    "scheme: warp",
    "base_volume: (path: \"/nonexistent.vdb\")",
];
const NUMBERS: &[&str] = &[
    "NaN",
    "inf",
    "-inf",
    "1e39",
    "-1e39",
    "3.4e38",
    "1e-45",
    "-0.0",
    "0",
    "-1",
    "4294967296",
    "4294967295",
    "18446744073709551616",
    "99999999999999999999999",
    "1e308",
    "0x10",
    "1_000",
    ".5",
    "5.",
    "+1",
];

fn edit() -> impl Strategy<Value = Edit> {
    prop_oneof![
        (any::<usize>(), 1usize..40).prop_map(|(a, n)| Edit::Delete(a, n)),
        (any::<usize>(), prop::sample::select(TOKENS)).prop_map(|(a, t)| Edit::Insert(a, t)),
        (any::<usize>(), prop::sample::select(NUMBERS)).prop_map(|(a, t)| Edit::ReplaceNumber(a, t)),
        (any::<usize>(), 1usize..200).prop_map(|(a, n)| Edit::Duplicate(a, n)),
        any::<usize>().prop_map(Edit::Truncate),
    ]
}

fn apply(text: &str, edits: &[Edit]) -> String {
    let mut chars: Vec<char> = text.chars().collect();
    for e in edits {
        let len = chars.len().max(1);
        match *e {
            Edit::Delete(a, n) => {
                let a = a % len;
                let b = (a + n).min(chars.len());
                if a < b {
                    chars.drain(a..b);
                }
            }
            Edit::Insert(a, t) => {
                let a = a % (chars.len() + 1);
                chars.splice(a..a, t.chars());
            }
            Edit::ReplaceNumber(a, t) => {
                let starts: Vec<usize> = (0..chars.len())
                    .filter(|&i| {
                        chars[i].is_ascii_digit()
                            && (i == 0 || !chars[i - 1].is_ascii_alphanumeric() && chars[i - 1] != '.')
                    })
                    .collect();
                if let Some(&s) = starts.get(a % starts.len().max(1)) {
                    let mut end = s;
                    while end < chars.len()
                        && (chars[end].is_ascii_alphanumeric() || chars[end] == '.' || chars[end] == '-')
                    {
                        end += 1;
                    }
                    chars.splice(s..end, t.chars());
                }
            }
            Edit::Duplicate(a, n) => {
                let a = a % len;
                let b = (a + n).min(chars.len());
                let piece: Vec<char> = chars[a.min(chars.len())..b].to_vec();
                chars.splice(b..b, piece);
            }
            Edit::Truncate(a) => chars.truncate(a % len),
        }
    }
    chars.into_iter().collect()
}

/// The property every project text must satisfy; Err describes the violation.
fn check_project_text(text: &str) -> Result<(), String> {
    let origin = Path::new("fuzz.ron");
    let result = catch_unwind(AssertUnwindSafe(|| parse_project(text, origin)))
        .map_err(|_| format!("parse_project panicked on:\n{text}"))?;
    match result {
        Ok(p) => {
            p.validate(MAX_RESOLUTION_DEFAULT).map_err(|e| format!("accepted an invalid project ({e}):\n{text}"))?;
            let saved = to_ron_string(&p).map_err(|e| format!("could not serialise an accepted project: {e}"))?;
            let back =
                parse_project(&saved, origin).map_err(|e| format!("saved text does not load ({e}):\n{saved}"))?;
            if back != p {
                return Err(format!("save/load changed the project:\n{text}"));
            }
            Ok(())
        }
        Err(e @ (ProjectError::Syntax { line, col, .. } | ProjectError::Invalid { line, col, .. })) => {
            let msg = e.to_string();
            if line == 0 || col == 0 || !msg.starts_with(&format!("fuzz.ron:{line}:{col}: ")) {
                return Err(format!("error without a usable position: {msg}"));
            }
            Ok(())
        }
        Err(e) => Err(format!("unexpected error kind: {e}")),
    }
}

#[test]
fn mutated_project_text_never_panics_and_errors_have_positions() {
    let seeds: Vec<String> = corpus("ron")
        .into_iter()
        .map(|(p, b)| String::from_utf8(b).unwrap_or_else(|_| panic!("{} is UTF-8", p.display())))
        .collect();
    for s in &seeds {
        check_project_text(s).unwrap();
    }
    let strategy = (0..seeds.len(), prop::collection::vec(edit(), 1..6));
    let accepted = std::cell::Cell::new(0u32);
    let n = cases(3000);
    runner(n)
        .run(&strategy, |(seed, edits)| {
            let text = apply(&seeds[seed], &edits);
            accepted.set(accepted.get() + parse_project(&text, Path::new("x.ron")).is_ok() as u32);
            check_project_text(&text).map_err(TestCaseError::fail)
        })
        .unwrap();
    println!("{n} mutated projects, {} accepted", accepted.get());
    assert!(accepted.get() > 0 && accepted.get() < n, "the mutations reach both outcomes");
}

/// Mutations of a binary file: truncation, bit flips, extreme integers, foreign tree types.
#[derive(Clone, Debug)]
enum ByteEdit {
    Truncate(usize),
    Flip(usize, u8),
    Int32(usize, u32),
    Int64(usize, u64),
    Splice(usize, usize, usize),
    TreeType(&'static str),
}

fn byte_edit() -> impl Strategy<Value = ByteEdit> {
    let ints32 = prop::sample::select(vec![0u32, 1, 7, 0x7FFF_FFFF, 0x8000_0000, u32::MAX, 1 << 20, 4097]);
    let ints64 = prop::sample::select(vec![0u64, u64::MAX, i64::MAX as u64, 1 << 40, 1 << 31, u32::MAX as u64 + 1]);
    prop_oneof![
        any::<usize>().prop_map(ByteEdit::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| ByteEdit::Flip(a, b)),
        (any::<usize>(), ints32).prop_map(|(a, v)| ByteEdit::Int32(a, v)),
        (any::<usize>(), ints64).prop_map(|(a, v)| ByteEdit::Int64(a, v)),
        (any::<usize>(), any::<usize>(), 1usize..64).prop_map(|(a, b, n)| ByteEdit::Splice(a, b, n)),
        prop::sample::select(vec!["Tree_int32_5_4_3", "Tree_vec3s_5_4_3", "Tree_float_4_4_3", "Tree_bool_5_4_3_"])
            .prop_map(ByteEdit::TreeType),
    ]
}

fn apply_bytes(bytes: &[u8], edits: &[ByteEdit]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    for e in edits {
        let len = b.len().max(1);
        match *e {
            ByteEdit::Truncate(a) => b.truncate(a % len),
            ByteEdit::Flip(a, x) => {
                if let Some(v) = b.get_mut(a % len) {
                    *v ^= x.max(1);
                }
            }
            ByteEdit::Int32(a, v) => {
                let a = a % len;
                if a + 4 <= b.len() {
                    b[a..a + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
            ByteEdit::Int64(a, v) => {
                let a = a % len;
                if a + 8 <= b.len() {
                    b[a..a + 8].copy_from_slice(&v.to_le_bytes());
                }
            }
            ByteEdit::Splice(a, from, n) => {
                let (a, from) = (a % len, from % len);
                let piece: Vec<u8> = b[from.min(b.len())..(from + n).min(b.len())].to_vec();
                let end = (a + piece.len()).min(b.len());
                b.splice(a..end, piece);
            }
            ByteEdit::TreeType(t) => {
                let needle = b"Tree_float_5_4_3";
                if let Some(at) = b.windows(needle.len()).position(|w| w == needle) {
                    b[at..at + needle.len()].copy_from_slice(t.as_bytes());
                }
            }
        }
    }
    b
}

fn check_vdb_bytes(bytes: &[u8]) -> Result<(), String> {
    let path = Path::new("fuzz.vdb");
    let target = GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(6) };
    let outcome = catch_unwind(AssertUnwindSafe(|| {
        read_vdb_grid_from_bytes(path, bytes, None).map(|g| {
            let leaves = g.leaf_count();
            let values = resample_into(&target, &g, 1.0);
            (leaves, values.len(), g.active_bbox())
        })
    }))
    .map_err(|_| format!("the VDB reader panicked on {} bytes", bytes.len()))?;
    match outcome {
        Ok((leaves, n, _)) if leaves <= MAX_LEAVES && n == 216 => Ok(()),
        Ok((leaves, n, _)) => Err(format!("accepted a grid of {leaves} leaves, resampled to {n} values")),
        Err(e) => {
            let msg = e.to_string();
            if msg.starts_with("fuzz.vdb: ") && msg.len() > 20 {
                Ok(())
            } else {
                Err(format!("error does not name the file: {msg}"))
            }
        }
    }
}

#[test]
fn mutated_vdb_files_never_panic_and_errors_name_the_file() {
    let seeds: Vec<Vec<u8>> = corpus("vdb").into_iter().map(|(_, b)| b).collect();
    for s in &seeds {
        check_vdb_bytes(s).unwrap();
        read_vdb_grid_from_bytes(Path::new("seed.vdb"), s, None).expect("corpus seeds are readable");
    }
    let strategy = (0..seeds.len(), prop::collection::vec(byte_edit(), 1..5));
    let accepted = std::cell::Cell::new(0u32);
    let n = cases(1500);
    runner(n)
        .run(&strategy, |(seed, edits)| {
            let bytes = apply_bytes(&seeds[seed], &edits);
            accepted.set(accepted.get() + read_vdb_grid_from_bytes(Path::new("x.vdb"), &bytes, None).is_ok() as u32);
            check_vdb_bytes(&bytes).map_err(TestCaseError::fail)
        })
        .unwrap();
    println!("{n} mutated VDB files, {} read", accepted.get());
    assert!(accepted.get() > 0 && accepted.get() < n, "the mutations reach both outcomes");
}

/// A small grid with a dense blob, written by our writer: the corpus seeds.
fn seed_volume() -> Volume {
    let grid =
        GridSpec { min: Vec3::new(-1.0, 0.0, -1.0), max: Vec3::new(1.0, 1.0, 1.0), resolution: UVec3::new(9, 8, 8) };
    let mut data = Vec::new();
    for k in 0..8 {
        for j in 0..8 {
            for i in 0..9 {
                let x = grid.cell_center(i, j, k);
                data.push(if i >= 8 {
                    0.5
                } else {
                    3.0 * (-(x - Vec3::new(0.2, 0.5, 0.0)).length_squared() * 4.0).exp()
                });
            }
        }
    }
    Volume::new(grid, data)
}

/// `cargo test --test hostile -- --ignored write_corpus` rewrites the VDB seeds.
#[test]
#[ignore = "rewrites the committed VDB seeds under tests/corpus; run by hand after a writer change"]
fn write_corpus() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus");
    let v = seed_volume();
    for (name, opts) in [
        ("float_zip.vdb", VdbOptions::default()),
        ("half_none.vdb", VdbOptions { compression: VdbCompression::None, half: true, ..Default::default() }),
        (
            "float_none_notiles.vdb",
            VdbOptions { compression: VdbCompression::None, tiles: false, threshold: 0.01, ..Default::default() },
        ),
    ] {
        let (bytes, _) = encode_vdb(Path::new(name), &[VdbGrid::from_volume("density", &v)], &opts).unwrap();
        std::fs::write(dir.join(name), bytes).unwrap();
    }
}

/// A density grid with negative or non-finite values (a level set, a damaged file) would put
/// negative extinction or NaN into every frame: the import refuses it, naming file and grid.
#[test]
fn importing_negative_or_non_finite_density_is_refused() {
    let dir = common::temp_dir();
    let target = GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(4) };
    for bad in [-0.25f32, f32::INFINITY] {
        let mut v = seed_volume();
        v.data[100] = bad;
        let path = dir.path().join("bad.vdb");
        fogsmith::export::vdb::write_vdb(
            &path,
            &[VdbGrid::from_volume("density", &v)],
            &VdbOptions { tiles: false, ..Default::default() },
        )
        .unwrap();
        let target = GridSpec { resolution: UVec3::new(9, 8, 8), min: v.grid.min, max: v.grid.max };
        let err = import_density(&path, None, &target, 1.0).unwrap_err().to_string();
        assert!(
            err.contains("bad.vdb") && err.contains("\"density\"") && err.contains("negative or not finite"),
            "{err}"
        );
    }
    // A finite grid whose scaled values overflow f32.
    let path = dir.path().join("scaled.vdb");
    fogsmith::export::vdb::write_vdb(&path, &[VdbGrid::from_volume("density", &seed_volume())], &VdbOptions::default())
        .unwrap();
    let err = import_density(&path, None, &target, 3e38).unwrap_err().to_string();
    assert!(err.contains("not finite"), "{err}");
    assert!(import_density(&path, None, &target, 2.0).is_ok());
}

/// Loading, saving and exporting to paths that do not exist or cannot be written name the
/// path; nothing panics.
#[test]
fn bad_paths_give_clear_errors() {
    use fogsmith::scene::{load_project, save_project, Project};
    let err = load_project(Path::new("/nonexistent/dir/fog.ron")).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/dir/fog.ron") && err.contains("No such file"), "{err}");
    let dir = common::temp_dir();
    let err = load_project(dir.path()).unwrap_err().to_string();
    assert!(err.contains(&dir.path().display().to_string()), "a directory is not a project: {err}");
    let binary = dir.path().join("binary.ron");
    std::fs::write(&binary, [0xFFu8, 0xFE, 0x00, 0x41]).unwrap();
    let err = load_project(&binary).unwrap_err().to_string();
    assert!(err.contains("binary.ron"), "{err}");

    let p = Project::default();
    let err = save_project(Path::new("/nonexistent/dir/fog.ron"), &p).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/dir/fog.ron"), "{err}");
    let err = save_project(dir.path(), &p).unwrap_err().to_string();
    assert!(err.contains(&dir.path().display().to_string()), "saving over a directory: {err}");

    let v = seed_volume();
    let grids = [VdbGrid::from_volume("density", &v)];
    let err = fogsmith::export::vdb::write_vdb(Path::new("/nonexistent/dir/out.vdb"), &grids, &VdbOptions::default())
        .unwrap_err()
        .to_string();
    assert!(err.contains("/nonexistent/dir/out.vdb") && err.contains("cannot write"), "{err}");
    let err =
        fogsmith::export::vdb_read::read_vdb_grid(Path::new("/nonexistent/in.vdb"), None).unwrap_err().to_string();
    assert!(err.contains("/nonexistent/in.vdb") && err.contains("cannot read"), "{err}");
    let ron = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/minimal.ron");
    let err = fogsmith::export::vdb_read::read_vdb_grid(&ron, None).unwrap_err().to_string();
    assert!(err.contains("minimal.ron") && err.contains("not an OpenVDB file"), "{err}");
}

/// Declared sizes far beyond anything bakeable are refused by validation, not allocated.
#[test]
fn huge_declared_sizes_are_refused() {
    for (text, field) in [
        (
            "Project(grid: (min: (0,0,0), max: (1,1,1), resolution: (4294967295, 4294967295, 4294967295)))",
            "grid.resolution.x",
        ),
        ("Project(render: (width: 4294967295))", "render.width"),
        ("Project(render: (near_steps: 4000000000))", "render.near_steps"),
    ] {
        let err = parse_project(text, Path::new("huge.ron")).unwrap_err().to_string();
        assert!(err.starts_with("huge.ron:1:") && err.contains(field), "{err}");
    }
}

/// A base volume on a grid too large to hold densely is refused before the dense copy is
/// allocated (it used to abort the process with an allocation failure).
#[test]
fn base_volume_on_a_huge_grid_is_refused() {
    let dir = common::temp_dir();
    let path = dir.path().join("base.vdb");
    fogsmith::export::vdb::write_vdb(&path, &[VdbGrid::from_volume("density", &seed_volume())], &VdbOptions::default())
        .unwrap();
    let huge = GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(4096) };
    let err = import_density(&path, None, &huge, 1.0).unwrap_err().to_string();
    assert!(
        err.contains("base.vdb") && err.contains("4096×4096×4096") && err.contains("lower grid.resolution"),
        "{err}"
    );
}

/// Saving a project of a version this build does not write is an error, not a debug panic.
#[test]
fn saving_a_foreign_version_is_an_error() {
    let dir = common::temp_dir();
    let p = fogsmith::scene::Project { version: 7, ..Default::default() };
    let err = fogsmith::scene::save_project(&dir.path().join("v.ron"), &p).unwrap_err().to_string();
    assert!(err.contains("version 7"), "{err}");
}

/// The CLI checks the adapter's limits before it resamples and uploads a base volume, so a
/// grid past them is refused at once with the limit named and a suggestion.
#[test]
fn cli_refuses_an_oversized_grid_before_loading_its_base_volume() {
    let dir = common::temp_dir();
    std::fs::write(
        dir.path().join("base.vdb"),
        std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus/float_zip.vdb")).unwrap(),
    )
    .unwrap();
    let project = dir.path().join("big.ron");
    std::fs::write(
        &project,
        "Project(grid: (min: (-1, -1, -1), max: (1, 1, 1), resolution: (4096, 4096, 128)), base_volume: Some((path: \"base.vdb\")))",
    )
    .unwrap();
    let started = std::time::Instant::now();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_fogsmith"))
        .args(["render", &project.display().to_string(), "-o", &dir.path().join("x.png").display().to_string()])
        .env("XDG_RUNTIME_DIR", std::env::var_os("XDG_RUNTIME_DIR").unwrap_or_else(|| std::env::temp_dir().into()))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && !stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains("allows at most") && stderr.contains("lower grid.resolution"), "{stderr}");
    assert!(started.elapsed().as_secs() < 60, "refused before any dense work");
}

/// Half floats stop at 65504: a VDB or EXR written as half refuses larger values instead of
/// storing infinity (the optical depth of dense fog is often larger).
#[test]
fn half_float_overflow_is_refused() {
    let dir = common::temp_dir();
    let mut v = seed_volume();
    v.data[3] = 1e5;
    let path = dir.path().join("dense.vdb");
    let half = VdbOptions { half: true, ..Default::default() };
    let err = fogsmith::export::vdb::write_vdb(&path, &[VdbGrid::from_volume("optical_depth", &v)], &half)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("dense.vdb")
            && err.contains("\"optical_depth\"")
            && err.contains("65504")
            && err.contains("full floats"),
        "{err}"
    );
    assert!(!path.exists());
    fogsmith::export::vdb::write_vdb(&path, &[VdbGrid::from_volume("optical_depth", &v)], &VdbOptions::default())
        .unwrap();

    let exr = dir.path().join("bright.exr");
    let mut rgba = vec![[0.5f32, 0.5, 0.5, 1.0]; 16];
    rgba[5][0] = 7e4;
    let err = fogsmith::export::exr::write_render_exr(&exr, 4, 4, &rgba, true).unwrap_err().to_string();
    assert!(err.contains("bright.exr") && err.contains("65504"), "{err}");
    fogsmith::export::exr::write_render_exr(&exr, 4, 4, &rgba, false).unwrap();
}

/// Deep nesting and very long input end in a positioned error, not a stack overflow.
#[test]
fn deeply_nested_and_long_text_is_an_error() {
    for text in [
        format!("Project(particles: {}", "[".repeat(100_000)),
        format!("Project(grid: {}", "(".repeat(100_000)),
        format!("Project(camera: (fov_y_deg: {}))", "9".repeat(100_000)),
        format!("Project(particles: [{}])", "(center: (0, 0, 0), radius: 1, density: 1),".repeat(20_000))
            + "(radius: -1)",
    ] {
        check_project_text(&text).unwrap();
        assert!(parse_project(&text, Path::new("deep.ron")).is_err());
    }
}

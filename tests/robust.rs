//! Damaged files and missing folders that once aborted, misread or were refused: a render EXR
//! whose data window claims gigabytes, a VDB whose topology runs into its buffers, a light
//! bake that the farm check called damaged, a frame range of billions, and an export into a
//! folder that does not exist.
//! Each damaged input is kept, minimised, under `tests/corpus/damaged/`.

use fogsmith::export::sequence::FrameSet;
use fogsmith::export::vdb::{encode_vdb, VdbCompression, VdbGrid, VdbOptions};
use fogsmith::export::vdb_read::read_vdb_grid_from_bytes;
use fogsmith::farm::check::{file_state, FileState};
use fogsmith::farm::FarmJob;
use fogsmith::scene::{GridSpec, Volume, Volume3};
use glam::{UVec3, Vec3};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn corpus(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus").join(name)
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn fogsmith(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fogsmith")).args(args).output().expect("fogsmith runs")
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// `export` of the small corpus project at 8×4 pixels, with `args` added.
fn export(args: &[&str]) -> Output {
    let project = corpus("minimal.ron");
    let mut all = vec!["export", s(&project), "--width", "8", "--height", "4", "--quiet"];
    all.extend_from_slice(args);
    fogsmith(&all)
}

/// `tests/corpus/damaged/render-window-min-x.exr`: a render EXR of `minimal.ron` whose
/// `dataWindow.min.x` (offset 337) is 268435456 instead of 0, so its window claims 2²⁸ pixels
/// a row (`render-window-max-x.exr`: `max.x` 7 → 29999999, 1.9 GB of pixels). The export runs
/// with its address space limited to 4 GB, so that an allocation of the claimed size fails
/// (and aborts) whatever the machine's overcommit.
#[test]
fn a_render_exr_with_a_huge_data_window_is_damaged_and_resume_rebakes_it() {
    let dir = tempfile::tempdir().unwrap();
    let project = corpus("minimal.ron");
    for name in ["render-window-min-x.exr", "render-window-max-x.exr"] {
        let exr = dir.path().join(name);
        std::fs::copy(corpus("damaged").join(name), &exr).unwrap();
        let script = format!(
            "ulimit -v 4194304; exec '{}' export '{}' --width 8 --height 4 --quiet --exr-render '{}' --resume",
            env!("CARGO_BIN_EXE_fogsmith"),
            s(&project),
            s(&exr)
        );
        let out = Command::new("sh").args(["-c", &script]).output().unwrap();
        assert!(out.status.success(), "{name}: export --resume over a damaged EXR: {:?}\n{}", out.status, text(&out));
        assert_eq!(file_state(&exr), FileState::Done, "{name}: the frame was baked again");
    }
}

#[test]
fn the_farm_check_reports_damaged_exr_headers_without_allocating_them() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in [
        ("min_x.exr", read(&corpus("damaged/render-window-min-x.exr"))),
        ("max_x.exr", read(&corpus("damaged/render-window-max-x.exr"))),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        match file_state(&path) {
            FileState::Damaged(why) => assert!(why.contains("data window"), "{name}: {why}"),
            other => panic!("{name}: {other:?}"),
        }
    }
    let whole = dir.path().join("whole.exr");
    std::fs::copy(corpus("render.exr"), &whole).unwrap();
    assert_eq!(file_state(&whole), FileState::Done);
}

/// `tests/corpus/damaged/openvdb-root-tile-count.vdb`: an uncompressed float grid written by
/// OpenVDB (vdb_tool `codec=none`) whose root tile count (offset 566) is 1 instead of 0, so
/// its root child is read as a tile and the rest of its tree one tile late.
#[test]
fn a_vdb_whose_topology_runs_into_its_buffers_is_refused() {
    let damaged = read(&corpus("damaged/openvdb-root-tile-count.vdb"));
    let mut whole = damaged.clone();
    assert_eq!(whole[566..570], [1, 0, 0, 0], "the damaged root tile count");
    whole[566] = 0;
    let grid = read_vdb_grid_from_bytes(Path::new("whole.vdb"), &whole, None).expect("the undamaged file reads");
    assert_eq!(grid.active_voxel_count(), 120);
    let err = read_vdb_grid_from_bytes(Path::new("bad.vdb"), &damaged, None).expect_err("a damaged tree").to_string();
    assert!(err.contains("bad.vdb") && err.contains("topology") && !err.contains('\n'), "{err}");
}

fn light_bake_grids() -> (Volume, Volume3) {
    let grid = GridSpec { min: Vec3::splat(-1.0), max: Vec3::ONE, resolution: UVec3::new(12, 9, 10) };
    let n = grid.cell_count() as usize;
    let density = Volume::new(grid, (0..n).map(|i| (i % 7) as f32 * 0.25).collect());
    let emission = Volume3::new(grid, (0..n).map(|i| [(i % 5) as f32, 0.5, (i % 3) as f32 * 0.125]).collect());
    (density, emission)
}

#[test]
fn the_farm_check_reads_a_light_bake_in_every_codec_and_precision() {
    let dir = tempfile::tempdir().unwrap();
    let (density, emission) = light_bake_grids();
    let grids = [VdbGrid::from_volume("density", &density), VdbGrid::from_volume3("emission", &emission)];
    for compression in [VdbCompression::None, VdbCompression::Zip] {
        for half in [false, true] {
            let path = dir.path().join(format!("bake-{compression:?}-{half}.vdb"));
            let opts = VdbOptions { compression, half, ..VdbOptions::default() };
            let (bytes, _) = encode_vdb(&path, &grids, &opts).unwrap();
            std::fs::write(&path, &bytes).unwrap();
            assert_eq!(file_state(&path), FileState::Done, "{}", path.display());
            std::fs::write(&path, &bytes[..bytes.len() - 9]).unwrap();
            assert!(matches!(file_state(&path), FileState::Damaged(_)), "{} truncated", path.display());
        }
    }
}

#[test]
fn resuming_a_light_bake_skips_its_complete_frame() {
    let dir = tempfile::tempdir().unwrap();
    let vdb = dir.path().join("bake.vdb");
    let first = export(&["--bake-light", "--vdb", s(&vdb)]);
    assert!(first.status.success(), "{}", text(&first));
    let again = export(&["--bake-light", "--vdb", s(&vdb), "--resume"]);
    assert!(again.status.success(), "{}", text(&again));
    assert!(text(&again).contains("complete, skipped"), "{}", text(&again));
}

#[test]
fn an_export_creates_the_folders_it_writes_into() {
    let dir = tempfile::tempdir().unwrap();
    let vdb = dir.path().join("out/fog/fog.vdb");
    let exr = dir.path().join("renders/r.exr");
    let out = export(&["--vdb", s(&vdb), "--exr-render", s(&exr)]);
    assert!(out.status.success(), "{}", text(&out));
    assert_eq!(file_state(&vdb), FileState::Done);
    assert_eq!(file_state(&exr), FileState::Done);
}

/// `tests/corpus/damaged/farm-frames.json`: a bundle's `farm.json` whose frames read
/// `1-2147483647`; `farm status` listed every frame before it looked at one.
#[test]
fn a_frame_range_of_billions_is_refused_before_it_is_listed() {
    let job: FarmJob = serde_json::from_slice(&read(&corpus("damaged/farm-frames.json"))).unwrap();
    let err = job.frame_set().unwrap_err();
    assert!(err.contains("1-2147483647") && err.contains("1000000"), "{err}");
    assert_eq!(FrameSet::parse("1-1000000").unwrap().len(), 1_000_000);
    assert!(FrameSet::parse("-2147483648-2147483647x1000").is_err());
}

/// `tests/corpus/damaged/vdb-no-grids.vdb`: `half_none.vdb` with 27 bytes of its file
/// metadata deleted (found by the fuzzer), so its header reads as a file without grids,
/// which the farm check took for a complete output.
#[test]
fn a_vdb_whose_header_lost_its_grids_is_damaged() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fog.vdb");
    std::fs::copy(corpus("damaged/vdb-no-grids.vdb"), &path).unwrap();
    match file_state(&path) {
        FileState::Damaged(why) => assert!(why.contains("no grids"), "{why}"),
        other => panic!("{other:?}"),
    }
}

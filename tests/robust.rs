//! Damaged files and missing folders that once aborted, misread or were refused: a render EXR
//! whose data window claims gigabytes, a VDB whose topology runs into its buffers, a light
//! bake that the farm check called damaged, a frame range of billions, and an export into a
//! folder that does not exist.
//! Each damaged input is kept, minimised, under `tests/corpus/damaged/`.

use fogsmith::farm::check::{file_state, FileState};
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

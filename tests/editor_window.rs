//! Starts the real `fogsmith` binary in a window under Xvfb (through scripts/screenshot.sh),
//! waits for its first preview frame and checks the screenshot it saves: the window opened,
//! the wgpu surface presented, and the preview shows lit fog. Needs xvfb-run (./setup.sh
//! installs it) and a wgpu adapter; without them the test fails.

mod common;

use std::process::Command;

#[test]
fn the_editor_window_opens_and_draws_the_preview() {
    let dir = common::temp_dir();
    let out = dir.path().join("editor.png");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/screenshot.sh");
    let status = Command::new("bash")
        .arg(script)
        .arg(&out)
        .env("FOGSMITH_BIN", env!("CARGO_BIN_EXE_fogsmith"))
        .status()
        .expect("bash runs scripts/screenshot.sh");
    assert!(status.success(), "scripts/screenshot.sh failed: {status}");
    let img = image::open(&out).expect("the screenshot is a PNG").to_rgba8();
    assert!(img.width() >= 1000 && img.height() >= 600, "window size {}×{}", img.width(), img.height());
    let mut colours = std::collections::HashSet::new();
    let mut bright = 0usize;
    for p in img.pixels() {
        colours.insert([p[0] / 8, p[1] / 8, p[2] / 8]);
        if p[0] as u32 + p[1] as u32 + p[2] as u32 > 200 {
            bright += 1;
        }
    }
    assert!(colours.len() > 200, "the window shows more than a flat UI ({} colours)", colours.len());
    assert!(bright > 1000, "lit fog and text are visible ({bright} bright pixels)");
    if std::env::var_os("FOGSMITH_UPDATE_SCREENSHOT").is_some() {
        let docs = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/editor.png");
        std::fs::copy(&out, docs).expect("copy to docs/editor.png");
    }
}

#[test]
fn without_a_display_the_editor_explains_and_fails() {
    let out = Command::new(env!("CARGO_BIN_EXE_fogsmith"))
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("the binary runs");
    assert!(!out.status.success(), "no window can open without a display");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no display") && stderr.contains("fogsmith render"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// Nothing lost: the real editor, with unsaved work, is killed with SIGKILL (with its X
/// server); the recovery file it left holds exactly that work, which is what the next start
/// offers to restore (tests/editor.rs checks the offer and the restore in-process).
#[test]
fn a_killed_editor_leaves_its_unsaved_work_in_a_recovery_file() {
    use std::os::unix::process::CommandExt;
    let dir = common::temp_dir();
    let state = dir.path().join("state");
    let project_path = dir.path().join("room.ron");
    let project = fogsmith::demos::demo("cornell").expect("the demo parses");
    fogsmith::scene::save_project(&project_path, &project).expect("save the project");

    let mut child = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1200x800x24"])
        .arg(env!("CARGO_BIN_EXE_fogsmith"))
        .arg(&project_path)
        .args(["--scripted-stroke", "7"])
        .env("FOGSMITH_STATE_DIR", &state)
        .env("FOGSMITH_AUTOSAVE_SECS", "0.5")
        .env("XDG_CONFIG_HOME", dir.path())
        .env("XDG_DATA_HOME", dir.path())
        .process_group(0)
        .spawn()
        .expect("xvfb-run starts (./setup.sh installs it)");
    let started = std::time::Instant::now();
    let recovery = loop {
        let found = fogsmith::scene::recovery::find_recoveries(&state);
        if let Some(Ok((_, rec))) = found.into_iter().next() {
            break Some(rec);
        }
        if started.elapsed().as_secs() > 240 || child.try_wait().ok().flatten().is_some() {
            break None;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    };
    // SIGKILL the whole group: xvfb-run, Xvfb and the editor die without any cleanup.
    let _ = Command::new("kill").args(["-KILL", "--", &format!("-{}", child.id())]).status();
    let _ = child.wait();

    let recovery = recovery.expect("the editor wrote a recovery file for its unsaved work");
    assert_eq!(recovery.original.as_deref(), Some(project_path.as_path()));
    assert_eq!(recovery.project.particles.len(), project.particles.len() + 7, "the stroke is in the recovery file");
    assert_eq!(
        recovery.project.particles[..project.particles.len()],
        project.particles[..],
        "the earlier work is intact"
    );
    let after = fogsmith::scene::recovery::find_recoveries(&state);
    assert_eq!(after.len(), 1, "the killed editor could not remove its recovery file");
}

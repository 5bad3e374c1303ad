//! Starts the real `fogsmith` binary in a window under Xvfb (through scripts/screenshot.sh),
//! waits for its first preview frame and checks the screenshot it saves: the window opened,
//! the wgpu surface presented, and the preview shows lit fog. Needs xvfb-run (./setup.sh
//! installs it) and a wgpu adapter; without them the test fails.

use std::process::Command;

#[test]
fn the_editor_window_opens_and_draws_the_preview() {
    let dir = tempfile::tempdir().expect("temp dir");
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

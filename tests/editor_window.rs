//! Starts the real `fogsmith` binary in a window under Xvfb (through scripts/screenshot.sh),
//! waits for its first preview frame and checks the screenshot it saves: the window opened,
//! the wgpu surface presented, and the preview shows lit fog where an unlit scene's preview
//! is black. Needs xvfb-run (./setup.sh
//! installs it) and a wgpu adapter; without them the test fails.

mod common;

use std::process::Command;

/// A screenshot of the real editor window on `project`, saved to `out`.
fn screenshot(project: &std::path::Path, out: &std::path::Path) -> image::RgbaImage {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/scripts/screenshot.sh");
    let status = Command::new("bash")
        .arg(script)
        .arg(out)
        .arg(project)
        .env("FOGSMITH_BIN", env!("CARGO_BIN_EXE_fogsmith"))
        .status()
        .expect("bash runs scripts/screenshot.sh");
    assert!(status.success(), "scripts/screenshot.sh failed: {status}");
    image::open(out).expect("the screenshot is a PNG").to_rgba8()
}

/// The longest run of indices below `n` that `pass`, bridging gaps of up to 4 that fail (the
/// overlay's lines drawn over the preview), as start..end.
fn longest_run(n: u32, pass: impl Fn(u32) -> bool) -> Option<(u32, u32)> {
    const GAP: u32 = 4;
    let (mut best, mut start, mut last) = (None::<(u32, u32)>, None::<u32>, 0u32);
    for i in 0..=n {
        let ok = i < n && pass(i);
        if ok {
            start.get_or_insert(i);
            last = i;
        } else if let Some(s) = start {
            if i == n || i - last > GAP {
                if best.is_none_or(|(a, b)| last + 1 - s > b - a) {
                    best = Some((s, last + 1));
                }
                start = None;
            }
        }
    }
    best
}

fn black(p: &image::Rgba<u8>) -> bool {
    p[0].max(p[1]).max(p[2]) <= 4
}

/// The preview's rectangle (x0..x1, y0..y1): the largest black area of a window whose preview
/// shows an unlit scene (the rest of the window is the UI's grey panels and text).
fn black_rectangle(img: &image::RgbaImage) -> (u32, u32, u32, u32) {
    let (w, h) = img.dimensions();
    let row_black = |y: u32| (0..w).filter(|&x| black(img.get_pixel(x, y))).count();
    let (y0, y1) = longest_run(h, |y| row_black(y) * 5 >= w as usize).expect("a black preview in the unlit window");
    let (x0, x1) =
        longest_run(w, |x| (y0..y1).filter(|&y| black(img.get_pixel(x, y))).count() * 2 >= (y1 - y0) as usize)
            .expect("a black preview in the unlit window");
    (x0, x1, y0, y1)
}

/// The share of the rectangle's pixels that are lit: clearly brighter than black.
fn lit_share(img: &image::RgbaImage, (x0, x1, y0, y1): (u32, u32, u32, u32)) -> f64 {
    let lit = (y0..y1)
        .flat_map(|y| (x0..x1).map(move |x| (x, y)))
        .filter(|&(x, y)| {
            let p = img.get_pixel(x, y);
            p[0].max(p[1]).max(p[2]) > 24
        })
        .count();
    lit as f64 / ((x1 - x0) as f64 * (y1 - y0) as f64)
}

/// The real window opens and its wgpu surface presents the preview: the demo with its lights
/// removed shows a black preview, which locates the preview in the window; the demo itself
/// shows lit fog and walls over much of that same rectangle.
#[test]
fn the_editor_window_opens_and_draws_the_preview() {
    let dir = common::temp_dir();
    let demo = fogsmith::demos::demo("cornell").expect("the demo parses");
    let mut unlit = demo.clone();
    unlit.lights.clear();
    let (lit_path, unlit_path) = (dir.path().join("cornell.ron"), dir.path().join("unlit.ron"));
    fogsmith::scene::save_project(&lit_path, &demo).expect("save the demo");
    fogsmith::scene::save_project(&unlit_path, &unlit).expect("save the unlit demo");
    let out = dir.path().join("editor.png");
    let img = screenshot(&lit_path, &out);
    let dark = screenshot(&unlit_path, &dir.path().join("unlit.png"));
    assert!(img.width() >= 1000 && img.height() >= 600, "window size {}×{}", img.width(), img.height());
    assert_eq!(img.dimensions(), dark.dimensions());
    let rect = black_rectangle(&dark);
    let (x0, x1, y0, y1) = rect;
    let area = ((x1 - x0) * (y1 - y0)) as f64 / (img.width() * img.height()) as f64;
    let (lit, unlit) = (lit_share(&img, rect), lit_share(&dark, rect));
    println!(
        "preview {x0}..{x1} × {y0}..{y1} ({:.0} % of the window): lit {:.1} %, unlit {:.1} %",
        area * 100.0,
        lit * 100.0,
        unlit * 100.0
    );
    assert!(area > 0.1, "the preview covers {:.1} % of the window", area * 100.0);
    // Unlit, only the overlay's outlines are bright (measured 2.9 %); lit, the fog and walls
    // (measured 39 %).
    assert!(unlit < 0.08, "without lights the preview is black ({:.1} % lit)", unlit * 100.0);
    assert!(
        lit > 0.2 && lit > 4.0 * unlit,
        "the lit demo's preview shows lit fog ({:.1} % of the preview lit)",
        lit * 100.0
    );
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

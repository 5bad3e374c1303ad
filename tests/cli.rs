//! The `fogsmith` binary end to end: render, verify, export, and its errors.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn fogsmith() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fogsmith"))
}

fn demo(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("projects").join(name)
}

fn json_of(out: &std::process::Output) -> serde_json::Value {
    assert!(out.status.success(), "failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("stdout is not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

/// `--sweep-refine false|true` and `--sweep-tolerance` override the project's settings
/// (default on, 5e-4) for that run, the JSON says which settings the bake used, and a
/// tolerance out of range is refused with the flag and its range named.
#[test]
fn sweep_refine_flag_reaches_the_bake() {
    let dir = common::temp_dir();
    let png = dir.path().join("street.png");
    let (project, png) = (demo("street.ron").display().to_string(), png.display().to_string());
    let run = |extra: &[&str]| {
        let mut args = vec!["render", &project, "-o", &png, "--width", "32", "--height", "18", "--json"];
        args.extend_from_slice(extra);
        json_of(&fogsmith().args(&args).output().unwrap())
    };
    let default = run(&[]);
    let plain = run(&["--sweep-refine", "false"]);
    let refined = run(&["--sweep-refine", "true", "--sweep-tolerance", "2e-4"]);
    assert_eq!(default["sweep_refine"], true, "{default}");
    assert!((default["sweep_tolerance"].as_f64().unwrap() - 5e-4).abs() < 1e-9, "{default}");
    assert_eq!(plain["sweep_refine"], false, "{plain}");
    assert_eq!(refined["sweep_refine"], true, "{refined}");
    assert!((refined["sweep_tolerance"].as_f64().unwrap() - 2e-4).abs() < 1e-9, "{refined}");
    assert_eq!(refined["scheme"], "sweep");
    let bad = fogsmith().args(["render", &project, "-o", &png, "--sweep-tolerance", "0"]).output().unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(!bad.status.success() && err.contains("--sweep-tolerance must be within 1e-6..=0.1"), "{err}");
}

#[test]
fn render_every_demo_prints_json_and_writes_the_image() {
    let dir = common::temp_dir();
    for (stem, _) in fogsmith::demos::DEMOS {
        let name = &format!("{stem}.ron");
        let png = dir.path().join(format!("{stem}.png"));
        let out = fogsmith()
            .args([
                "render",
                demo(name).to_str().unwrap(),
                "-o",
                png.to_str().unwrap(),
                "--width",
                "64",
                "--height",
                "36",
                "--json",
            ])
            .output()
            .unwrap();
        let v = json_of(&out);
        for key in ["width", "height", "lights", "grid", "timings_ms", "adapter"] {
            assert!(v.get(key).is_some(), "{name}: JSON lacks {key}: {v}");
        }
        for stage in ["inject", "propagate", "march"] {
            assert!(v["timings_ms"][stage].as_f64().is_some_and(|t| t >= 0.0), "{name}: {v}");
        }
        assert_eq!(v["width"], 64);
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (64, 36));
        assert!(img.pixels().any(|p| p.0.iter().any(|&c| c > 20)), "{name}: the image is black");
    }
}

#[test]
fn verify_reports_errors_against_the_reference() {
    let out = fogsmith()
        .args(["verify", demo("cornell.ron").to_str().unwrap(), "--width", "32", "--cells", "5000", "--json"])
        .output()
        .unwrap();
    let v = json_of(&out);
    assert!(v["ev_max_rel_error"].as_f64().unwrap() < 1e-3, "{v}");
    let opv = v["opv"].as_array().unwrap();
    assert_eq!(opv.len(), 2);
    for o in opv {
        assert!(o["scheme"]["transmittance_max_abs_error"].as_f64().unwrap() < 2e-3, "{v}");
        assert!(o["resolution"]["transmittance_max_abs_error"].as_f64().unwrap() < 0.02, "{v}");
        assert!(o["total"]["transmittance_max_abs_error"].as_f64().unwrap() < 0.02, "{v}");
        assert!(o["scheme"]["transmittance_mean_abs_error"].as_f64().is_some());
    }
    assert!(v["image_rel_rmse"].as_f64().unwrap() < 0.05, "{v}");
}

#[test]
fn export_writes_vdb_and_exr_files() {
    let dir = common::temp_dir();
    let vdb = dir.path().join("fog.vdb");
    let atlas = dir.path().join("atlas.exr");
    let out = fogsmith()
        .args(["export", demo("cloud.ron").to_str().unwrap(), "--width", "32", "--height", "18"])
        .args(["--vdb", vdb.to_str().unwrap(), "--exr-atlas", atlas.to_str().unwrap(), "--json"])
        .output()
        .unwrap();
    let v = json_of(&out);
    let names: Vec<&str> = v["vdb"]["grids"].as_array().unwrap().iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["density", "optical_depth_0", "optical_depth_1"]);
    let grid = fogsmith::export::vdb_read::read_vdb_grid(&vdb, Some("density")).unwrap();
    assert!(grid.active_voxel_count() > 0);
    let r = fogsmith::scene::load_project(&demo("cloud.ron")).unwrap().grid.resolution;
    let layout = format!("{} slices of {}×{}", r.z, r.x, r.y);
    assert!(v["exr_atlas"]["layout"].as_str().unwrap().contains(&layout), "{v} lacks {layout:?}");
    assert!(atlas.exists());
}

#[test]
fn errors_are_clear_and_exit_nonzero() {
    let dir = common::temp_dir();
    let bad = dir.path().join("bad.ron");
    std::fs::write(&bad, "Project(particles: [(center: (0.0, 0.0, 0.0), radius: -1.0, density: 1.0)])").unwrap();
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec!["render".into(), "/nonexistent/x.ron".into(), "-o".into(), "x.png".into()], "/nonexistent/x.ron"),
        (vec!["render".into(), bad.display().to_string(), "-o".into(), "x.png".into()], "particles[0].radius"),
        (
            vec![
                "render".into(),
                demo("cornell.ron").display().to_string(),
                "-o".into(),
                dir.path().join("x.bmp").display().to_string(),
            ],
            "unsupported output format",
        ),
        (
            vec![
                "render".into(),
                demo("cornell.ron").display().to_string(),
                "-o".into(),
                "x.png".into(),
                "--width".into(),
                "0".into(),
            ],
            "--width",
        ),
        (vec!["export".into(), demo("cornell.ron").display().to_string()], "nothing to export"),
        (
            vec![
                "export".into(),
                demo("cornell.ron").display().to_string(),
                "--vdb".into(),
                // A folder cannot be made inside a file.
                format!("{}/Cargo.toml/x.vdb", env!("CARGO_MANIFEST_DIR")),
                "--width".into(),
                "16".into(),
                "--height".into(),
                "16".into(),
            ],
            "Cargo.toml/x.vdb: cannot create its folder",
        ),
    ];
    for (args, needle) in cases {
        let out = fogsmith().args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "{args:?}: stderr lacks {needle:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    }
}

/// Ctrl+C during an export stops it at the next work item: exit status 130 and a one-line
/// message, the existing output untouched, no temporary file left; without a terminal no
/// progress bar is drawn, so `--json` output is exactly the summary.
#[test]
fn ctrl_c_cancels_an_export_and_leaves_existing_files_untouched() {
    let dir = common::temp_dir();
    let mut p = fogsmith::scene::load_project(&demo("cloud.ron")).unwrap();
    // Large and slow enough (the iterated scheme) to be mid-bake when the signal arrives.
    p.grid.resolution = glam::UVec3::splat(160);
    p.propagation.scheme = fogsmith::scene::Scheme::Giroud;
    let project = dir.path().join("big.ron");
    fogsmith::scene::save_project(&project, &p).unwrap();
    let vdb = dir.path().join("out.vdb");
    std::fs::write(&vdb, b"the previous export").unwrap();
    let child = fogsmith()
        .args(["export", project.to_str().unwrap(), "--vdb", vdb.to_str().unwrap(), "--json"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1500));
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "stderr: {stderr}");
    assert_eq!(
        stderr.trim().lines().last(),
        Some("fogsmith: cancelled by Ctrl+C; no output file was changed"),
        "{stderr}"
    );
    assert!(out.stdout.is_empty(), "no JSON for a cancelled export");
    assert_eq!(std::fs::read(&vdb).unwrap(), b"the previous export");
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(left.len(), 2, "only the project and the old output remain: {left:?}");
}

#[test]
fn export_json_is_the_summary_alone_and_no_temporary_remains() {
    let dir = common::temp_dir();
    let vdb = dir.path().join("room.vdb");
    let out = fogsmith()
        .args([
            "export",
            demo("cornell.ron").to_str().unwrap(),
            "--vdb",
            vdb.to_str().unwrap(),
            "--width",
            "32",
            "--height",
            "18",
            "--json",
        ])
        .output()
        .unwrap();
    let v = json_of(&out);
    assert!(v.get("vdb").is_some(), "{v}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains('%') && !stderr.contains("wrote"), "no bar or note with --json and no terminal: {stderr}");
    let names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert_eq!(names, vec!["room.vdb".to_string()]);
}

/// With stderr on a terminal (a pseudo-terminal from `script`) the progress bar is drawn there
/// and `--json` on stdout carries the same fields as without one; `--quiet` draws nothing.
#[test]
fn json_is_the_same_with_a_progress_bar_on_a_terminal() {
    let dir = common::temp_dir();
    let png = dir.path().join("a.png");
    let json = dir.path().join("out.json");
    let bin = env!("CARGO_BIN_EXE_fogsmith");
    let args = format!("render {} -o {} --width 48 --height 27 --json", demo("cloud.ron").display(), png.display());
    let piped = fogsmith().args(args.split(' ')).output().unwrap();
    let without = json_of(&piped);
    for quiet in [false, true] {
        let cmd = format!("{bin} {args}{} > {}", if quiet { " --quiet" } else { "" }, json.display());
        let out = Command::new("script")
            .args(["-qec", &cmd, "/dev/null"])
            .output()
            .expect("script (util-linux) runs a command on a pseudo-terminal");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stdout));
        let with: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&json).unwrap()).expect("stdout is the JSON alone");
        let keys = |v: &serde_json::Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
        assert_eq!(keys(&with), keys(&without));
        assert_eq!(with["width"], without["width"]);
        let terminal = String::from_utf8_lossy(&out.stdout);
        assert_eq!(terminal.contains('%'), !quiet, "the bar is drawn on the terminal unless --quiet: {terminal:?}");
    }
}

/// `render --json` reports the GPU memory the baked scene holds and its peak; `info` with a
/// project reports the live memory of its baked resources, at least its EV and two
/// optical-depth arrays per light.
#[test]
fn render_and_info_report_gpu_memory() {
    let dir = common::temp_dir();
    let png = dir.path().join("c.png");
    let cloud = demo("cloud.ron");
    let out = fogsmith()
        .args([
            "render",
            cloud.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
            "--width",
            "48",
            "--height",
            "27",
            "--json",
        ])
        .output()
        .unwrap();
    let v = json_of(&out);
    let cells: u64 = v["grid"].as_array().unwrap().iter().map(|n| n.as_u64().unwrap()).product();
    let lights = v["lights"].as_u64().unwrap();
    let floor = cells * 4 * (1 + 2 * lights);
    let (live, peak) = (v["gpu_memory_bytes"].as_u64().unwrap(), v["gpu_memory_peak_bytes"].as_u64().unwrap());
    assert!(live >= floor && peak >= live, "live {live}, peak {peak}, EV + OPVs alone {floor}: {v}");
    let info = json_of(&fogsmith().args(["info", cloud.to_str().unwrap(), "--json"]).output().unwrap());
    assert!(info["gpu_memory_bytes"].as_u64().unwrap() >= floor, "{info}");
    // Optical depth lives in textures: more lights at 128³ than one storage binding holds.
    let one_binding = info["limits"]["max_storage_buffer_binding_size"].as_u64().unwrap() / (128 * 128 * 128 * 4);
    assert!(info["opv_lights_128"].as_u64().unwrap() > one_binding, "{info}");
    let plain = fogsmith().arg("info").output().unwrap();
    let text = String::from_utf8_lossy(&plain.stdout);
    assert!(plain.status.success() && text.contains("optical-depth storage:") && text.contains("GPU memory"), "{text}");
}

/// A project with an imported base volume: a smooth, lumpy density written as a VDB on its
/// own grid (coarser, shifted, partly outside the project's box), under `seed`'s particles.
fn base_volume_project(dir: &Path, seed: u64) -> PathBuf {
    use fogsmith::export::vdb::{write_vdb, VdbGrid, VdbOptions};
    use fogsmith::scene::{BaseVolume, GridSpec, Particle, Volume};
    use glam::{UVec3, Vec3};
    let mut rng = common::Rng(seed);
    let mut p = common::small_scene(20, &[Vec3::new(rng.range(-1.5, 1.5), 1.6, rng.range(-1.5, 1.5))]);
    p.particles =
        (0..5).map(|_| Particle::new(rng.vec3(-0.35, 0.35), rng.range(0.2, 0.3), rng.range(1.0, 5.0))).collect();
    let layer_grid =
        GridSpec { min: Vec3::new(-1.3, -0.9, -1.1), max: Vec3::new(0.9, 1.4, 1.2), resolution: UVec3::new(7, 6, 9) };
    let (c, w) = (rng.vec3(-0.4, 0.4), rng.range(0.3, 0.6));
    let data = (0..layer_grid.cell_count() as usize)
        .map(|n| {
            let [i, j, k] = layer_grid.cell_of(n);
            let x = layer_grid.min + (Vec3::new(i as f32, j as f32, k as f32) + 0.5) * layer_grid.cell_size();
            (-(x - c).length_squared() / (w * w)).exp() * 2.0 + 0.3 * rng.f32()
        })
        .collect();
    let volume = Volume::new(layer_grid, data);
    write_vdb(&dir.join("layer.vdb"), &[VdbGrid::from_volume("density", &volume)], &VdbOptions::default()).unwrap();
    p.base_volume = Some(BaseVolume { path: "layer.vdb".into(), grid: "density".into(), scale: 1.7 });
    let path = dir.join("fog.ron");
    fogsmith::scene::save_project(&path, &p).unwrap();
    path
}

#[test]
fn verify_includes_the_base_volume_in_the_reference() {
    for seed in [3, 11] {
        let dir = common::temp_dir();
        let path = base_volume_project(dir.path(), seed);
        let out = fogsmith().args(["verify", path.to_str().unwrap(), "--width", "32", "--json"]).output().unwrap();
        let v = json_of(&out);
        assert_eq!(v["base_volume"], true, "{v}");
        assert!(v["ev_max_rel_error"].as_f64().unwrap() < 1e-4, "seed {seed}: {v}");
        for o in v["opv"].as_array().unwrap() {
            assert!(o["scheme"]["transmittance_max_abs_error"].as_f64().unwrap() < 5e-3, "seed {seed}: {v}");
            assert!(o["resolution"]["transmittance_max_abs_error"].as_f64().unwrap() < 0.02, "seed {seed}: {v}");
        }
        assert!(v["image_rel_rmse"].as_f64().unwrap() < 0.05, "seed {seed}: {v}");
    }
}

/// The same measures as `verify`, with the reference's base volume wrong: left out, or at a
/// scale 5 % off. Each must show up as error far above the honest figures.
#[test]
fn a_wrong_base_volume_in_the_reference_is_detected() {
    use fogsmith::gpu::FrameRequest;
    use fogsmith::measure::{ev_error_with, image_error, opv_errors_with, sample_cells};
    use fogsmith::reference::{render_reference_with, Medium64, RefRenderOptions};
    let dir = common::temp_dir();
    let path = base_volume_project(dir.path(), 5);
    let project = fogsmith::scene::load_project(&path).unwrap();
    let layer =
        fogsmith::export::load_base_layer(&project, Some(&path)).unwrap().expect("the project has a base volume");
    assert!(layer.data.iter().any(|&v| v > 1.0), "the layer is substantial");
    let mut gpu = common::pipeline();
    gpu.set_base_layer(Some(layer.clone()));
    let mut request = FrameRequest::for_project(&project);
    (request.width, request.height) = (24, 18);
    gpu.update(&project, &request).unwrap();
    let (ev, opv, image) = (gpu.read_ev().unwrap(), gpu.read_opv(0).unwrap(), gpu.read_image().unwrap());
    let cells = sample_cells(&project.grid, 4096);
    let mut off = layer.clone();
    off.data.iter_mut().for_each(|v| *v *= 1.05);
    let measure = |exact: &Medium64| {
        let (ev_rel, _) = ev_error_with(exact, &project, &ev, &cells);
        let opv = opv_errors_with(&project, exact, 0, &ev, &opv, &cells).total.transmittance_max_abs_error;
        let img =
            image_error(&image, &render_reference_with(&project, exact, 24, 18, &RefRenderOptions::default())).rel_rmse;
        (ev_rel, opv, img)
    };
    let honest = measure(&Medium64::for_project(&project, Some(&layer)));
    let scaled = measure(&Medium64::for_project(&project, Some(&off)));
    let without = measure(&Medium64::for_project(&project, None));
    println!("honest {honest:?}, scale 5% off {scaled:?}, left out {without:?}");
    assert!(honest.0 < 1e-4 && honest.1 < 0.01 && honest.2 < 0.01, "{honest:?}");
    assert!(
        scaled.0 > 0.02 && scaled.1 > 2.0 * honest.1 && scaled.2 > 2.0 * honest.2,
        "a 5% scale error: {scaled:?} vs {honest:?}"
    );
    assert!(
        without.0 > 0.5 && without.1 > 0.05 && without.2 > 0.1 && without.2 > 3.0 * honest.2,
        "{without:?} vs {honest:?}"
    );
}

/// The propagation suite's `--scene` and `--scheme` filters refuse names they do not know,
/// naming the bad one and listing the valid ones, before any benchmark runs.
#[test]
fn bench_refuses_unknown_scenes_and_schemes() {
    let dir = common::temp_dir();
    let out = dir.path().display().to_string();
    for (flag, bad, known) in [("--scene", "atlantis", "cornell"), ("--scheme", "sweep9", "sweep8r")] {
        let run = fogsmith().args(["bench", "--suite", "opv", "--quiet", "--out", &out, flag, bad]).output().unwrap();
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{flag} {bad} was accepted");
        assert!(err.contains(&format!("{flag} {bad}")) && err.contains(known), "{err}");
    }
}

/// The propagation suite records each scheme's error against the grid's medium and against
/// the gaussians clipped to the box, and plots time against both: on a thin street the
/// refined sweep is within 1e-5 of its grid and `analytic` within 1e-5 of the gaussians,
/// which the coarse grid misses by far more.
#[test]
fn bench_opv_measures_both_errors_and_plots_both() {
    let dir = common::temp_dir();
    let out = dir.path().display().to_string();
    let run = fogsmith()
        .args([
            "bench",
            "--suite",
            "opv",
            "--quiet",
            "--resolution",
            "16",
            "--scene",
            "street",
            "--scheme",
            "sweep8r,analytic",
            "--out",
            &out,
        ])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let records: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(dir.path().join("bench.json")).unwrap()).unwrap();
    let get = |scheme: &str, key: &str| {
        let r =
            records.iter().find(|r| r["scheme_or_policy"] == scheme).unwrap_or_else(|| panic!("no {scheme} record"));
        r[key].as_f64().unwrap_or_else(|| panic!("{scheme}: no {key}"))
    };
    let resolution = get("sweep8r", "resolution_error_max");
    assert!(get("sweep8r", "error_max") < 1e-5 && resolution > 1e-2, "{records:?}");
    assert!(get("analytic", "error_vs_analytic_max") < 1e-5, "{records:?}");
    assert!(
        (get("analytic", "error_max") - resolution).abs() < 1e-3,
        "against the grid, analytic shows the grid's resolution error: {records:?}"
    );
    for png in ["opv_pareto.png", "opv_pareto_gaussians.png"] {
        let size = image::image_dimensions(dir.path().join(png)).unwrap_or_else(|e| panic!("{png}: {e}"));
        assert!(size.0 > 100 && size.1 > 100, "{png}: {size:?}");
    }
}

//! USD scene export: stages of randomized projects in every right-handed export frame, read
//! by Pixar's USD (usd-core) and imported by Blender 4.5 (bpy), both from the project's
//! test-only venv (./setup.sh); and the `fogsmith export --usd` command end to end.

mod common;
use common::{root, venv_python, Rng};

use fogsmith::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use fogsmith::export::usd::{asset_path, write_usd, UsdField, UsdOptions, GROUND_HALF_SIZE};
use fogsmith::export::vdb::{grids_from_volumes, write_vdb, GridSelection, VdbOptions};
use fogsmith::export::LightInfo;
use fogsmith::scene::{Camera, GridSpec, Ground, Light, Medium, Project, SurfaceBox, Volume};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs a checker script on the stages and returns one JSON object per stage.
fn run_checker(module: &str, script: &str, stages: &[PathBuf]) -> Vec<Value> {
    let out = Command::new(venv_python(module)).arg(root().join("tests").join(script)).args(stages).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{script} failed: {}\n{stdout}", String::from_utf8_lossy(&out.stderr));
    let v: Vec<Value> =
        stdout.lines().filter(|l| l.starts_with('{')).map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(v.len(), stages.len(), "{script}: {stdout}");
    v
}

fn random_project(seed: u64) -> Project {
    let mut r = Rng(fogsmith::rng::scrambled(seed));
    let mut p = Project::default();
    let min = r.vec3(-3.0, 1.0);
    let max = min + r.vec3(0.5, 3.0);
    p.grid = GridSpec {
        min,
        max,
        resolution: UVec3::new(8 + (r.f32() * 9.0) as u32, 8 + (r.f32() * 9.0) as u32, 8 + (r.f32() * 9.0) as u32),
    };
    p.medium = Medium {
        base_extinction: r.range(0.0, 0.2),
        albedo: r.f32(),
        anisotropy: r.range(-0.5, 0.8),
        ..Medium::default()
    };
    let n = 1 + (r.f32() * 3.0) as usize;
    p.lights = (0..n).map(|_| Light::new(r.vec3(-4.0, 4.0), r.range(0.5, 50.0), r.vec3(0.2, 1.0))).collect();
    if n > 1 {
        p.lights[1].hidden = r.f32() < 0.5;
    }
    let position = r.vec3(-6.0, 6.0) + Vec3::new(0.0, 0.0, 8.0);
    p.camera = Camera { position, target: r.vec3(-1.0, 1.0), up: Vec3::Y, fov_y_deg: r.range(20.0, 80.0) };
    p.render.width = 16 + (r.f32() * 100.0) as u32;
    p.render.height = 16 + (r.f32() * 100.0) as u32;
    if r.f32() < 0.7 {
        p.surfaces.ground = Some(Ground { height: r.range(-3.0, 0.0), albedo: r.vec3(0.0, 1.0), ..Ground::default() });
    }
    for _ in 0..(r.f32() * 3.0) as usize {
        let a = r.vec3(-2.0, 2.0);
        p.surfaces.boxes.push(SurfaceBox {
            min: a,
            max: a + r.vec3(0.1, 1.5),
            albedo: r.vec3(0.0, 1.0),
            ..SurfaceBox::default()
        });
    }
    p
}

fn right_handed_frames() -> Vec<Frame> {
    let mut v = Vec::new();
    for up in [UpAxis::Y, UpAxis::Z] {
        for units in [Units::M, Units::Cm] {
            v.push(Frame { up, units, handedness: Handedness::Right });
        }
    }
    v
}

/// Writes `p`'s stage in `frame` to `dir/name.usda` with a VDB (a blob of density and one
/// optical-depth grid per light) beside it, as the CLI does.
fn write_stage(dir: &Path, name: &str, p: &Project, frame: Frame) -> (PathBuf, PathBuf, Vec<UsdField>) {
    let ev = Volume::new(p.grid, (0..p.grid.cell_count()).map(|n| (n % 7) as f32 * 0.3).collect());
    let opv = Volume::new(p.grid, (0..p.grid.cell_count()).map(|n| (n % 5) as f32 * 0.1).collect());
    let lights: Vec<(&Volume, LightInfo)> = p
        .lights
        .iter()
        .map(|l| {
            (
                &opv,
                LightInfo {
                    id: l.id,
                    position: l.position.to_array(),
                    intensity: l.intensity,
                    color: l.color.to_array(),
                }
                .in_frame(&frame),
            )
        })
        .collect();
    let grids =
        grids_from_volumes(&ev, &lights, GridSelection { density: true, optical_depth: true, transmittance: false });
    let vdb = dir.join(format!("{name}.vdb"));
    write_vdb(&vdb, &grids, &VdbOptions { frame, ..Default::default() }).unwrap();
    let fields: Vec<UsdField> =
        grids.iter().map(|g| UsdField { name: g.name.clone(), density: g.name == "density", vector: false }).collect();
    let usd = dir.join(format!("{name}.usda"));
    let opts = UsdOptions {
        vdb_asset: asset_path(&usd, &vdb),
        fields: fields.clone(),
        frame,
        width: p.render.width,
        height: p.render.height,
    };
    write_usd(&usd, p, &opts).unwrap();
    (usd, vdb, fields)
}

fn vec3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap_or_else(|| panic!("not a vector: {v}"));
    [0, 1, 2].map(|i| a[i].as_f64().unwrap())
}

#[track_caller]
fn close(got: [f64; 3], want: [f64; 3], tol: f64, what: &str) {
    for a in 0..3 {
        assert!((got[a] - want[a]).abs() <= tol, "{what}: got {got:?}, want {want:?} (±{tol})");
    }
}

fn p64(v: Vec3) -> [f64; 3] {
    v.to_array().map(f64::from)
}

/// The grid box's corners carried into `frame`, as (min, max).
fn box_in(frame: &Frame, min: Vec3, max: Vec3) -> ([f64; 3], [f64; 3]) {
    let (a, b) = (frame.point(p64(min)), frame.point(p64(max)));
    ([0, 1, 2].map(|i| a[i].min(b[i])), [0, 1, 2].map(|i| a[i].max(b[i])))
}

#[test]
fn usd_core_reads_random_projects_in_every_frame() {
    let dir = common::temp_dir();
    let mut cases = Vec::new();
    for seed in 1..=6u64 {
        let p = random_project(seed);
        for (f, frame) in right_handed_frames().into_iter().enumerate() {
            let (usd, vdb, fields) = write_stage(dir.path(), &format!("s{seed}_{f}"), &p, frame);
            cases.push((p.clone(), frame, usd, vdb, fields));
        }
    }
    let stages: Vec<PathBuf> = cases.iter().map(|c| c.2.clone()).collect();
    let reports = run_checker("pxr.Usd", "usd_check.py", &stages);
    for ((p, frame, usd, vdb, fields), v) in cases.iter().zip(&reports) {
        let tag = format!("{} ({frame})", usd.display());
        let s = frame.scale();
        let tol = 1e-5 * s * 10.0;
        assert_eq!(v["upAxis"], frame.up_name(), "{tag}");
        assert_eq!(v["metersPerUnit"].as_f64().unwrap(), frame.meters_per_unit(), "{tag}");
        assert_eq!(v["defaultPrim"], "/World", "{tag}");
        assert_eq!(v["creator"], "fogsmith", "{tag}");
        assert_eq!(
            v["validation_errors"].as_array().unwrap().len(),
            0,
            "{tag}: USD's validators report {}",
            v["validation_errors"]
        );
        assert!(v["validators"].as_u64().unwrap() > 0, "{tag}");

        // The volume and its fields, each resolving to the VDB.
        assert_eq!(v["volume"]["is_volume"], true, "{tag}");
        let ext = v["volume"]["extent"].as_array().unwrap();
        let (lo, hi) = box_in(frame, p.grid.min, p.grid.max);
        close(vec3(&ext[0]), lo, tol, &format!("{tag} extent min"));
        close(vec3(&ext[1]), hi, tol, &format!("{tag} extent max"));
        assert_eq!(v["volume"]["albedo"].as_f64().unwrap() as f32, p.medium.albedo, "{tag}");
        assert_eq!(v["volume"]["anisotropy"].as_f64().unwrap() as f32, p.medium.anisotropy, "{tag}");
        assert_eq!(v["volume"]["base_extinction"].as_f64().unwrap() as f32, p.medium.base_extinction, "{tag}");
        let got: Vec<&String> = v["fields"].as_object().unwrap().keys().collect();
        let mut want: Vec<&String> = fields.iter().map(|f| &f.name).collect();
        want.sort();
        let mut got_sorted = got.clone();
        got_sorted.sort();
        assert_eq!(got_sorted, want, "{tag}");
        assert_eq!(fields.len(), 1 + p.lights.len(), "{tag}");
        for f in fields {
            let o = &v["fields"][&f.name];
            assert_eq!(o["is_openvdb_asset"], true, "{tag} {}", f.name);
            assert_eq!(o["fieldName"], f.name.as_str(), "{tag}");
            assert_eq!(o["fieldClass"], if f.density { "fogVolume" } else { "unknown" }, "{tag} {}", f.name);
            assert_eq!(o["fieldDataType"], "float", "{tag}");
            let resolved = PathBuf::from(o["resolved"].as_str().unwrap());
            assert_eq!(
                resolved.canonicalize().unwrap(),
                vdb.canonicalize().unwrap(),
                "{tag} {}: the asset does not resolve to the VDB",
                f.name
            );
        }

        // Lights: visible ones only, at their positions in the frame, intensity 4·I.
        let lights = v["lights"].as_object().unwrap();
        let visible: Vec<(usize, &Light)> = p.lights.iter().enumerate().filter(|(_, l)| !l.hidden).collect();
        assert_eq!(lights.len(), visible.len(), "{tag}: {lights:?}");
        for (i, l) in visible {
            let o = &lights[&format!("Light_{i}")];
            close(vec3(&o["position"]), frame.point(p64(l.position)), tol, &format!("{tag} light {i}"));
            assert!(
                (o["intensity"].as_f64().unwrap() - 4.0 * l.intensity as f64).abs() <= 1e-5 * l.intensity as f64,
                "{tag} light {i}: {o}"
            );
            close(vec3(&o["color"]), p64(l.color), 1e-7, &format!("{tag} light {i} colour"));
            assert_eq!(o["normalize"], true, "{tag}");
            assert_eq!(o["treatAsPoint"], true, "{tag}");
            assert_eq!(o["radius"].as_f64().unwrap(), 0.0, "{tag}");
        }

        // Camera: placement, view and up directions, and both fields of view.
        let c = &v["camera"];
        let (_, up, forward) = p.camera.basis();
        close(vec3(&c["position"]), frame.point(p64(p.camera.position)), tol, &format!("{tag} camera position"));
        close(vec3(&c["forward"]), frame.vector(p64(forward)), 1e-5, &format!("{tag} camera forward"));
        close(vec3(&c["up"]), frame.vector(p64(up)), 1e-5, &format!("{tag} camera up"));
        let fov_y = c["fov_y_deg"].as_f64().unwrap();
        assert!((fov_y - p.camera.fov_y_deg as f64).abs() < 1e-3, "{tag}: fov_y {fov_y} vs {}", p.camera.fov_y_deg);
        let half = |deg: f64| (deg.to_radians() * 0.5).tan();
        let aspect = p.render.width as f64 / p.render.height as f64;
        assert!(
            (half(c["fov_x_deg"].as_f64().unwrap()) / half(fov_y) - aspect).abs() < 1e-4 * aspect,
            "{tag}: fov_x {c}"
        );

        // Surfaces: meshes at their places with their diffuse albedo.
        let meshes = v["meshes"].as_object().unwrap();
        assert_eq!(meshes.len(), p.surfaces.boxes.len() + p.surfaces.ground.is_some() as usize, "{tag}");
        let mut want: Vec<(String, Vec3, Vec3, Vec3, usize)> =
            p.surfaces.boxes.iter().enumerate().map(|(n, b)| (format!("Box_{n}"), b.min, b.max, b.albedo, 6)).collect();
        if let Some(g) = &p.surfaces.ground {
            let l = GROUND_HALF_SIZE as f32;
            want.push(("Ground".into(), Vec3::new(-l, g.height, -l), Vec3::new(l, g.height, l), g.albedo, 1));
        }
        for (name, min, max, albedo, faces) in want {
            let o = &meshes[&name];
            let (lo, hi) = box_in(frame, min, max);
            let tol = tol * (1.0 + max.abs().max_element() as f64);
            close(vec3(&o["min"]), lo, tol, &format!("{tag} {name} min"));
            close(vec3(&o["max"]), hi, tol, &format!("{tag} {name} max"));
            assert_eq!(o["faces"].as_u64().unwrap() as usize, faces, "{tag} {name}");
            assert_eq!(o["shader"], "UsdPreviewSurface", "{tag} {name}");
            close(vec3(&o["diffuseColor"]), p64(albedo), 1e-7, &format!("{tag} {name} albedo"));
            assert_eq!(o["roughness"].as_f64().unwrap(), 1.0, "{tag} {name}");
        }
    }
}

/// Blender imports every frame's stage to the same place in its own Z-up metre world: the
/// volume with all its grids and voxel (0, 0, 0) at cell 0's centre, each light at its
/// position with power 4π·I W (Cycles' point light of power P has P/(4π) W/sr), the camera
/// where the project puts it with its vertical field of view, the surfaces' meshes.
#[test]
fn blender_imports_random_projects_in_every_frame_to_the_same_places() {
    let dir = common::temp_dir();
    let blender = Frame::preset(Preset::Blender);
    let mut cases = Vec::new();
    for seed in 11..=13u64 {
        let p = random_project(seed);
        for (f, frame) in right_handed_frames().into_iter().enumerate() {
            let (usd, _, fields) = write_stage(dir.path(), &format!("b{seed}_{f}"), &p, frame);
            cases.push((p.clone(), frame, usd, fields));
        }
    }
    let stages: Vec<PathBuf> = cases.iter().map(|c| c.2.clone()).collect();
    let reports = run_checker("bpy", "blender_check.py", &stages);
    for ((p, frame, usd, fields), v) in cases.iter().zip(&reports) {
        let tag = format!("{} ({frame})", usd.display());
        let tol = 1e-4;
        assert_eq!(v["result"][0], "FINISHED", "{tag}");

        let vols = v["volumes"].as_object().unwrap();
        assert_eq!(vols.len(), 1, "{tag}: {vols:?}");
        let vol = vols.values().next().unwrap();
        assert_eq!(vol["error"], "", "{tag}");
        let mut names: Vec<&String> = vol["grids"].as_object().unwrap().keys().collect();
        names.sort();
        let mut want: Vec<&String> = fields.iter().map(|f| &f.name).collect();
        want.sort();
        assert_eq!(names, want, "{tag}: Blender's grids");
        // World position of the density grid's voxel (0, 0, 0): matrix_world · matrix_object · 0.
        let mw: Vec<[f64; 4]> = vol["matrix_world"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let r = r.as_array().unwrap();
                [0, 1, 2, 3].map(|i| r[i].as_f64().unwrap())
            })
            .collect();
        let mo: Vec<[f64; 4]> = vol["grids"]["density"]["matrix_object"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| {
                let r = r.as_array().unwrap();
                [0, 1, 2, 3].map(|i| r[i].as_f64().unwrap())
            })
            .collect();
        let local = [mo[0][3], mo[1][3], mo[2][3]];
        let world = [0, 1, 2].map(|a| mw[a][0] * local[0] + mw[a][1] * local[1] + mw[a][2] * local[2] + mw[a][3]);
        close(world, blender.point(p64(p.grid.cell_center(0, 0, 0))), tol, &format!("{tag} voxel 0"));
        // One voxel step along index x is one cell along Fogsmith's x, in metres.
        let step = [0, 1, 2].map(|a| mw[a][0] * mo[0][0] + mw[a][1] * mo[1][0] + mw[a][2] * mo[2][0]);
        close(step, blender.vector([p.grid.cell_size().x as f64, 0.0, 0.0]), 1e-5, &format!("{tag} voxel step"));

        let lights = v["lights"].as_object().unwrap();
        let visible: Vec<(usize, &Light)> = p.lights.iter().enumerate().filter(|(_, l)| !l.hidden).collect();
        assert_eq!(lights.len(), visible.len(), "{tag}");
        for (i, l) in visible {
            let o = &lights[&format!("Light_{i}")];
            assert_eq!(o["type"], "POINT", "{tag}");
            close(vec3(&o["position"]), blender.point(p64(l.position)), tol, &format!("{tag} light {i}"));
            let power = 4.0 * std::f64::consts::PI * l.intensity as f64;
            assert!(
                (o["energy"].as_f64().unwrap() - power).abs() <= 1e-5 * power,
                "{tag} light {i}: {o} want {power} W"
            );
            close(vec3(&o["color"]), p64(l.color), 1e-6, &format!("{tag} light {i} colour"));
        }

        let c = &v["camera"];
        let (_, up, forward) = p.camera.basis();
        close(vec3(&c["position"]), blender.point(p64(p.camera.position)), tol, &format!("{tag} camera"));
        close(vec3(&c["forward"]), blender.vector(p64(forward)), 1e-5, &format!("{tag} camera forward"));
        close(vec3(&c["up"]), blender.vector(p64(up)), 1e-5, &format!("{tag} camera up"));
        let fov_y = c["angle_y_deg"].as_f64().unwrap();
        assert!((fov_y - p.camera.fov_y_deg as f64).abs() < 1e-3, "{tag}: {c}");

        let meshes = v["meshes"].as_object().unwrap();
        assert_eq!(meshes.len(), p.surfaces.boxes.len() + p.surfaces.ground.is_some() as usize, "{tag}: {meshes:?}");
        for (n, b) in p.surfaces.boxes.iter().enumerate() {
            let o = &meshes[&format!("Box_{n}")];
            let (lo, hi) = box_in(&blender, b.min, b.max);
            close(vec3(&o["min"]), lo, tol, &format!("{tag} box {n}"));
            close(vec3(&o["max"]), hi, tol, &format!("{tag} box {n}"));
        }
    }
}

fn fogsmith() -> Command {
    fogsmith::cli::ensure_runtime_dir();
    Command::new(env!("CARGO_BIN_EXE_fogsmith"))
}

/// `fogsmith export --usd --ktx2` on a demo: the stage, the VDB beside it (Blender's frame,
/// optical depths of class unknown), the KTX2 texture and its snippet, and clear errors for a left-handed frame and a wrong extension.
#[test]
fn cli_exports_a_usd_stage_with_its_vdb() {
    let dir = common::temp_dir();
    let usd = dir.path().join("cornell.usda");
    let project = root().join("projects/cornell.ron");
    let out = fogsmith()
        .args(["export", project.to_str().unwrap(), "--width", "32", "--height", "18", "--preset", "blender", "--json"])
        .args(["--usd", usd.to_str().unwrap(), "--ktx2", dir.path().join("cornell.ktx2").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    // The KTX2 texture has the project grid's size whatever the preset, and its Bevy snippet.
    let json: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["usd"]["frame"], "Z-up, m, right-handed");
    let ktx = ktx2::Reader::new(std::fs::read(dir.path().join("cornell.ktx2")).unwrap()).unwrap();
    let grid = fogsmith::scene::io::load_project(&root().join("projects/cornell.ron")).unwrap().grid;
    let h = ktx.header();
    assert_eq!(
        (h.pixel_width, h.pixel_height, h.pixel_depth),
        (grid.resolution.x, grid.resolution.y, grid.resolution.z)
    );
    assert!(std::fs::read_to_string(dir.path().join("cornell.fogvolume.ron"))
        .unwrap()
        .contains("density_texture: \"cornell.ktx2\""));
    let vdb = dir.path().join("cornell.vdb");
    let v = &run_checker("pxr.Usd", "usd_check.py", std::slice::from_ref(&usd))[0];
    assert_eq!(v["upAxis"], "Z");
    assert_eq!(v["fields"]["density"]["path"], "./cornell.vdb");
    assert_eq!(
        PathBuf::from(v["fields"]["density"]["resolved"].as_str().unwrap()).canonicalize().unwrap(),
        vdb.canonicalize().unwrap()
    );
    let p = fogsmith::scene::io::load_project(&project).unwrap();
    assert_eq!(v["lights"].as_object().unwrap().len(), p.lights.iter().filter(|l| !l.hidden).count());
    for (name, g) in [("density", "fog volume"), ("optical_depth_0", "unknown")] {
        let grid = fogsmith::export::vdb_read::read_vdb_grid(&vdb, Some(name)).unwrap();
        assert_eq!(grid.frame, Frame::preset(Preset::Blender));
        let class = grid.metadata.iter().find(|m| m.0 == "class").map(|m| String::from_utf8_lossy(&m.2).into_owned());
        assert_eq!(class.as_deref(), Some(g));
    }

    for (args, needle) in [
        (vec!["--preset", "unreal", "--usd", usd.to_str().unwrap()], "--handedness right"),
        (vec!["--usd", dir.path().join("x.usd").to_str().unwrap()], ".usda"),
    ] {
        let out = fogsmith().args(["export", project.to_str().unwrap()]).args(&args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} succeeded");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}

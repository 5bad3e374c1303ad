//! The light bake in a renderer we did not write: randomized fog scenes are exported with
//! `--bake-light --bake-phase camera --preset blender --usd`, imported by Blender 4.5 (`bpy`
//! in the project's test venv, ./setup.sh) with every light deleted, and rendered by Cycles
//! as emission and absorption only (tests/blender_bake.py). The image must match
//! `fogsmith render` of the lit scene.
//!
//! Cycles renders twice with different seeds; their difference estimates its noise. The mean
//! must agree within 5 % plus 4σ of that noise. Over 4×4-pixel blocks, Cycles must match our
//! own emission–absorption render of the bake within 4σ plus [`RMSE_ALLOWANCE`], and the lit
//! render within that plus the bake's own difference from it (its resolution error, which
//! tests/bake.rs bounds).

mod common;
use common::{read_exr_rgb, read_f32_rgb, root, run_ok, venv_python, Rng};

use fogsmith::scene::{Camera, GridSpec, Light, LightKind, Medium, Particle, Project};
use glam::{UVec3, Vec3};
use std::process::Command;

const W: usize = 64;
const H: usize = 48;
const SAMPLES: u32 = 64;
/// Principled Volume's Emission Strength that makes Cycles' emission the bake's j: measured
/// (the printed ratio at strength 1 is 1 within the noise) and documented in docs/interchange.md.
const STRENGTH: f64 = 1.0;
/// Beyond 4σ of Cycles' noise, the relative RMSE over 4×4-pixel blocks between Cycles and our
/// own emission–absorption render of the same bake (`reference::render_emission`) may hold the
/// renderers' different voxel interpolation and volume sampling: measured 2 % (printed).
const RMSE_ALLOWANCE: f64 = 0.03;

/// A cloud of gaussians inside a grid off the origin, a point light and a spot outside it,
/// a camera from a random side, random albedo and g; no base fog, no surfaces.
fn random_scene(seed: u64) -> Project {
    let mut r = Rng(fogsmith::rng::scrambled(seed));
    let centre = Vec3::new(r.range(-1.0, 1.0), r.range(0.0, 2.0), r.range(-1.0, 1.0));
    let mut p = Project {
        grid: GridSpec { min: centre - Vec3::splat(1.5), max: centre + Vec3::splat(1.5), resolution: UVec3::splat(40) },
        medium: Medium {
            base_extinction: 0.0,
            albedo: r.range(0.5, 1.0),
            anisotropy: r.range(-0.3, 0.6),
            ..Medium::default()
        },
        ..Default::default()
    };
    p.particles = (0..6)
        .map(|_| {
            let c = centre + Vec3::new(r.range(-0.4, 0.4), r.range(-0.4, 0.4), r.range(-0.4, 0.4));
            Particle::new(c, r.range(0.12, 0.25), r.range(1.0, 4.0))
        })
        .collect();
    let pos = centre + r.direction() * r.range(1.6, 2.4);
    let point = Light::new(pos, r.range(5.0, 30.0), Vec3::new(r.range(0.4, 1.0), r.range(0.4, 1.0), 1.0));
    let at = centre + r.direction() * 2.0;
    let mut spot = Light::new(at, r.range(10.0, 30.0), Vec3::new(1.0, r.range(0.4, 1.0), r.range(0.4, 1.0)));
    spot.id = 1;
    spot.kind = LightKind::Spot { direction: centre - at, angle_deg: 20.0, blend: 0.3 };
    p.lights = vec![point, spot];
    let mut d = r.direction();
    d.y = d.y.abs() * 0.5;
    p.camera = Camera { position: centre + d.normalize() * 4.5, target: centre, up: Vec3::Y, fov_y_deg: 40.0 };
    p
}

#[test]
fn cycles_renders_the_bake_like_the_lit_scene() {
    let py = venv_python("bpy");
    fogsmith::cli::ensure_runtime_dir();
    let bin = env!("CARGO_BIN_EXE_fogsmith");
    let tmp = common::temp_dir();
    let dir = tmp.path();
    let (w, h) = (W.to_string(), H.to_string());
    for seed in 1..=2u64 {
        let p = random_scene(seed);
        let ron = dir.join(format!("s{seed}.ron"));
        fogsmith::scene::io::save_project(&ron, &p).unwrap();
        let usd = dir.join(format!("s{seed}.usda"));
        let exr = dir.join(format!("s{seed}.exr"));
        let ron_s = ron.to_str().unwrap();
        run_ok(
            Command::new(bin).args(["export", ron_s, "--quiet", "--bake-light", "--bake-phase", "camera"]).args([
                "--preset",
                "blender",
                "--usd",
                usd.to_str().unwrap(),
                "--width",
                &w,
                "--height",
                &h,
            ]),
            "fogsmith export",
        );
        run_ok(
            Command::new(bin).args(["render", ron_s, "-o", exr.to_str().unwrap(), "--width", &w, "--height", &h]),
            "fogsmith render",
        );
        let fog = read_exr_rgb(&exr, W, H);
        let mut cycles = Vec::new();
        for s in [1, 2] {
            let out = dir.join(format!("s{seed}_cycles{s}.f32"));
            let log = run_ok(
                Command::new(&py).arg(root().join("tests/blender_bake.py")).args([
                    usd.to_str().unwrap(),
                    out.to_str().unwrap(),
                    &w,
                    &h,
                    &SAMPLES.to_string(),
                    &s.to_string(),
                    &STRENGTH.to_string(),
                ]),
                "Cycles render",
            );
            eprintln!("seed {seed} cycles {s}: {}", log.lines().last().unwrap_or(""));
            cycles.push(read_f32_rgb(&out, W, H));
        }
        let px = |img: &[[f32; 3]], i: usize| img[i].iter().map(|&v| v as f64).sum::<f64>() / 3.0;
        let n = (W * H) as f64;
        let mean = |img: &[[f32; 3]]| (0..W * H).map(|i| px(img, i)).sum::<f64>() / n;
        let (mf, m1, m2) = (mean(&fog), mean(&cycles[0]), mean(&cycles[1]));
        assert!(mf > 1e-4, "seed {seed}: Fogsmith's image is black ({mf})");
        let mc = 0.5 * (m1 + m2);
        // Per pixel, d = c1 − c2 has twice the variance of one render's noise; the mean of
        // both renders has a quarter of Var(d) per pixel.
        let var_d = (0..W * H).map(|i| (px(&cycles[0], i) - px(&cycles[1], i)).powi(2)).sum::<f64>() / n;
        let sigma_mean = (var_d / 4.0 / n).sqrt();
        let ratio = mc / mf;
        let bound = 0.05 + 4.0 * sigma_mean / mf;
        // The relative RMSE over 4×4-pixel blocks: Fogsmith shoots one ray through each pixel's
        // centre, Cycles averages over the pixel (box filter), which differ at every sharp edge
        // of the fog; blocks of 4×4 pixels average that out and keep the fog's shape.
        let r = 4;
        let block = |f: &dyn Fn(usize) -> f64| -> Vec<f64> {
            let mut out = Vec::new();
            for by in 0..H / r {
                for bx in 0..W / r {
                    let mut sum = 0.0;
                    for y in by * r..(by + 1) * r {
                        for x in bx * r..(bx + 1) * r {
                            sum += f(y * W + x);
                        }
                    }
                    out.push(sum / (r * r) as f64);
                }
            }
            out
        };
        // Our own emission–absorption render of the same bake, for the share of the difference
        // that is the bake's (against the march) rather than Cycles'.
        let ours = {
            let mut gpu = common::pipeline();
            let request = fogsmith::gpu::FrameRequest {
                width: W as u32,
                height: H as u32,
                ..fogsmith::gpu::FrameRequest::for_project(&p)
            };
            let emission = gpu.bake_emission(&p, &request, fogsmith::gpu::BakePhase::Camera).unwrap();
            let ev = gpu.read_ev().unwrap();
            fogsmith::reference::render_emission(&p, &ev, &emission, W as u32, H as u32)
        };
        let bo = block(&|i| ours[i].iter().sum::<f64>() / 3.0);
        let bf = block(&|i| px(&fog, i));
        let bc = block(&|i| 0.5 * (px(&cycles[0], i) + px(&cycles[1], i)));
        let bd = block(&|i| px(&cycles[0], i) - px(&cycles[1], i));
        let nb = bf.len() as f64;
        let rmse = (bf.iter().zip(&bc).map(|(f, c)| (c - f).powi(2)).sum::<f64>() / nb).sqrt() / mf;
        let noise = (bd.iter().map(|d| d * d).sum::<f64>() / nb / 4.0).sqrt() / mf;
        let ours_rmse = (bf.iter().zip(&bo).map(|(f, o)| (o - f).powi(2)).sum::<f64>() / nb).sqrt() / mf;
        let cycles_vs_ours = (bo.iter().zip(&bc).map(|(o, c)| (c - o).powi(2)).sum::<f64>() / nb).sqrt() / mf;
        eprintln!(
            "seed {seed}: blocks: our bake render vs lit {ours_rmse:.4}; Cycles vs our bake render {cycles_vs_ours:.4}"
        );
        eprintln!(
            "seed {seed}: mean Fogsmith {mf:.5}, Cycles {m1:.5} / {m2:.5}, ratio {ratio:.4} (bound ±{bound:.4}); \
             relative RMSE {rmse:.4}, Cycles' noise {noise:.4}"
        );
        assert!((ratio - 1.0).abs() <= bound, "seed {seed}: Cycles/Fogsmith mean {ratio:.4}, allowed 1 ± {bound:.4}");
        let bound = 4.0 * noise + RMSE_ALLOWANCE;
        assert!(
            cycles_vs_ours <= bound,
            "seed {seed}: Cycles differs from our render of the bake by {cycles_vs_ours:.4} > {bound:.4}"
        );
        assert!(
            rmse <= ours_rmse + bound,
            "seed {seed}: Cycles differs from the lit render by {rmse:.4}, beyond the bake's own {ours_rmse:.4} + {bound:.4}"
        );
    }
}

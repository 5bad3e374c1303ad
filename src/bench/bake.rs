//! `bench --suite bake`: the light bake on each demo, per grid resolution and phase mode. Its
//! time on the GPU; its error, as the relative RMSE and mean error of an emission–absorption
//! render of the bake (`reference::render_emission`) against the lit render; the bytes of each
//! output; and the error the engine textures' quantisation adds (8-bit with a scale, and half
//! floats), measured on the same render.
//!
//! The bake holds the fog inside the grid only, so each demo is measured fog-only: without
//! surfaces and without base fog (its lit render then holds exactly what the bake can).

use super::context::Context;
use super::BenchError;
use crate::export::exr::write_baked_atlas_exr;
use crate::export::frame::Frame;
use crate::export::ktx::encode_baked_ktx2;
use crate::export::vdb::{encode_vdb, VdbGrid, VdbOptions};
use crate::gpu::{BakePhase, FrameRequest, Image};
use crate::measure::image_error;
use crate::reference::render_emission;
use crate::scene::{Project, Volume, Volume3};
use serde_json::{json, Value};
use std::path::Path;
use std::time::Instant;

/// The demo with its grid's longest axis at `longest` cells, fog only (see the module doc).
fn fog_only(name: &str, longest: u32) -> Result<Project, BenchError> {
    let mut p = crate::demos::demo(name)?;
    p.surfaces = Default::default();
    p.medium.base_extinction = 0.0;
    let size = p.grid.size();
    p.grid.resolution = (size * (longest as f32 / size.max_element())).round().as_uvec3().max(glam::UVec3::ONE);
    Ok(p)
}

/// `v` stored with 8 bits per channel against its largest value.
fn quantise8(v: f32, scale: f32) -> f32 {
    (v / scale * 255.0).round().clamp(0.0, 255.0) / 255.0 * scale
}

fn half(v: f32) -> f32 {
    half::f16::from_f32(v).to_f32()
}

/// The bake's render error with its textures quantised by `q` (per-quantity scale given).
fn quantised_render(
    p: &Project,
    ev: &Volume,
    emission: &Volume3,
    q: &dyn Fn(f32, f32) -> f32,
    (w, h): (u32, u32),
) -> Vec<[f64; 3]> {
    let (se, sa) = (emission.max_value().max(1e-30), ev.max_value().max(1e-30));
    let ev_q = Volume::new(ev.grid, ev.data.iter().map(|&v| q(v, sa)).collect());
    let em_q = Volume3::new(emission.grid, emission.data.iter().map(|e| e.map(|c| q(c, se))).collect());
    render_emission(p, &ev_q, &em_q, w, h)
}

fn as_image(v: &[[f64; 3]], w: u32, h: u32) -> Image {
    Image { width: w, height: h, rgba: v.iter().map(|p| [p[0] as f32, p[1] as f32, p[2] as f32, 1.0]).collect() }
}

fn mean(v: &[[f64; 3]]) -> f64 {
    v.iter().flatten().sum::<f64>() / (v.len() * 3).max(1) as f64
}

pub(super) fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let resolutions = if ctx.quick { vec![64] } else { vec![64, 128] };
    let scenes: Vec<String> = if ctx.scenes.is_empty() {
        crate::demos::DEMOS.iter().map(|(name, _)| name.to_string()).collect()
    } else {
        ctx.scenes.clone()
    };
    let (w, h) = if ctx.quick { (96, 54) } else { (160, 90) };
    let tmp = std::env::temp_dir().join(format!("fogsmith-bench-bake-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).map_err(|e| BenchError::Option(format!("{}: {e}", tmp.display())))?;
    for name in &scenes {
        for &res in &resolutions {
            let p = fog_only(name, res)?;
            ctx.full(&p, w, h)?;
            let lit: Vec<[f64; 3]> =
                ctx.gpu.read_image()?.rgba.iter().map(|c| [c[0] as f64, c[1] as f64, c[2] as f64]).collect();
            let request = FrameRequest { width: w, height: h, ..FrameRequest::for_project(&p) };
            for phase in [BakePhase::Isotropic, BakePhase::Camera] {
                let t = Instant::now();
                let emission = ctx.gpu.bake_emission(&p, &request, phase)?;
                let bake_ms = t.elapsed().as_secs_f64() * 1e3;
                let ev = ctx.gpu.read_ev()?;
                let render = render_emission(&p, &ev, &emission, w, h);
                let err = image_error(&as_image(&render, w, h), &lit);
                let mean_err = (mean(&render) - mean(&lit)).abs() / mean(&lit).max(1e-30);
                let q8 = quantised_render(&p, &ev, &emission, &quantise8, (w, h));
                let q16 = quantised_render(&p, &ev, &emission, &|v, _| half(v), (w, h));
                let e8 = image_error(&as_image(&q8, w, h), &render).rel_rmse;
                let e16 = image_error(&as_image(&q16, w, h), &render).rel_rmse;
                let vdb_grids = [VdbGrid::from_volume("density", &ev), VdbGrid::from_volume3("emission", &emission)];
                let vdb = encode_vdb(Path::new("bake.vdb"), &vdb_grids, &VdbOptions::default())
                    .map(|(b, _)| b.len())
                    .unwrap_or(0);
                let ktx = encode_baked_ktx2(Path::new("bake.ktx2"), &ev, &emission).map(|(b, _)| b.len()).unwrap_or(0);
                let atlas_path = tmp.join("atlas.exr");
                let atlas = write_baked_atlas_exr(&atlas_path, &ev, &emission, &Frame::NATIVE)
                    .ok()
                    .and_then(|_| std::fs::metadata(&atlas_path).ok())
                    .map_or(0, |m| m.len() as usize);
                log(&format!(
                    "bake   {name:8} {res:>3} {:9} {bake_ms:8.1} ms  render vs lit: rel RMSE {:.2e}, mean {:.2e}  \
                     textures: 8-bit {e8:.2e}, half {e16:.2e}  bytes: VDB {vdb}, KTX2 {ktx}, EXR atlas {atlas}",
                    phase.name(),
                    err.rel_rmse,
                    mean_err,
                ));
                out.push(json!({
                    "suite": "bake", "scene": name, "resolution": res, "grid": p.grid.resolution.to_array(),
                    "phase": phase.name(), "anisotropy": p.medium.anisotropy, "image": [w, h],
                    "time_ms": bake_ms, "error_mean": err.rel_rmse, "mean_error": mean_err,
                    "texture_error_8bit": e8, "texture_error_half": e16,
                    "bytes": {"vdb_density_emission": vdb, "ktx2_rgba16f": ktx, "exr_atlas_rgba_half": atlas},
                }));
            }
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    Ok(())
}

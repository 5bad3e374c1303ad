//! Image-space sampling: the march of every demo, adaptive against per-pixel, at the editor's
//! default viewport (842×427) and at 1920×1080: rays marched per pixel, march time of each,
//! and the adaptive image's error against the per-pixel one (rel-RMSE, 99.9th-percentile and
//! largest pixel error over the image's maximum).
//!
//! The bake is done once per scene and size; each march is then run again alone (a change of
//! sampling re-marches the image and nothing else), alternating the two samplings, and the
//! faster of each one's runs is kept. [`stability`] measures the frame-to-frame change of each
//! sampling over a camera orbit and an animated sequence.

use super::context::Context;
use super::BenchError;
use crate::gpu::ImageSampling;
use crate::measure::image_difference;
use serde_json::{json, Value};

const SIZES: [(u32, u32); 2] = [(842, 427), (1920, 1080)];
/// Marches of each sampling per scene and size.
const RUNS: usize = 2;

pub(super) fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let scenes: Vec<String> = if !ctx.scenes.is_empty() {
        ctx.scenes.clone()
    } else if ctx.quick {
        vec!["cloud".into()]
    } else {
        crate::demos::DEMOS.iter().map(|(n, _)| n.to_string()).collect()
    };
    let sizes: &[(u32, u32)] = if ctx.quick { &SIZES[..1] } else { &SIZES };
    let adaptive = ImageSampling::default();
    for name in &scenes {
        let project = ctx.demo(name)?;
        for &(w, h) in sizes {
            ctx.gpu.set_image_sampling(ImageSampling::PerPixel);
            ctx.full(&project, w, h)?;
            let mut best = [f64::INFINITY; 2];
            let mut rays = [0u64; 2];
            let mut images = [None, None];
            for _ in 0..RUNS {
                for (k, sampling) in [ImageSampling::PerPixel, adaptive].into_iter().enumerate() {
                    // Switch away and back, so that every run re-marches.
                    ctx.gpu.set_image_sampling(if k == 0 { adaptive } else { ImageSampling::PerPixel });
                    ctx.gpu.set_image_sampling(sampling);
                    let report = ctx.incremental(&project, w, h)?;
                    best[k] = best[k].min(report.timings_ms.march);
                    rays[k] = report.counters.rays_marched;
                    if images[k].is_none() {
                        images[k] = Some(ctx.gpu.read_image()?);
                    }
                }
            }
            let [Some(per_pixel), Some(adaptive_image)] = &images else { unreachable!("both were read") };
            let d = image_difference(adaptive_image, per_pixel);
            let pixels = (w * h) as f64;
            log(&format!(
                "sampling {name:11} {w:4}×{h:<4}  per-pixel {:8.1} ms  adaptive {:8.1} ms ({:4.1}× faster, {:.3} rays/px)  rel-RMSE {:.3} %  p99.9 {:.3} % of max  max {:.2} % of max{}",
                best[0],
                best[1],
                best[0] / best[1],
                rays[1] as f64 / pixels,
                d.rel_rmse * 100.0,
                d.p999_of_max * 100.0,
                d.max_of_max * 100.0,
                if d.nan_or_inf { "  NaN!" } else { "" }
            ));
            out.push(json!({
                "suite": "march", "case": "image_sampling", "scene": name, "image": [w, h],
                "per_pixel_ms": best[0], "adaptive_ms": best[1], "speedup": best[0] / best[1],
                "rays_per_pixel": rays[1] as f64 / pixels, "per_pixel_rays": rays[0],
                "rel_rmse": d.rel_rmse, "p999_of_max": d.p999_of_max, "max_of_max": d.max_of_max,
                "nan_or_inf": d.nan_or_inf,
            }));
        }
    }
    ctx.gpu.set_image_sampling(ctx.image_sampling);
    Ok(())
}

/// Frames of each motion of the stability measure.
const MOTION_FRAMES: usize = 8;

/// Stability under motion: over a camera orbit (cloud, half a degree a frame) and over an
/// animated sequence (street-wind's first frames), the mean change between consecutive
/// frames of each sampling, and how far the adaptive change strays from the per-pixel one
/// (mean |Δ adaptive − Δ per-pixel| over mean |Δ per-pixel|): a sample pattern that crawls or
/// flickers adds change of its own.
pub(super) fn stability(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let (w, h) = SIZES[0];
    let orbit_base = ctx.demo("cloud")?;
    let orbit: Vec<crate::scene::Project> = (0..MOTION_FRAMES)
        .map(|i| {
            let mut p = orbit_base.clone();
            let c = p.camera;
            let offset = c.position - c.target;
            let turn = glam::Quat::from_rotation_y((i as f32 * 0.5).to_radians());
            p.camera.position = c.target + turn * offset;
            p
        })
        .collect();
    let wind = crate::demos::demo("street-wind")?;
    let start = wind.animation.map_or(1, |a| a.start);
    let sequence: Vec<crate::scene::Project> = (0..MOTION_FRAMES as i32).map(|i| wind.at_frame(start + i)).collect();
    for (motion, frames) in [("cloud orbit", orbit), ("street-wind sequence", sequence)] {
        let mut images: [Vec<crate::gpu::Image>; 2] = [Vec::new(), Vec::new()];
        for (k, sampling) in [ImageSampling::PerPixel, ImageSampling::default()].into_iter().enumerate() {
            ctx.gpu.set_image_sampling(sampling);
            for p in &frames {
                ctx.incremental(p, w, h)?;
                images[k].push(ctx.gpu.read_image()?);
            }
        }
        let (mut change, mut stray, mut base) = ([0.0f64; 2], 0.0f64, 0.0f64);
        for i in 1..frames.len() {
            let (p0, p1, a0, a1) = (&images[0][i - 1], &images[0][i], &images[1][i - 1], &images[1][i]);
            for j in 0..p0.rgba.len() {
                for c in 0..3 {
                    let dp = (p1.rgba[j][c] - p0.rgba[j][c]) as f64;
                    let da = (a1.rgba[j][c] - a0.rgba[j][c]) as f64;
                    change[0] += dp.abs();
                    change[1] += da.abs();
                    stray += (da - dp).abs();
                    base += p1.rgba[j][c] as f64;
                }
            }
        }
        let relative = |x: f64| if base > 0.0 { x / base } else { x };
        let extra = if change[0] > 0.0 { stray / change[0] } else { 0.0 };
        log(&format!(
            "stability {motion:21} {w}×{h}, {MOTION_FRAMES} frames: change per frame (of the mean) per-pixel {:.3} %, adaptive {:.3} %; adaptive strays from the per-pixel change by {:.1} % of it",
            relative(change[0]) * 100.0,
            relative(change[1]) * 100.0,
            extra * 100.0
        ));
        out.push(json!({
            "suite": "march", "case": "stability", "motion": motion, "image": [w, h], "frames": MOTION_FRAMES,
            "change_per_pixel": relative(change[0]), "change_adaptive": relative(change[1]), "stray_of_change": extra,
        }));
    }
    ctx.gpu.set_image_sampling(ctx.image_sampling);
    Ok(())
}

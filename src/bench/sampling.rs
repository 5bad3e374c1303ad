//! Image-space sampling: the march of every demo, adaptive against per-pixel, at the editor's
//! default viewport (842×427) and at 1920×1080: rays marched per pixel, march time of each,
//! and the adaptive image's error against the per-pixel one (rel-RMSE, 99.9th-percentile and
//! largest pixel error over the image's maximum).
//!
//! The bake is done once per scene and size; each march is then run again alone (a change of
//! sampling re-marches the image and nothing else), alternating the two samplings, and the
//! faster of each one's runs is kept.

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
    ctx.gpu.set_image_sampling(ImageSampling::default());
    Ok(())
}

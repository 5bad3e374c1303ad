//! `bench --suite scattering`: multiple scattering's error against its cost on each demo at
//! the interaction benchmark's viewport (842×427). Per setting (orders, coarse resolution):
//! the solve's time beside a full update's propagation and march (warm pipelines, so no shader
//! compilation), and its error against the solver's own converged solution (32 orders, the
//! finest coarse grid the device holds): the relative difference of the added light and the
//! relative RMSE of the image (physics.md §8). The comparison with a path tracer's every order
//! is `tests/mitsuba_reference.rs` and `docs/bench/scattering`.

use super::context::Context;
use super::BenchError;
use crate::gpu::Image;
use crate::measure::image_error;
use crate::scene::{MultipleScattering, Project};
use serde_json::{json, Value};

/// The viewport of the interaction benchmark.
const VIEWPORT: (u32, u32) = (842, 427);

fn rgb(image: &Image) -> Vec<[f64; 3]> {
    image.rgba.iter().map(|p| [p[0] as f64, p[1] as f64, p[2] as f64]).collect()
}

fn mean(image: &Image) -> f64 {
    image.rgba.iter().map(|p| (p[0] + p[1] + p[2]) as f64 / 3.0).sum::<f64>() / image.rgba.len().max(1) as f64
}

fn with(project: &Project, ms: Option<MultipleScattering>) -> Project {
    let mut p = project.clone();
    p.medium.multiple_scattering = ms;
    p
}

/// The largest `resolution` whose coarse grid's radiance the device can bind.
fn finest(ctx: &Context, project: &Project) -> u32 {
    let limit = ctx.gpu.context().max_binding_bytes();
    (4..=128)
        .rev()
        .find(|&resolution| {
            let f = MultipleScattering { resolution, ..Default::default() }.factor(&project.grid);
            project.grid.resolution.map(|n| n.div_ceil(f)).as_u64vec3().element_product() * 16 * 48 <= limit
        })
        .unwrap_or(4)
}

pub(super) fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let scenes: Vec<String> = if ctx.scenes.is_empty() {
        crate::demos::DEMOS.iter().map(|(name, _)| name.to_string()).collect()
    } else {
        ctx.scenes.clone()
    };
    let settings: &[(u32, u32)] =
        if ctx.quick { &[(12, 24)] } else { &[(4, 16), (8, 16), (8, 24), (12, 24), (16, 24), (12, 32)] };
    let (w, h) = VIEWPORT;
    for name in &scenes {
        let base = ctx.demo(name)?;
        let reference_res = finest(ctx, &base);
        let reference = with(&base, Some(MultipleScattering { orders: 32, resolution: reference_res, strength: 1.0 }));
        ctx.full(&reference, w, h)?;
        let converged_image = ctx.gpu.read_image()?;
        let converged = rgb(&converged_image);
        ctx.full(&with(&base, None), w, h)?;
        let single = ctx.gpu.read_image()?;
        let added_reference = mean(&converged_image) - mean(&single);
        let single_error = image_error(&single, &converged);
        log(&format!(
            "{name}: converged solution (32 orders, {reference_res} cells) adds {:.1} % to single scattering, whose rel-RMSE against it is {:.4}",
            100.0 * added_reference / mean(&single).max(1e-30),
            single_error.rel_rmse
        ));
        for &(orders, resolution) in settings {
            let p = with(&base, Some(MultipleScattering { orders, resolution, strength: 1.0 }));
            // The first update compiles what this setting needs; the second is timed.
            ctx.full(&p, w, h)?;
            let report = ctx.full(&p, w, h)?;
            let image = ctx.gpu.read_image()?;
            let t = report.timings_ms;
            let added = mean(&image) - mean(&single);
            let added_error = (added - added_reference) / added_reference.abs().max(1e-30);
            let e = image_error(&image, &converged);
            let share = t.scatter / (t.propagate + t.march).max(1e-9);
            log(&format!(
                "{name}: {orders} orders, {resolution} cells: solve {:.0} ms = {:.0} % of propagation + march ({:.0} + {:.0} ms); added light {:+.2} %, rel-RMSE {:.4}",
                t.scatter,
                100.0 * share,
                t.propagate,
                t.march,
                100.0 * added_error,
                e.rel_rmse
            ));
            out.push(json!({
                "suite": "scattering",
                "scene": name,
                "width": w,
                "height": h,
                "orders": orders,
                "resolution": resolution,
                "reference_resolution": reference_res,
                "scatter_ms": t.scatter,
                "propagate_ms": t.propagate,
                "march_ms": t.march,
                "share_of_update": share,
                "added_light_error": added_error,
                "rel_rmse": e.rel_rmse,
                "single_rel_rmse": single_error.rel_rmse,
                "gain_over_single": mean(&image) / mean(&single).max(1e-30),
            }));
        }
    }
    Ok(())
}

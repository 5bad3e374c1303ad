//! `fogsmith verify`: how far this project's bake and render are from the exact reference.

use crate::gpu::{FogPipeline, FrameRequest, GpuContext};
use crate::measure::{ev_error_with, image_error, opv_errors_with, sample_cells, EV_REL_THRESHOLD};
use crate::reference::{render_reference_with, Medium64, RefRenderOptions};
use crate::scene::{load_project_with, Scheme};
use std::path::Path;
use std::time::Instant;

pub fn run(
    path: &Path,
    scheme: Option<Scheme>,
    width: u32,
    max_cells: usize,
    frame: Option<i32>,
    json: bool,
    quiet: bool,
) -> Result<(), Box<dyn std::error::Error>> {
    let mut bar = super::progress::Bar::new(quiet);
    let project = load_project_with(path, &mut |step, fraction| bar.stage(&format!("load: {step}"), fraction))?;
    // One frame of an animated project: --frame, else its first.
    let (frames, _) = super::frames(&project, path, frame.map(|f| f.to_string()).as_deref(), "--frame")?;
    let mut project = super::still(&project, frames[0]);
    // The exact reference is single scattering: the image is compared without the other orders
    // (tests/mitsuba_reference.rs checks those against a path tracer).
    let multiple_scattering = project.medium.multiple_scattering.take().is_some();
    if width == 0 || width > 4096 {
        return Err(format!("--width must be within 1..=4096, got {width}").into());
    }
    let height = ((width as f32 * project.render.height as f32 / project.render.width as f32).round() as u32).max(1);
    let mut request = FrameRequest::for_project(&project);
    request.scheme = scheme.unwrap_or(request.scheme);
    request.width = width;
    request.height = height;
    let ctx = GpuContext::new_headless()?;
    let adapter = ctx.adapter_summary();
    let mut gpu = FogPipeline::new(ctx);
    gpu.check_limits(&project, width, height)?;
    // The base volume, resampled and scaled once: the GPU injects these values and the exact
    // medium holds the same ones, trilinear between cell centres as the EV is read.
    let layer = crate::export::load_base_layer(&project, Some(path))?;
    let exact = Medium64::for_project(&project, layer.as_ref());
    gpu.set_base_layer(layer);
    let report =
        match gpu.update_with(&project, &request, std::time::Duration::from_millis(100), &mut |p| bar.pipeline(p)) {
            Err(crate::gpu::GpuError::Cancelled) => return Err(super::progress::Cancelled.into()),
            other => other?,
        };
    bar.stage("exact reference", 0.0);

    let started = Instant::now();
    let cells = sample_cells(&project.grid, max_cells.max(8));
    let ev = gpu.read_ev()?;
    let (ev_err, ev_abs) = ev_error_with(&exact, &project, &ev, &cells);
    let mut opv = Vec::new();
    // Hidden, dark and culled lights have no optical-depth volume to compare.
    let mut without_opv = Vec::new();
    for (light, l) in project.lights.iter().enumerate() {
        if crate::gpu::light_has_opv(&project, l) {
            opv.push(opv_errors_with(&project, &exact, light, &ev, &gpu.read_opv(light)?, &cells));
        } else {
            without_opv.push(light);
        }
    }
    let image = gpu.read_image()?;
    let reference = render_reference_with(&project, &exact, width, height, &RefRenderOptions::default());
    let img_err = image_error(&image, &reference);
    let reference_ms = started.elapsed().as_secs_f64() * 1e3;
    let sampled = (cells.len() as u64) < project.grid.cell_count();
    bar.finish();
    super::progress::check()?;

    if json {
        let v = serde_json::json!({
            "project": path,
            "scheme": request.scheme.to_string(),
            "grid": project.grid.resolution.to_array(),
            "base_volume": exact.has_layer(),
            "ev_max_rel_error": ev_err,
            "ev_rel_threshold": EV_REL_THRESHOLD,
            "ev_max_abs_error": ev_abs,
            "opv": opv,
            "lights_without_opv": without_opv,
            "image_rel_rmse": img_err.rel_rmse,
            "multiple_scattering_left_out": multiple_scattering,
            "image_max_abs_error": img_err.max_abs_error,
            "image_size": [width, height],
            "cells_compared": cells.len(),
            "cells_sampled": sampled,
            "gpu_timings_ms": report.timings_ms,
            "reference_ms": reference_ms,
            "adapter": adapter,
        });
        println!("{}", serde_json::to_string(&v)?);
    } else {
        println!(
            "{} ({} scheme, {} grid{}) on {adapter}",
            path.display(),
            request.scheme,
            fmt_grid(&project),
            if exact.has_layer() { ", with its base volume" } else { "" }
        );
        if multiple_scattering {
            println!("multiple scattering left out: the exact reference is single scattering");
        }
        println!(
            "EV max relative error {ev_err:.3e} (where σ_t ≥ {EV_REL_THRESHOLD} /m), max absolute error {ev_abs:.3e} /m ({} cells{})",
            cells.len(),
            if sampled { ", sampled" } else { "" }
        );
        for e in &opv {
            println!(
                "light {}: transmittance max abs error: scheme {:.3e} (mean {:.3e}), resolution {:.3e} (mean {:.3e}), total {:.3e}",
                e.light,
                e.scheme.transmittance_max_abs_error,
                e.scheme.transmittance_mean_abs_error,
                e.resolution.transmittance_max_abs_error,
                e.resolution.transmittance_mean_abs_error,
                e.total.transmittance_max_abs_error,
            );
        }
        for l in &without_opv {
            println!("light {l}: no optical-depth volume (hidden, dark, or its light cannot reach the grid)");
        }
        println!("  scheme: the OPV against the line integral through the grid's trilinear medium (base fog outside the box)");
        println!("  resolution: that grid medium against the analytic gaussians (and base volume) clipped to the box");
        println!(
            "image {width}×{height}: relative RMSE {:.3e}, max abs error {:.3e}",
            img_err.rel_rmse, img_err.max_abs_error
        );
    }
    Ok(())
}

fn fmt_grid(p: &crate::scene::Project) -> String {
    let r = p.grid.resolution;
    format!("{}×{}×{}", r.x, r.y, r.z)
}

//! The benchmark suites. Every measurement forces the stages it times to rerun and reads
//! their GPU time (timestamp queries where available).

use super::context::{image_size, with_resolution, Context, OPV_SCHEMES};
use super::BenchError;
use crate::gpu::FrameReport;
use crate::measure::{depth_error, image_error, opv_error_against, sample_cells};
use crate::reference::sun::{f_exact, table_error, table_error_paper_metric, FTable, Interp, TableLayout};
use crate::reference::{
    clipped_optical_depth_cells, grid_light_depth_cells, render_reference, GridMedium64, RefRenderOptions,
};
use crate::rng::Lcg;
use crate::scene::{Ground, Light, LightKind, Noise, Particle, Project, Scheme, StepPolicy, SurfaceBox};
use glam::{UVec3, Vec3};
use serde_json::{json, Value};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    Opv,
    /// Image sampling (adaptive against per-pixel, every demo at 842×427 and 1920×1080; see
    /// `sampling`), then step policies against the reference.
    March,
    /// The image-sampling part of `march` alone.
    Sampling,
    Sun,
    Scaling,
    /// Time and memory growth up to a million particles, 256³–384³ grids and 16 lights
    /// (see `scale`; run on request only: it takes long on software adapters).
    Scale,
    /// The editor under scripted input (not part of the default run: it needs the editor's
    /// frame loop and takes about a minute per quality mode).
    Interaction,
    /// Light kinds (point, spot, sun) and medium features (height fog, noise, surfaces) on one
    /// small scene: bake-and-render time against OPV and image error, per grid resolution.
    Kinds,
    /// Propagation cost per cell by grid shape: a cube against wide, thin grids of the same
    /// cell count (see `shapes`; run on request only: its full grids take minutes).
    Shapes,
    /// Frame sequences of the cloud demo, one kind of motion each: the time per frame of one
    /// pipeline baking them in order against cold bakes (see `animation`).
    Animation,
    /// The light bake on each demo (fog only): time, error of its emission–absorption render
    /// against the lit render per phase mode, output sizes, texture quantisation error.
    Bake,
    /// Multiple scattering on each demo: the solve's time against a full update's and its
    /// error against its converged solution, per number of orders and coarse resolution (see
    /// `scattering`).
    Scattering,
}

/// The demo without its noise: the exact optical depth of noisy particles is an adaptive
/// quadrature, too slow for the scheme and step-policy sweeps over whole demos (the `kinds`
/// suite measures noise on a small scene).
fn smooth_demo(ctx: &Context, name: &str) -> Result<Project, BenchError> {
    let mut p = ctx.demo(name)?;
    p.medium.noise = None;
    Ok(p)
}

pub(super) fn opv(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let scenes: Vec<String> = if !ctx.scenes.is_empty() {
        ctx.scenes.clone()
    } else if ctx.quick {
        vec!["cornell".into()]
    } else {
        ["cornell", "cloud", "street"].map(String::from).to_vec()
    };
    let resolutions: Vec<u32> = if !ctx.resolutions.is_empty() {
        ctx.resolutions.clone()
    } else if ctx.quick {
        vec![32, 48]
    } else {
        vec![32, 48, 64, 96, 128]
    };
    let quick_labels = ["giroud", "sweep8", "sweep8r", "exact"];
    let schemes: Vec<(Scheme, u32, bool)> = OPV_SCHEMES
        .iter()
        .filter(|(_, label)| {
            if ctx.schemes.is_empty() {
                !ctx.quick || quick_labels.contains(label)
            } else {
                ctx.schemes.iter().any(|s| s == label)
            }
        })
        .map(|&(s, _)| s)
        .collect();
    let max_cells = if ctx.quick { 20_000 } else { 100_000 };
    for name in &scenes {
        let mut base = smooth_demo(ctx, name)?;
        // Suns have rows of their own (`opv_suns`): the schemes are compared on the other
        // lights here.
        opv_suns(ctx, &base, name, &resolutions, out, log)?;
        base.lights.retain(|l| !matches!(l.kind, LightKind::Directional { .. }));
        if base.lights.is_empty() {
            continue;
        }
        for &res in &resolutions {
            let project = with_resolution(&base, res);
            let cells = sample_cells(&project.grid, max_cells);
            // Scheme error: against the line integral through the grid's own medium (the
            // EV, the same for every scheme); resolution error: that medium against the
            // analytic gaussians clipped to the box.
            ctx.full(&project, 8, 8)?;
            let medium = GridMedium64::for_project(&project, &ctx.gpu.read_ev()?);
            let exact: Vec<Vec<f64>> =
                (0..project.lights.len()).map(|l| grid_light_depth_cells(&project, &medium, l, &cells)).collect();
            let analytic: Vec<Vec<f64>> =
                (0..project.lights.len()).map(|l| clipped_optical_depth_cells(&project, l, &cells)).collect();
            let resolution = exact
                .iter()
                .zip(&analytic)
                .enumerate()
                .map(|(l, (g, a))| depth_error(l, g, a).transmittance_max_abs_error)
                .fold(0.0f64, f64::max);
            for &(scheme, stride, refine) in &schemes {
                if scheme == Scheme::Analytic {
                    if let Some(what) = crate::gpu::analytic_unsupported(&project) {
                        log(&format!("opv    {name:8} {res:>3} analytic skipped: it cannot represent {what}"));
                        continue;
                    }
                }
                let mut p = project.clone();
                p.propagation.scheme = scheme;
                p.propagation.sweep_stride = stride;
                p.propagation.sweep_refine = refine;
                let (report, propagate_ms, runs) = median_propagation(ctx, &p)?;
                let (mut max, mut mean, mut truth) = (0.0f64, 0.0f64, 0.0f64);
                for (l, (ex, an)) in exact.iter().zip(&analytic).enumerate() {
                    let opv = ctx.gpu.read_opv(l)?;
                    let e = opv_error_against(l, &opv, &cells, ex);
                    max = max.max(e.transmittance_max_abs_error);
                    mean += e.transmittance_mean_abs_error / exact.len() as f64;
                    truth = truth.max(opv_error_against(l, &opv, &cells, an).transmittance_max_abs_error);
                }
                let label = match (scheme, refine) {
                    (Scheme::Sweep, false) => format!("sweep{stride}"),
                    (Scheme::Sweep, true) => format!("sweep{stride}r"),
                    _ => scheme.to_string(),
                };
                let r = project.grid.resolution;
                log(&format!(
                    "opv    {name:8} {:>3}×{:>3}×{:>3} {label:8} {propagate_ms:9.1} ms  scheme error mean {mean:.2e} max {max:.2e}  resolution error max {resolution:.2e}  vs analytic max {truth:.2e}  ({} passes, median of {runs})",
                    r.x, r.y, r.z, report.counters.propagation_iterations
                ));
                out.push(json!({
                    "suite": "opv", "scene": name, "scheme_or_policy": label, "resolution": res,
                    "grid": r.to_array(), "lights": p.lights.len(),
                    "time_ms": propagate_ms, "runs": runs, "error_mean": mean, "error_max": max, "error_vs_analytic_max": truth,
                    "resolution_error_max": resolution,
                    "samples": report.counters.cells_propagated,
                    "iterations": report.counters.propagation_iterations,
                    "cells_compared": cells.len(),
                }));
            }
        }
    }
    Ok(())
}

/// The sun rows of the propagation suite, for a scene with a sun: that sun alone, and a sun
/// from a direction drawn once at random, each by the plain and the refined directional sweep,
/// `exact` and `analytic`, GPU time against the error in transmittance against the grid's
/// own medium and against the gaussians clipped to the box.
fn opv_suns(
    ctx: &mut Context,
    base: &Project,
    name: &str,
    resolutions: &[u32],
    out: &mut Vec<Value>,
    log: &mut dyn FnMut(&str),
) -> Result<(), BenchError> {
    let Some(sun) = base.lights.iter().find(|l| matches!(l.kind, LightKind::Directional { .. })) else {
        return Ok(());
    };
    // Drawn once (an LCG from a fixed seed), so the rows are comparable between runs.
    let mut rng = Lcg(0x5EED_0036);
    let mut draw = || rng.f32() * 2.0 - 1.0;
    let random = Vec3::new(draw(), -draw().abs() - 0.1, draw()).normalize();
    let suns = [
        ("demo sun", sun.clone()),
        ("random sun", Light { kind: LightKind::Directional { direction: random }, ..sun.clone() }),
    ];
    let variants = [
        ("sun-sweep", Scheme::Sweep, false),
        ("sun-sweepr", Scheme::Sweep, true),
        ("sun-exact", Scheme::Exact, false),
        ("sun-analytic", Scheme::Analytic, false),
    ];
    let max_cells = if ctx.quick { 20_000 } else { 100_000 };
    for (which, light) in suns {
        let mut one = base.clone();
        one.lights = vec![light];
        for &res in resolutions {
            let project = with_resolution(&one, res);
            let cells = sample_cells(&project.grid, max_cells);
            ctx.full(&project, 8, 8)?;
            let medium = GridMedium64::for_project(&project, &ctx.gpu.read_ev()?);
            let exact = grid_light_depth_cells(&project, &medium, 0, &cells);
            let analytic = clipped_optical_depth_cells(&project, 0, &cells);
            for &(label, scheme, refine) in &variants {
                if scheme == Scheme::Analytic && crate::gpu::analytic_unsupported(&project).is_some() {
                    continue;
                }
                let mut p = project.clone();
                p.propagation.scheme = scheme;
                p.propagation.sweep_refine = refine;
                let (_, propagate_ms, runs) = median_propagation(ctx, &p)?;
                let opv = ctx.gpu.read_opv(0)?;
                let e = opv_error_against(0, &opv, &cells, &exact);
                let truth = opv_error_against(0, &opv, &cells, &analytic).transmittance_max_abs_error;
                let r = project.grid.resolution;
                log(&format!(
                    "opv    {name:8} {:>3}×{:>3}×{:>3} {which:10} {label:12} {propagate_ms:9.1} ms  scheme error mean {:.2e} max {:.2e}  vs analytic max {truth:.2e}  (median of {runs})",
                    r.x, r.y, r.z, e.transmittance_mean_abs_error, e.transmittance_max_abs_error
                ));
                out.push(json!({
                    "suite": "opv", "scene": name, "light": which, "scheme_or_policy": format!("{label} ({which})"), "resolution": res,
                    "grid": r.to_array(), "lights": 1, "direction": match p.lights[0].kind {
                        LightKind::Directional { direction } => direction.to_array(),
                        _ => [0.0; 3],
                    },
                    "time_ms": propagate_ms, "runs": runs,
                    "error_mean": e.transmittance_mean_abs_error, "error_max": e.transmittance_max_abs_error,
                    "error_vs_analytic_max": truth, "cells_compared": cells.len(),
                }));
            }
        }
    }
    Ok(())
}

/// Bakes `project` from scratch until its propagation has run for about a second (at most
/// five times): the median propagation time, with the last run's report. Single runs on a
/// software adapter vary by a third.
fn median_propagation(ctx: &mut Context, project: &Project) -> Result<(FrameReport, f64, usize), BenchError> {
    let mut times = Vec::new();
    loop {
        let report = ctx.full(project, 8, 8)?;
        times.push(report.timings_ms.propagate);
        if times.len() >= 5 || times.iter().sum::<f64>() >= 1000.0 {
            times.sort_by(f64::total_cmp);
            return Ok((report, times[times.len() / 2], times.len()));
        }
    }
}

pub(super) fn march(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let scenes: &[&str] = if ctx.quick { &["cornell"] } else { &["cornell", "cloud"] };
    let (res, width) = if ctx.quick { (32, 64) } else { (64, 128) };
    let pick = |v: &[f32]| -> Vec<f32> {
        if ctx.quick {
            vec![v[0], v[2], v[4]]
        } else {
            v.to_vec()
        }
    };
    let fixed = pick(&[2.0, 1.0, 0.5, 0.25, 0.125]);
    let two_level = pick(&[6.0, 12.0, 24.0, 48.0, 96.0]);
    let adaptive = pick(&[0.4, 0.2, 0.1, 0.05, 0.025]);
    for name in scenes {
        let mut project = with_resolution(&smooth_demo(ctx, name)?, res);
        project.propagation.scheme = Scheme::Sweep;
        let (w, h) = image_size(&project, width);
        let t = Instant::now();
        let reference = render_reference(&project, w, h, &RefRenderOptions::default());
        log(&format!("march  {name:8} reference {w}×{h} in {:.1} s", t.elapsed().as_secs_f64()));
        let mut cases: Vec<(String, f32, Project)> = Vec::new();
        for &f in &fixed {
            let mut p = project.clone();
            p.render.step_policy = StepPolicy::Fixed;
            p.render.step_factor = f;
            cases.push(("fixed".into(), f, p));
        }
        for &n in &two_level {
            let mut p = project.clone();
            p.render.step_policy = StepPolicy::TwoLevel;
            p.render.near_steps = n as u32;
            p.render.far_steps = (n / 2.0) as u32;
            cases.push(("two_level".into(), n, p));
        }
        for &tau in &adaptive {
            let mut p = project.clone();
            p.render.step_policy = StepPolicy::Adaptive;
            p.render.tau_target = tau;
            cases.push(("adaptive".into(), tau, p));
        }
        for cutoff in [1e-1f32, 1e-2, 1e-3, 0.0] {
            let mut p = project.clone();
            p.render.step_policy = StepPolicy::Adaptive;
            p.render.transmittance_cutoff = cutoff;
            cases.push(("adaptive_cutoff".into(), cutoff, p));
        }
        ctx.full(&project, w, h)?;
        for (policy, knob, p) in cases {
            // Only the render settings differ: the bake is reused and only the march reruns.
            let report = ctx.incremental(&p, w, h)?;
            let err = image_error(&ctx.gpu.read_image()?, &reference);
            let spp = report.counters.samples_marched as f64 / (w * h) as f64;
            log(&format!(
                "march  {name:8} {policy:15} {knob:<6} {:8.1} ms  {spp:7.1} samples/px  rel RMSE {:.2e}  max {:.2e}  ({} rays cut off)",
                report.timings_ms.march, err.rel_rmse, err.max_abs_error, report.counters.rays_terminated
            ));
            out.push(json!({
                "suite": "march", "scene": name, "scheme_or_policy": policy, "knob": knob, "resolution": res,
                "image": [w, h], "time_ms": report.timings_ms.march, "error_mean": err.rel_rmse,
                "error_max": err.max_abs_error, "samples": spp, "rays_terminated": report.counters.rays_terminated,
            }));
        }
    }
    Ok(())
}

/// Largest and mean relative error of the table's F against the exact F at the midpoints of
/// a 64×64 grid over the paper's domain u ∈ [0, 10], v ∈ [0, π/2].
fn f_error(table: &FTable, interp: Interp) -> (f64, f64) {
    let (mut max, mut sum, mut n) = (0.0f64, 0.0f64, 0usize);
    for i in 0..64 {
        for j in 0..64 {
            let u = (i as f64 + 0.5) / 64.0 * 10.0;
            let v = (j as f64 + 0.5) / 64.0 * std::f64::consts::FRAC_PI_2;
            let exact = f_exact(u, v);
            let e = ((table.lookup(u, v, interp) - exact) / exact).abs();
            max = max.max(e);
            sum += e;
            n += 1;
        }
    }
    (sum / n as f64, max)
}

pub(super) fn sun(quick: bool, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) {
    let sizes: &[usize] = if quick { &[16, 64, 256] } else { &[8, 16, 32, 64, 128, 256] };
    let samples = if quick { 300 } else { 2000 };
    for &n in sizes {
        for (layout, lname) in [(TableLayout::Paper, "paper"), (TableLayout::Remapped, "remapped")] {
            let t = Instant::now();
            let table = FTable::new(layout, n, n);
            let build_ms = t.elapsed().as_secs_f64() * 1e3;
            for (interp, iname) in [(Interp::Bilinear, "bilinear"), (Interp::Nearest, "nearest")] {
                let (mean, max) = table_error(&table, interp, samples);
                let (pm_mean, pm_max) = table_error_paper_metric(&table, interp, samples);
                let (f_mean, f_max) = f_error(&table, interp);
                log(&format!(
                    "sun    {lname:8} {iname:8} {n:>3}²  L_a rel error mean {mean:.2e} max {max:.2e}  paper metric mean {pm_mean:.2e}  F rel error max {f_max:.2e}"
                ));
                out.push(json!({
                    "suite": "sun", "scheme_or_policy": format!("{lname}_{iname}"), "resolution": n,
                    "time_ms": build_ms, "error_mean": mean, "error_max": max,
                    "paper_metric_mean": pm_mean, "paper_metric_max": pm_max,
                    "f_error_mean": f_mean, "f_error_max": f_max, "samples": samples,
                }));
            }
        }
    }
}

/// `count` particles of equal density whose total volume is constant: radius ∝ count^(-1/3).
fn particle_scene(count: usize, lights: usize, res: u32) -> Project {
    let mut p = Project::default();
    p.grid.min = Vec3::splat(-1.0);
    p.grid.max = Vec3::splat(1.0);
    p.grid.resolution = UVec3::splat(res);
    p.medium.base_extinction = 0.0;
    let side = (count as f64).cbrt().ceil() as usize;
    let radius = 0.35 / (count as f32).cbrt();
    let mut rng = Lcg(12345);
    let mut rnd = || rng.f32();
    for n in 0..count {
        let (i, j, k) = (n % side, (n / side) % side, n / (side * side));
        let cell = 1.4 / side as f32;
        let c = Vec3::new(i as f32, j as f32, k as f32) * cell - 0.7
            + cell * 0.5
            + (Vec3::new(rnd(), rnd(), rnd()) - 0.5) * cell * 0.5;
        p.particles.push(Particle::new(c, radius, 3.0));
    }
    p.lights = (0..lights)
        .map(|l| {
            let a = l as f32 / lights as f32 * std::f32::consts::TAU;
            Light::new(Vec3::new(0.8 * a.cos(), 0.85, 0.8 * a.sin()), 4.0, Vec3::ONE)
        })
        .collect();
    p.camera.position = Vec3::new(0.4, 0.6, 3.5);
    p.camera.target = Vec3::ZERO;
    p
}

fn stage_json(r: &FrameReport) -> Value {
    json!({"inject": r.timings_ms.inject, "propagate": r.timings_ms.propagate, "march": r.timings_ms.march})
}

fn total_ms(r: &FrameReport) -> f64 {
    r.timings_ms.inject + r.timings_ms.propagate + r.timings_ms.march
}

/// One dynamic (everything) and one static (camera moved) update of `p`.
fn dynamic_and_static(
    ctx: &mut Context,
    p: &Project,
    w: u32,
    h: u32,
) -> Result<(FrameReport, FrameReport), BenchError> {
    let dynamic = ctx.full(p, w, h)?;
    let mut moved = p.clone();
    moved.camera.position.x += 0.05;
    let stat = ctx.incremental(&moved, w, h)?;
    Ok((dynamic, stat))
}

/// Least-squares slope of log(y) against log(x).
pub(super) fn loglog_slope(points: &[(f64, f64)]) -> f64 {
    let pts: Vec<(f64, f64)> =
        points.iter().filter(|(x, y)| *x > 0.0 && *y > 0.0).map(|(x, y)| (x.ln(), y.ln())).collect();
    let n = pts.len() as f64;
    if n < 2.0 {
        return f64::NAN;
    }
    let (sx, sy) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
    let (mx, my) = (sx / n, sy / n);
    let num: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let den: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    num / den
}

pub(super) fn scaling(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let (w, h) = if ctx.quick { (64, 36) } else { (128, 72) };
    let resolutions: &[u32] = if ctx.quick { &[16, 32, 64] } else { &[16, 32, 64, 128] };
    let light_counts: &[usize] = if ctx.quick { &[1, 4] } else { &[1, 2, 4, 8, 16] };
    let record =
        |out: &mut Vec<Value>, case: &str, res: u32, lights: usize, particles: usize, r: &FrameReport, extra: Value| {
            let mut v = json!({
                "suite": "scaling", "case": case, "resolution": res, "lights": lights, "particles": particles,
                "time_ms": total_ms(r), "stage_ms": stage_json(r),
                "samples": r.counters.samples_marched, "cells_injected": r.counters.cells_injected,
                "lights_propagated": r.counters.lights_propagated,
            });
            if let (Some(o), Value::Object(e)) = (v.as_object_mut(), extra) {
                o.extend(e);
            }
            out.push(v);
        };
    let mut by_lights: Vec<(usize, Vec<(f64, f64)>)> = Vec::new();
    for &lights in light_counts {
        let mut points = Vec::new();
        for &res in resolutions {
            let p = particle_scene(1000, lights, res);
            if let Err(e) = ctx.gpu.check_limits(&p, w, h) {
                log(&format!("scaling {res}³ × {lights} lights skipped: {e}"));
                continue;
            }
            let (d, s) = dynamic_and_static(ctx, &p, w, h)?;
            log(&format!(
                "scaling {res:>3}³ {lights:>2} lights  dynamic {:9.1} ms (inject {:.1}, propagate {:.1}, march {:.1})  static {:7.1} ms",
                total_ms(&d), d.timings_ms.inject, d.timings_ms.propagate, d.timings_ms.march, total_ms(&s)
            ));
            record(out, "dynamic", res, lights, 1000, &d, json!({}));
            record(out, "static", res, lights, 1000, &s, json!({}));
            points.push(((res as f64).powi(3), d.timings_ms.inject + d.timings_ms.propagate));
        }
        by_lights.push((lights, points));
    }
    for (lights, points) in &by_lights {
        let slope = loglog_slope(points);
        log(&format!(
            "scaling fit: bake time ∝ cells^{slope:.2} with {lights} lights (O(N³) per light means exponent 1)"
        ));
        out.push(json!({"suite": "scaling_fit", "case": "bake_vs_cells", "lights": lights, "exponent": slope}));
    }

    let res = if ctx.quick { 32 } else { 64 };
    let counts: &[usize] = if ctx.quick { &[1, 1000, 27000] } else { &[1, 125, 1000, 8000, 27000, 100_000] };
    let mut inject_points = Vec::new();
    for &count in counts {
        let p = particle_scene(count, 2, res);
        let (d, s) = dynamic_and_static(ctx, &p, w, h)?;
        log(&format!(
            "scaling {res}³ {count:>6} particles  dynamic {:9.1} ms (inject {:.2})  static {:7.1} ms",
            total_ms(&d),
            d.timings_ms.inject,
            total_ms(&s)
        ));
        record(out, "dynamic", res, 2, count, &d, json!({}));
        record(out, "static", res, 2, count, &s, json!({}));
        inject_points.push((count as f64, d.timings_ms.inject));
        if count <= 27_000 {
            ctx.gpu.set_brute_force_injection(true);
            let brute = ctx.full(&p, w, h)?;
            ctx.gpu.set_brute_force_injection(false);
            log(&format!(
                "injection {count:>6} particles  binned {:.2} ms  brute force {:.2} ms",
                d.timings_ms.inject, brute.timings_ms.inject
            ));
            out.push(json!({
                "suite": "injection", "scheme_or_policy": "binned", "resolution": res, "particles": count,
                "time_ms": d.timings_ms.inject, "samples": d.counters.particle_evaluations,
            }));
            out.push(json!({
                "suite": "injection", "scheme_or_policy": "brute_force", "resolution": res, "particles": count,
                "time_ms": brute.timings_ms.inject, "samples": brute.counters.particle_evaluations,
            }));
        }
    }
    let slope = loglog_slope(&inject_points[1..]);
    log(&format!("scaling fit: binned injection time ∝ particles^{slope:.2} at constant covered volume"));
    out.push(json!({"suite": "scaling_fit", "case": "inject_vs_particles", "exponent": slope}));

    // Empty-space skipping on and off, on the demos and on a scene whose fog fills one corner
    // (with base fog every brick holds extinction, so nothing can be skipped).
    let mut scenes: Vec<(String, Project)> = Vec::new();
    for name in ["cornell", "cloud", "street"] {
        scenes.push((name.into(), with_resolution(&ctx.demo(name)?, res)));
    }
    let mut sparse = particle_scene(27, 2, res);
    for q in &mut sparse.particles {
        q.center = q.center * 0.3 - 0.55;
        q.radius *= 0.4;
    }
    scenes.push(("sparse".into(), sparse));
    for (name, p) in scenes {
        let (w, h) = image_size(&p, w);
        let mut results = Vec::new();
        for skip in [false, true] {
            let mut q = p.clone();
            q.render.skip_empty = skip;
            let r = ctx.full(&q, w, h)?;
            results.push((skip, r));
        }
        for (skip, r) in &results {
            out.push(json!({
                "suite": "skipping", "scene": name, "scheme_or_policy": if *skip { "skip_empty" } else { "no_skip" },
                "resolution": res, "time_ms": r.timings_ms.march, "samples": r.counters.samples_marched,
                "bricks_skipped": r.counters.bricks_skipped,
            }));
        }
        let (off, on) = (&results[0].1, &results[1].1);
        log(&format!(
            "skipping {name:8} samples {} -> {} ({:.2}×), march {:.1} -> {:.1} ms",
            off.counters.samples_marched,
            on.counters.samples_marched,
            off.counters.samples_marched as f64 / on.counters.samples_marched.max(1) as f64,
            off.timings_ms.march,
            on.timings_ms.march
        ));
    }
    Ok(())
}

/// The variants of the `kinds` suite: one scene of 27 particles and one light, changed in one
/// respect each.
fn kind_variants(res: u32) -> Vec<(&'static str, Project)> {
    let base = particle_scene(27, 1, res);
    let towards = (Vec3::ZERO - base.lights[0].position).normalize();
    let mut out = vec![("point", base.clone())];
    let mut p = base.clone();
    p.lights[0].kind = LightKind::Spot { direction: towards, angle_deg: 20.0, blend: 0.3 };
    p.lights[0].intensity = 8.0;
    out.push(("spot", p));
    let mut p = base.clone();
    p.lights[0].kind = LightKind::Directional { direction: Vec3::new(-0.5, -1.0, -0.3) };
    out.push(("sun", p));
    let mut p = base.clone();
    p.medium.base_extinction = 0.3;
    p.medium.height_falloff = 1.5;
    p.medium.height_origin = -1.0;
    out.push(("height fog", p));
    let mut p = base.clone();
    // Octaves coarse enough for every resolution of the suite, so one exact image serves all.
    p.medium.noise = Some(Noise::new(1.5, 1.5, 2, 1));
    out.push(("noise", p));
    let mut p = base;
    p.surfaces.ground = Some(Ground { height: -1.0, specular: 0.3, ..Default::default() });
    p.surfaces.boxes.push(SurfaceBox {
        min: Vec3::new(-0.3, -1.0, -0.9),
        max: Vec3::new(0.3, -0.5, -0.4),
        ..Default::default()
    });
    out.push(("surfaces", p));
    out
}

pub(super) fn kinds(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let resolutions: Vec<u32> = if !ctx.resolutions.is_empty() {
        ctx.resolutions.clone()
    } else if ctx.quick {
        vec![24, 48]
    } else {
        vec![24, 48, 96]
    };
    let (w, h) = if ctx.quick { (48, 27) } else { (96, 54) };
    let max_cells = if ctx.quick { 4_000 } else { 20_000 };
    let mut references: Vec<Vec<[f64; 3]>> = Vec::new();
    for (i, &res) in resolutions.iter().enumerate() {
        for (v, (name, p)) in kind_variants(res).into_iter().enumerate() {
            if i == 0 {
                // The exact image does not depend on the grid's resolution.
                let t = Instant::now();
                references.push(render_reference(&p, w, h, &RefRenderOptions::default()));
                log(&format!("kinds  {name:10} reference {w}×{h} in {:.1} s", t.elapsed().as_secs_f64()));
            }
            let report = ctx.full(&p, w, h)?;
            let cells = sample_cells(&p.grid, max_cells);
            let ev = ctx.gpu.read_ev()?;
            let e = crate::measure::opv_errors(&p, 0, &ev, &ctx.gpu.read_opv(0)?, &cells);
            let img = image_error(&ctx.gpu.read_image()?, &references[v]);
            log(&format!(
                "kinds  {name:10} {res:>3}³ {:8.1} ms (inject {:.1}, propagate {:.1}, march {:.1})  OPV error max {:.2e} (scheme {:.2e})  image rel RMSE {:.2e}",
                total_ms(&report),
                report.timings_ms.inject,
                report.timings_ms.propagate,
                report.timings_ms.march,
                e.total.transmittance_max_abs_error,
                e.scheme.transmittance_max_abs_error,
                img.rel_rmse
            ));
            out.push(json!({
                "suite": "kinds", "scene": name, "resolution": res, "image": [w, h],
                "time_ms": total_ms(&report), "stages_ms": stage_json(&report),
                "error_max": e.total.transmittance_max_abs_error, "scheme_error_max": e.scheme.transmittance_max_abs_error,
                "error_mean": img.rel_rmse, "image_error_max": img.max_abs_error, "cells_compared": cells.len(),
            }));
        }
    }
    Ok(())
}

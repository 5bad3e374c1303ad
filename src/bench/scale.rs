//! The `scale` suite: how time and memory grow with particles, grid resolution and lights,
//! up to the sizes one storage binding used to refuse (a million small particles, 256³
//! grids with many lights). Each case bakes from scratch and records the stage times, the
//! GPU memory the pipeline's resources reached and the process's peak resident memory, then
//! fits the growth exponents by least squares on log–log axes. The file cases time what a
//! user's path adds around the bake: writing, loading, rendering as `fogsmith render` does
//! (sliced for its progress bar) and saving a project of 10⁴ to 10⁶ particles, with the
//! plain RON text of the same project for comparison.

use super::context::{small_particle_scene, Context};
use super::suites::loglog_slope;
use super::BenchError;
use crate::gpu::{FrameReport, InjectPath, OpvLayout};
use crate::scene::Project;
use serde_json::{json, Value};

/// Peak resident memory of this process in bytes (VmHWM), where the OS reports it.
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
}

/// Resets the peak resident memory to the current one (Linux), so the next reading is the
/// peak of one case. Returns whether it could.
fn reset_peak_rss() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// Bakes `p` from scratch on a fresh pipeline (so buffers grown by earlier cases do not
/// count) and returns its record.
fn case(ctx: &mut Context, kind: &str, p: &Project, w: u32, h: u32) -> Result<(FrameReport, Value), BenchError> {
    case_with(ctx, kind, p, w, h, None, InjectPath::Auto)
}

/// [`case`] with at most `lights_per_texture` optical-depth volumes in one texture and the
/// particles summed where `path` says.
fn case_with(
    ctx: &mut Context,
    kind: &str,
    p: &Project,
    w: u32,
    h: u32,
    lights_per_texture: Option<u32>,
    path: InjectPath,
) -> Result<(FrameReport, Value), BenchError> {
    let gpu = ctx.gpu.context().clone();
    let layout = match lights_per_texture {
        Some(n) => OpvLayout::with_lights_per_texture(&gpu.limits, n),
        None => OpvLayout::for_limits(&gpu.limits),
    };
    ctx.gpu = crate::gpu::FogPipeline::with_opv_layout(gpu, layout);
    ctx.gpu.set_inject_path(path);
    let on_host = ctx.gpu.inject_on_host(p);
    let rss_reset = reset_peak_rss();
    let t = std::time::Instant::now();
    let r = ctx.full(p, w, h)?;
    let wall = t.elapsed().as_secs_f64() * 1e3;
    let v = json!({
        "suite": "scale", "case": kind, "resolution": p.grid.resolution.x, "lights": p.lights.len(),
        "particles": p.particles.len(), "cells": p.grid.cell_count(),
        "time_ms": r.timings_ms.inject + r.timings_ms.propagate + r.timings_ms.march, "wall_ms": wall,
        "stage_ms": {"inject": r.timings_ms.inject, "propagate": r.timings_ms.propagate, "march": r.timings_ms.march},
        "particle_evaluations": r.counters.particle_evaluations, "inject_chunks": r.counters.inject_chunks,
        "inject_path": if on_host { "host" } else { "adapter" },
        "gpu_peak_bytes": ctx.gpu.peak_memory_bytes(),
        "rss_peak_bytes": if rss_reset { peak_rss_bytes() } else { None },
        "rss_peak_is_process_lifetime": !rss_reset,
    });
    Ok((r, v))
}

fn mib(v: &Value, key: &str) -> f64 {
    v[key].as_f64().unwrap_or(f64::NAN) / (1u64 << 20) as f64
}

/// Seconds since `t`.
fn secs(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64()
}

/// The total size in bytes of the project file at `path` and its particle sidecars.
fn project_bytes(path: &std::path::Path) -> u64 {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let dir = path.parent().map(std::fs::read_dir);
    let sidecars: u64 = dir
        .and_then(Result::ok)
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| crate::scene::sidecar::is_sidecar_of(&name, &e.file_name().to_string_lossy()))
        .filter_map(|e| e.metadata().ok().map(|m| m.len()))
        .sum();
    std::fs::metadata(path).map_or(0, |m| m.len()) + sidecars
}

/// The file cases (see the module doc), on a 128³ grid with 2 lights like a user's scene.
fn files(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    use crate::scene::{load_project, parse_project, save_project};
    let counts: &[usize] = if ctx.quick { &[10_000, 100_000] } else { &[10_000, 100_000, 1_000_000] };
    let dir = std::env::temp_dir().join(format!("fogsmith-scale-files-{}", std::process::id()));
    let write_err = |e: std::io::Error| BenchError::Write { path: dir.clone(), message: e.to_string() };
    std::fs::create_dir_all(&dir).map_err(write_err)?;
    let (w, h) = (96, 54);
    for &n in counts {
        let mut p = small_particle_scene(n, 2, 128);
        p.ensure_unique_ids();
        let path = dir.join(format!("scale-{n}.ron"));
        // The whole project as RON text, as files held it before particle sidecars.
        let t = std::time::Instant::now();
        let text = crate::scene::io::to_ron_string(&p)?;
        let ron_write = secs(t);
        let t = std::time::Instant::now();
        let parsed = parse_project(&text, &path)?;
        let ron_parse = secs(t);
        drop(parsed);
        let t = std::time::Instant::now();
        save_project(&path, &p)?;
        let write = secs(t);
        let bytes = project_bytes(&path);
        let t = std::time::Instant::now();
        let loaded = load_project(&path)?;
        let load = secs(t);
        // As `fogsmith render`: load, a fresh pipeline, the bake in 100 ms slices, readback.
        let t = std::time::Instant::now();
        let project = load_project(&path)?;
        let mut gpu = crate::gpu::FogPipeline::new(ctx.gpu.context().clone());
        let on_host = gpu.inject_on_host(&project);
        let request =
            crate::gpu::FrameRequest { width: w, height: h, ..crate::gpu::FrameRequest::for_project(&project) };
        let r = gpu.update_with(&project, &request, std::time::Duration::from_millis(100), &mut |_| true)?;
        gpu.read_image()?;
        let render = secs(t);
        let stages = (r.timings_ms.inject + r.timings_ms.propagate + r.timings_ms.march) / 1e3;
        let t = std::time::Instant::now();
        save_project(&path, &loaded)?;
        let save = secs(t);
        log(&format!(
            "scale files {n:>8} particles  write {write:.2} s  load {load:.2} s  render {render:.2} s (stages {stages:.2} s, {:.2}×)  save {save:.2} s  ({:.1} MB)  RON alone: write {ron_write:.2} s, parse {ron_parse:.2} s ({:.1} MB)",
            render / stages.max(1e-9),
            bytes as f64 / 1e6,
            text.len() as f64 / 1e6
        ));
        out.push(json!({
            "suite": "scale", "case": "files", "particles": n, "resolution": 128, "lights": 2,
            "write_s": write, "load_s": load, "render_s": render, "stage_s": stages, "save_s": save,
            "stage_ms": {"inject": r.timings_ms.inject, "propagate": r.timings_ms.propagate, "march": r.timings_ms.march},
            "inject_path": if on_host { "host" } else { "adapter" },
            "file_bytes": bytes, "ron_bytes": text.len(), "ron_write_s": ron_write, "ron_parse_s": ron_parse,
        }));
    }
    let _ = std::fs::remove_dir_all(&dir);
    Ok(())
}

pub fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    files(ctx, out, log)?;
    let quick = ctx.quick;
    let (w, h) = (96, 54);
    let fit = |out: &mut Vec<Value>, log: &mut dyn FnMut(&str), case: &str, what: &str, points: &[(f64, f64)]| {
        let e = loglog_slope(points);
        log(&format!("scale fit: {what} ∝ x^{e:.2} ({case})"));
        out.push(json!({"suite": "scale_fit", "case": case, "exponent": e, "points": points.len()}));
    };

    // Particles: injection time should follow the particle–cell overlaps.
    let particle_res: &[u32] = if quick { &[64] } else { &[64, 128] };
    let counts: &[usize] = if quick { &[1_000, 10_000, 100_000] } else { &[1_000, 10_000, 100_000, 1_000_000] };
    for &res in particle_res {
        let (mut by_count, mut by_evals) = (Vec::new(), Vec::new());
        for &n in counts {
            let p = small_particle_scene(n, 1, res);
            let (r, v) = case(ctx, "particles", &p, w, h)?;
            log(&format!(
                "scale {res}³ {n:>8} particles  inject {:9.1} ms  ({} evaluations, {} chunks)  GPU peak {:.0} MiB  RSS peak {:.0} MiB",
                r.timings_ms.inject, r.counters.particle_evaluations, r.counters.inject_chunks, mib(&v, "gpu_peak_bytes"), mib(&v, "rss_peak_bytes")
            ));
            by_count.push((n as f64, r.timings_ms.inject));
            by_evals.push((r.counters.particle_evaluations as f64, r.timings_ms.inject));
            out.push(v);
        }
        // The largest case again on the adapter's gather, the path a software adapter no
        // longer takes: what summing on the host saves.
        let n = *counts.last().expect("particle counts");
        let p = small_particle_scene(n, 1, res);
        if ctx.gpu.inject_on_host(&p) {
            let (r, v) = case_with(ctx, "particles_adapter_path", &p, w, h, None, InjectPath::Adapter)?;
            log(&format!(
                "scale {res}³ {n:>8} particles  inject {:9.1} ms on the adapter's gather ({} evaluations, {} chunks)  GPU peak {:.0} MiB",
                r.timings_ms.inject, r.counters.particle_evaluations, r.counters.inject_chunks, mib(&v, "gpu_peak_bytes")
            ));
            out.push(v);
        }
        fit(out, log, &format!("inject_vs_particles_{res}"), "injection time vs particles", &by_count);
        fit(
            out,
            log,
            &format!("inject_vs_evaluations_{res}"),
            "injection time vs particle–cell evaluations",
            &by_evals,
        );
    }

    // Grids, 2 lights: the sweep is O(N³) per light, so time ∝ cells^1 is the ideal.
    let grids: &[u32] = if quick { &[32, 64, 96] } else { &[32, 64, 128, 192, 256, 384] };
    let mut by_cells = Vec::new();
    let mut mem_by_cells = Vec::new();
    for &res in grids {
        let p = small_particle_scene(2_000, 2, res);
        if let Err(e) = ctx.gpu.check_limits(&p, w, h) {
            log(&format!("scale {res}³ skipped: {e}"));
            out.push(json!({"suite": "scale", "case": "grid_refused", "resolution": res, "error": e.to_string()}));
            continue;
        }
        let (r, v) = case(ctx, "grid", &p, w, h)?;
        log(&format!(
            "scale {res:>3}³ 2 lights  bake {:9.1} ms (inject {:.1}, propagate {:.1}, march {:.1})  GPU peak {:.0} MiB  RSS peak {:.0} MiB",
            r.timings_ms.inject + r.timings_ms.propagate, r.timings_ms.inject, r.timings_ms.propagate, r.timings_ms.march,
            mib(&v, "gpu_peak_bytes"), mib(&v, "rss_peak_bytes")
        ));
        by_cells.push((p.grid.cell_count() as f64, r.timings_ms.inject + r.timings_ms.propagate));
        mem_by_cells.push((p.grid.cell_count() as f64, v["gpu_peak_bytes"].as_f64().unwrap_or(0.0)));
        out.push(v);
    }
    fit(out, log, "bake_vs_cells", "bake time vs cells", &by_cells);
    fit(out, log, "gpu_memory_vs_cells", "GPU peak memory vs cells", &mem_by_cells);

    // Lights: propagation should be linear in lights.
    let res = if quick { 64 } else { 128 };
    let lights: &[usize] = if quick { &[1, 2, 4] } else { &[1, 2, 4, 8, 16] };
    let mut by_lights = Vec::new();
    for &l in lights {
        let p = small_particle_scene(2_000, l, res);
        let (r, v) = case(ctx, "lights", &p, w, h)?;
        log(&format!(
            "scale {res}³ {l:>2} lights  propagate {:9.1} ms  march {:.1} ms  GPU peak {:.0} MiB",
            r.timings_ms.propagate,
            r.timings_ms.march,
            mib(&v, "gpu_peak_bytes")
        ));
        by_lights.push((l as f64, r.timings_ms.propagate));
        out.push(v);
    }
    fit(out, log, &format!("propagate_vs_lights_{res}"), "propagation time vs lights", &by_lights);

    // The cost of optical-depth volumes spread over several textures: the same scene with
    // every light's volume in one texture, and with one light per texture (every load and
    // store picks its texture).
    let p = small_particle_scene(2_000, 4, res);
    for (name, per) in [("one_texture", None), ("one_light_per_texture", Some(1))] {
        let (r, mut v) = case_with(ctx, "opv_textures", &p, w, h, per, InjectPath::Auto)?;
        v["scheme_or_policy"] = json!(name);
        log(&format!(
            "scale {res}³ 4 lights, OPV {name:22} propagate {:9.1} ms  march {:.1} ms",
            r.timings_ms.propagate, r.timings_ms.march
        ));
        out.push(v);
    }

    // The target: 256³ with 8 lights (several storage bindings of optical depth).
    if !quick {
        let p = small_particle_scene(2_000, 8, 256);
        let (r, v) = case(ctx, "target_256_8_lights", &p, w, h)?;
        log(&format!(
            "scale 256³ 8 lights  bake {:.1} ms (propagate {:.1}), march {:.1} ms  GPU peak {:.0} MiB  RSS peak {:.0} MiB",
            r.timings_ms.inject + r.timings_ms.propagate, r.timings_ms.propagate, r.timings_ms.march,
            mib(&v, "gpu_peak_bytes"), mib(&v, "rss_peak_bytes")
        ));
        out.push(v);
    }
    Ok(())
}

//! `bench --suite animation`: what baking a sequence in one pipeline saves over baking each
//! frame from scratch. The cloud demo at 64 cells on its longest axis is animated over 48
//! frames (12 with `--quick`) four times, each with one kind of motion: the sun turning, the
//! point light (the sky light) moving, every particle drifting, and the noise drifting in a
//! wind alone. Each motion is baked twice: as a sequence (frame after frame in one pipeline,
//! as `fogsmith render --frames` does) and cold (every frame forced from scratch in a second
//! pipeline, interleaved frame by frame with the sequence so that both see the same machine
//! load). A record holds the per-frame wall time of both, the stage times and the work
//! counters summed over frames 2.. (the sequence's first frame is a cold bake and is reported
//! apart).

use super::context::{image_size, with_resolution, Context};
use super::BenchError;
use crate::gpu::{Counters, FrameRequest, StageTimings};
use crate::scene::animation::{Animation, Channel, Interp, Key, KeyValue, Object, Prop, Track};
use crate::scene::{LightKind, Project};
use glam::Vec3;
use serde_json::{json, Value};
use std::time::Instant;

/// The kinds of motion, by record label.
const MOTIONS: [&str; 4] = ["sun", "point", "particles", "wind"];

/// A linear track from `a` at frame 1 to `b` at frame `end`.
fn ramp(on: Channel, a: Vec3, b: Vec3, end: i32) -> Track {
    let key = |frame, v| Key { frame, value: KeyValue::Vec3(v), interp: Interp::Linear };
    Track { on, keys: vec![key(1, a), key(end, b)] }
}

/// The cloud, without wind, animated over frames 1..=`frames` by `motion`.
fn animated(base: &Project, motion: &str, frames: i32) -> Project {
    let mut p = base.clone();
    p.animation = Some(Animation { fps: 24.0, start: 1, end: frames });
    p.tracks.clear();
    if let Some(n) = &mut p.medium.noise {
        n.velocity = Vec3::ZERO;
    }
    match motion {
        "sun" => {
            if let Some(l) = p.lights.iter().find(|l| matches!(l.kind, LightKind::Directional { .. })) {
                let LightKind::Directional { direction } = l.kind else { unreachable!() };
                // A quarter turn about the vertical over the sequence.
                let turned = glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2) * direction;
                p.tracks.push(ramp(Channel(Object::Light(l.id), Prop::SunDirection), direction, turned, frames));
            }
        }
        "point" => {
            if let Some(l) = p.lights.iter().find(|l| matches!(l.kind, LightKind::Point)) {
                let to = l.position + Vec3::new(3.0, 1.5, -2.0);
                p.tracks.push(ramp(Channel(Object::Light(l.id), Prop::Position), l.position, to, frames));
            }
        }
        "particles" => {
            for q in &base.particles {
                let to = q.center + Vec3::new(0.5, 0.1, 0.0);
                p.tracks.push(ramp(Channel(Object::Particle(q.id), Prop::Center), q.center, to, frames));
            }
        }
        _ => {
            if let Some(n) = &mut p.medium.noise {
                n.velocity = Vec3::new(0.8, 0.0, 0.3);
            }
        }
    }
    p
}

/// Frames 2.. of one way of baking: wall time per frame, stage times and counters summed.
#[derive(Default)]
struct Run {
    ms: Vec<f64>,
    stages: StageTimings,
    counters: Counters,
}

impl Run {
    fn add(&mut self, ms: f64, report: &crate::gpu::FrameReport) {
        self.ms.push(ms);
        self.stages += report.timings_ms;
        self.counters += report.counters;
    }
}

fn stats(ms: &[f64]) -> (f64, f64) {
    let mean = ms.iter().sum::<f64>() / ms.len().max(1) as f64;
    (mean, ms.iter().copied().fold(0.0, f64::max))
}

fn counters_json(c: &Counters) -> Value {
    json!({
        "cells_injected": c.cells_injected,
        "lights_propagated": c.lights_propagated,
        "cells_propagated": c.cells_propagated,
        "samples_marched": c.samples_marched,
    })
}

pub(super) fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let frames: i32 = if ctx.quick { 12 } else { 48 };
    let base = with_resolution(&ctx.demo("cloud")?, 64);
    let (width, height) = image_size(&base, 320);
    let adapter = ctx.gpu.context().adapter_summary();
    log(&format!(
        "animation: cloud at {:?} cells, {width}×{height} image, {frames} frames per motion, adapter {adapter}",
        base.grid.resolution.to_array()
    ));
    // Cold bakes in a second pipeline, interleaved frame by frame with the sequence, so both
    // see the same machine load.
    let mut cold_gpu = crate::gpu::FogPipeline::new(ctx.gpu.context().clone());
    for motion in MOTIONS {
        let project = animated(&base, motion, frames);
        let request = |force| FrameRequest { width, height, scheme: project.propagation.scheme, force };
        let (mut seq, mut cold) = (Run::default(), Run::default());
        let mut first_ms = 0.0;
        for f in 1..=frames {
            let still = project.at_frame(f);
            let t = Instant::now();
            let report = ctx.gpu.update(&still, &request(f == 1))?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            if f == 1 {
                first_ms = ms;
                continue;
            }
            seq.add(ms, &report);
            let t = Instant::now();
            let report = cold_gpu.update(&still, &request(true))?;
            cold.add(t.elapsed().as_secs_f64() * 1e3, &report);
        }
        let (seq_mean, seq_max) = stats(&seq.ms);
        let (cold_mean, cold_max) = stats(&cold.ms);
        let n = (frames - 1) as f64;
        let split = |r: &Run| {
            let t = r.stages;
            format!("inject {:.0} + propagate {:.0} + march {:.0}", t.inject / n, t.propagate / n, t.march / n)
        };
        let per_frame = |c: &Counters| {
            format!(
                "injected {:.0} cells, propagated {:.2} lights ({:.0} cells), marched {:.0} samples",
                c.cells_injected as f64 / n,
                c.lights_propagated as f64 / n,
                c.cells_propagated as f64 / n,
                c.samples_marched as f64 / n
            )
        };
        log(&format!(
            "animation {motion:<9} ms/frame: sequence mean {seq_mean:6.0} max {seq_max:6.0} ({}), cold mean {cold_mean:6.0} max {cold_max:6.0} ({}); cold/sequence ×{:.2}; first frame {first_ms:.0} ms",
            split(&seq),
            split(&cold),
            cold_mean / seq_mean.max(1e-9),
        ));
        log(&format!("    per frame, sequence: {}; cold: {}", per_frame(&seq.counters), per_frame(&cold.counters)));
        out.push(json!({
            "suite": "animation",
            "scene": "cloud",
            "motion": motion,
            "resolution": base.grid.resolution.to_array(),
            "width": width,
            "height": height,
            "frames": frames,
            "first_frame_ms": first_ms,
            "sequence_mean_ms": seq_mean,
            "sequence_max_ms": seq_max,
            "sequence_stage_ms": seq.stages,
            "cold_mean_ms": cold_mean,
            "cold_max_ms": cold_max,
            "cold_stage_ms": cold.stages,
            "speedup": cold_mean / seq_mean.max(1e-9),
            "sequence_counters": counters_json(&seq.counters),
            "cold_counters": counters_json(&cold.counters),
            "adapter": adapter,
        }));
    }
    Ok(())
}

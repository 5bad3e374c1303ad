//! `bench --suite animation`: what baking a sequence in one pipeline saves over baking each
//! frame from scratch. The cloud demo at 64 cells on its longest axis is animated over 48
//! frames (12 with `--quick`) four times, each with one kind of motion: the sun turning, the
//! point light (the sky light) moving, every particle drifting, and the noise drifting in a
//! wind alone. Each motion is baked twice: as a sequence (frame after frame in one pipeline,
//! as `fogsmith render --frames` does) and cold (every frame forced from scratch). A record
//! holds the per-frame wall time of both (the sequence's first frame, which is a cold bake,
//! apart) and the work counters summed over the frames.

use super::suites::Context;
use super::BenchError;
use crate::gpu::{Counters, FrameRequest};
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
    let base = super::suites::with_resolution(&ctx.demo("cloud")?, 64);
    let (width, height) = super::suites::image_size(&base, 320);
    let adapter = ctx.gpu.context().adapter_summary();
    log(&format!(
        "animation: cloud at {:?} cells, {width}×{height} image, {frames} frames per motion, adapter {adapter}",
        base.grid.resolution.to_array()
    ));
    for motion in MOTIONS {
        let project = animated(&base, motion, frames);
        let request = |force| FrameRequest { width, height, scheme: project.propagation.scheme, force };
        let mut sequence = Vec::new();
        let mut warm = Counters::default();
        for f in 1..=frames {
            let still = project.at_frame(f);
            let t = Instant::now();
            let report = ctx.gpu.update(&still, &request(f == 1))?;
            sequence.push(t.elapsed().as_secs_f64() * 1e3);
            if f > 1 {
                warm += report.counters;
            }
        }
        let mut cold = Vec::new();
        let mut cold_counters = Counters::default();
        for f in 2..=frames {
            let still = project.at_frame(f);
            let t = Instant::now();
            let report = ctx.gpu.update(&still, &request(true))?;
            cold.push(t.elapsed().as_secs_f64() * 1e3);
            cold_counters += report.counters;
        }
        let (seq_mean, seq_max) = stats(&sequence[1..]);
        let (cold_mean, cold_max) = stats(&cold);
        log(&format!(
            "animation {motion:<9} sequence ms/frame mean {seq_mean:7.1} max {seq_max:7.1} | cold mean {cold_mean:7.1} max {cold_max:7.1} | ×{:.2} | first frame {:.1} ms | per frame: injected {} cells, propagated {:.2} lights ({} cells), marched {} samples",
            cold_mean / seq_mean.max(1e-9),
            sequence[0],
            warm.cells_injected / (frames as u64 - 1),
            warm.lights_propagated as f64 / (frames - 1) as f64,
            warm.cells_propagated / (frames as u64 - 1),
            warm.samples_marched / (frames as u64 - 1),
        ));
        out.push(json!({
            "suite": "animation",
            "scene": "cloud",
            "motion": motion,
            "resolution": base.grid.resolution.to_array(),
            "width": width,
            "height": height,
            "frames": frames,
            "first_frame_ms": sequence[0],
            "sequence_mean_ms": seq_mean,
            "sequence_max_ms": seq_max,
            "cold_mean_ms": cold_mean,
            "cold_max_ms": cold_max,
            "speedup": cold_mean / seq_mean.max(1e-9),
            "sequence_counters": counters_json(&warm),
            "cold_counters": counters_json(&cold_counters),
            "adapter": adapter,
        }));
    }
    Ok(())
}

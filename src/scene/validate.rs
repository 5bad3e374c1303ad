//! Checks that a project describes a physically meaningful, bakeable scene.
//!
//! [`Project::validate`] names the offending field by its path (`particles[3].radius`)
//! so the editor and the CLI can both point at it; the RON loader adds file, line and
//! column.

use super::animation::{Channel, KeyValue, Object, Prop, ValueKind};
use super::{GridSpec, LightKind, Project};
use glam::Vec3;

/// Largest grid edge accepted before a device is known (wgpu's default 3D texture limit is
/// 2048; the pipeline re-checks against the adapter's real limit).
pub const MAX_RESOLUTION_DEFAULT: u32 = 4096;

/// A field with an invalid value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{field}: {problem}")]
pub struct ValidationError {
    /// Path of the field, e.g. `particles[3].radius`.
    pub field: String,
    /// What is wrong and how to fix it.
    pub problem: String,
}

thread_local! {
    static VALIDATIONS: std::cell::Cell<u64> = const { std::cell::Cell::new(0) };
}

/// How many full validations ([`Project::validate`]) this thread has run: lets tests check
/// that a load validates once and that per-frame paths validate nothing.
pub fn validations_on_this_thread() -> u64 {
    VALIDATIONS.with(|n| n.get())
}

/// Whether a particle passes every check of [`Project::validate_particles`].
fn particle_ok(p: &super::Particle) -> bool {
    p.center.is_finite()
        && p.center.abs().max_element() <= MAX_COORDINATE
        && p.radius.is_finite()
        && p.radius > 0.0
        && p.radius <= MAX_COORDINATE
        && p.density.is_finite()
        && p.density >= 0.0
        && p.density <= MAX_EXTINCTION
}

fn err(field: impl Into<String>, problem: impl Into<String>) -> ValidationError {
    ValidationError { field: field.into(), problem: problem.into() }
}

fn finite(field: &str, v: f32) -> Result<(), ValidationError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(err(field, format!("must be a finite number, got {v}")))
    }
}

fn finite3(field: &str, v: Vec3) -> Result<(), ValidationError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(err(field, format!("must be finite, got ({}, {}, {})", v.x, v.y, v.z)))
    }
}

/// Largest coordinate, in metres, of any position. Squared distances between positions then
/// stay far inside f32 (≈1e19 of 3.4e38), which the GPU's distance and optical-depth
/// arithmetic needs: a light at 1e30 m turned whole frames into NaN.
pub const MAX_COORDINATE: f32 = 1e9;
/// Largest extinction, in 1/m, of the base fog or of one particle (opaque within a
/// picometre). With [`MAX_COORDINATE`] every optical depth stays finite in f32.
pub const MAX_EXTINCTION: f32 = 1e12;

/// Largest radiant intensity per channel (intensity × colour), in W/sr. Radiance near a point
/// light grows like 1/distance², so brighter lights overflowed f32 into infinite pixels.
pub const MAX_INTENSITY: f32 = 1e15;

fn position(field: &str, v: Vec3) -> Result<(), ValidationError> {
    finite3(field, v)?;
    if v.abs().max_element() > MAX_COORDINATE {
        return Err(err(
            field,
            format!(
                "must be within ±{MAX_COORDINATE:e} m on every axis, got ({}, {}, {}); move it closer",
                v.x, v.y, v.z
            ),
        ));
    }
    Ok(())
}

fn extinction(field: &str, v: f32) -> Result<(), ValidationError> {
    at_least(field, v, 0.0)?;
    if v > MAX_EXTINCTION {
        return Err(err(
            field,
            format!("must be at most {MAX_EXTINCTION:e} /m (already opaque within a picometre), got {v}"),
        ));
    }
    Ok(())
}

fn at_least(field: &str, v: f32, min: f32) -> Result<(), ValidationError> {
    finite(field, v)?;
    if v >= min {
        Ok(())
    } else {
        Err(err(field, format!("must be ≥ {min}, got {v}")))
    }
}

/// Largest height-fog falloff k in 1/m.
pub const MAX_HEIGHT_FALLOFF: f32 = 1e6;
/// Largest noise amplitude: the modulation max(0, 1 + a·n) then stays below 1 + this.
pub const MAX_NOISE_AMPLITUDE: f32 = 100.0;

fn direction(field: &str, v: Vec3) -> Result<(), ValidationError> {
    finite3(field, v)?;
    if v.length_squared() < 1e-12 || !v.length_squared().is_finite() {
        return Err(err(field, format!("must be a non-zero direction, got ({}, {}, {})", v.x, v.y, v.z)));
    }
    Ok(())
}

fn light_kind(i: usize, kind: &LightKind) -> Result<(), ValidationError> {
    match *kind {
        LightKind::Point => Ok(()),
        LightKind::Directional { direction: d } => direction(&format!("lights[{i}].kind.direction"), d),
        LightKind::Spot { direction: d, angle_deg, blend } => {
            direction(&format!("lights[{i}].kind.direction"), d)?;
            let field = format!("lights[{i}].kind.angle_deg");
            finite(&field, angle_deg)?;
            if !(angle_deg > 0.0 && angle_deg <= 90.0) {
                return Err(err(
                    field,
                    format!("the cone's half-angle must be within (0, 90] degrees, got {angle_deg}"),
                ));
            }
            let field = format!("lights[{i}].kind.blend");
            finite(&field, blend)?;
            if !(0.0..=1.0).contains(&blend) {
                return Err(err(field, format!("must be within [0, 1], got {blend}")));
            }
            Ok(())
        }
    }
}

impl GridSpec {
    /// Checks bounds and resolution against `max_resolution` cells per axis.
    pub fn validate(&self, max_resolution: u32) -> Result<(), ValidationError> {
        position("grid.min", self.min)?;
        position("grid.max", self.max)?;
        for (axis, (lo, hi)) in ["x", "y", "z"].iter().zip(self.min.to_array().into_iter().zip(self.max.to_array())) {
            if lo >= hi {
                return Err(err(
                    format!("grid.max.{axis}"),
                    format!("must be greater than grid.min.{axis} ({lo}), got {hi}"),
                ));
            }
        }
        for (axis, n) in ["x", "y", "z"].iter().zip(self.resolution.to_array()) {
            if n == 0 || n > max_resolution {
                return Err(err(
                    format!("grid.resolution.{axis}"),
                    format!("must be within 1..={max_resolution}, got {n}; lower the resolution"),
                ));
            }
        }
        Ok(())
    }
}

impl Project {
    /// Checks every field; `max_resolution` is the largest grid edge allowed. Counted by
    /// [`validations_on_this_thread`].
    pub fn validate(&self, max_resolution: u32) -> Result<(), ValidationError> {
        VALIDATIONS.with(|n| n.set(n.get() + 1));
        self.validate_head(max_resolution)?;
        self.validate_particles()?;
        self.validate_tail()?;
        self.validate_animation()
    }

    /// The checks the pipeline repeats on every call: every field but the particles and the
    /// animation tracks, which loading, importing and editing validate where they enter.
    /// Costs a few comparisons per light and surface, nothing next to a frame.
    pub fn validate_settings(&self, max_resolution: u32) -> Result<(), ValidationError> {
        self.validate_head(max_resolution)?;
        self.validate_tail()
    }

    /// Version, grid and medium.
    fn validate_head(&self, max_resolution: u32) -> Result<(), ValidationError> {
        if self.version == 0 || self.version > super::PROJECT_VERSION {
            return Err(err(
                "version",
                format!(
                    "unsupported project version {}; this build reads 1..={}",
                    self.version,
                    super::PROJECT_VERSION
                ),
            ));
        }
        self.grid.validate(max_resolution)?;
        let m = &self.medium;
        extinction("medium.base_extinction", m.base_extinction)?;
        at_least("medium.albedo", m.albedo, 0.0)?;
        if m.albedo > 1.0 {
            return Err(err("medium.albedo", format!("must be within [0, 1], got {}", m.albedo)));
        }
        finite("medium.anisotropy", m.anisotropy)?;
        if m.anisotropy.abs() >= 1.0 {
            return Err(err("medium.anisotropy", format!("must be within (−1, 1), got {}", m.anisotropy)));
        }
        if let Some(ms) = &m.multiple_scattering {
            ms.validate()?;
        }
        at_least("medium.height_falloff", m.height_falloff, 0.0)?;
        if m.height_falloff > MAX_HEIGHT_FALLOFF {
            return Err(err(
                "medium.height_falloff",
                format!(
                    "must be at most {MAX_HEIGHT_FALLOFF:e} /m (a layer a micrometre thick), got {}",
                    m.height_falloff
                ),
            ));
        }
        finite("medium.height_origin", m.height_origin)?;
        if m.height_origin.abs() > MAX_COORDINATE {
            return Err(err(
                "medium.height_origin",
                format!("must be within ±{MAX_COORDINATE:e} m, got {}", m.height_origin),
            ));
        }
        if let Some(n) = &m.noise {
            finite("medium.noise.amplitude", n.amplitude)?;
            if !(0.0..=MAX_NOISE_AMPLITUDE).contains(&n.amplitude) {
                return Err(err(
                    "medium.noise.amplitude",
                    format!("must be within [0, {MAX_NOISE_AMPLITUDE}], got {}", n.amplitude),
                ));
            }
            finite("medium.noise.frequency", n.frequency)?;
            if !(n.frequency > 0.0 && n.frequency <= 1e6) {
                return Err(err(
                    "medium.noise.frequency",
                    format!("must be within (0, 1e6] per metre, got {}", n.frequency),
                ));
            }
            if !(1..=super::MAX_NOISE_OCTAVES).contains(&n.octaves) {
                return Err(err(
                    "medium.noise.octaves",
                    format!("must be within 1..={}, got {}", super::MAX_NOISE_OCTAVES, n.octaves),
                ));
            }
            position("medium.noise.velocity", n.velocity)?;
            position("medium.noise.offset", n.offset)?;
        }
        Ok(())
    }

    /// Every particle's centre, radius and density. A particle in range costs a few
    /// comparisons; the field names of the message are built only for the one that fails.
    pub fn validate_particles(&self) -> Result<(), ValidationError> {
        for (i, p) in self.particles.iter().enumerate() {
            if particle_ok(p) {
                continue;
            }
            position(&format!("particles[{i}].center"), p.center)?;
            finite(&format!("particles[{i}].radius"), p.radius)?;
            if p.radius <= 0.0 {
                return Err(err(format!("particles[{i}].radius"), format!("must be > 0, got {}", p.radius)));
            }
            if p.radius > MAX_COORDINATE {
                return Err(err(
                    format!("particles[{i}].radius"),
                    format!("must be at most {MAX_COORDINATE:e} m, got {}", p.radius),
                ));
            }
            extinction(&format!("particles[{i}].density"), p.density)?;
        }
        Ok(())
    }

    /// Lights, camera, render settings, surfaces, base volume and propagation.
    fn validate_tail(&self) -> Result<(), ValidationError> {
        for (i, l) in self.lights.iter().enumerate() {
            position(&format!("lights[{i}].position"), l.position)?;
            at_least(&format!("lights[{i}].intensity"), l.intensity, 0.0)?;
            finite3(&format!("lights[{i}].color"), l.color)?;
            if l.color.min_element() < 0.0 {
                return Err(err(format!("lights[{i}].color"), "components must be ≥ 0"));
            }
            light_kind(i, &l.kind)?;
            let peak = l.intensity as f64 * l.color.max_element() as f64;
            if peak > MAX_INTENSITY as f64 {
                return Err(err(
                    format!("lights[{i}].intensity"),
                    format!("intensity × colour must be at most {MAX_INTENSITY:e} W/sr per channel, got {peak:e}; lower the intensity or the colour"),
                ));
            }
        }
        let c = &self.camera;
        position("camera.position", c.position)?;
        position("camera.target", c.target)?;
        finite3("camera.up", c.up)?;
        let fwd = c.target - c.position;
        if fwd.length_squared() < 1e-12 {
            return Err(err("camera.target", "must differ from camera.position"));
        }
        if fwd.normalize().cross(c.up.normalize_or_zero()).length_squared() < 1e-10 {
            return Err(err("camera.up", "must not be parallel to the view direction"));
        }
        finite("camera.fov_y_deg", c.fov_y_deg)?;
        if !(c.fov_y_deg > 0.0 && c.fov_y_deg < 180.0) {
            return Err(err("camera.fov_y_deg", format!("must be within (0, 180), got {}", c.fov_y_deg)));
        }
        let r = &self.render;
        for (name, v) in [("render.width", r.width), ("render.height", r.height)] {
            if v == 0 || v > 16384 {
                return Err(err(name, format!("must be within 1..=16384 pixels, got {v}")));
            }
        }
        finite("render.step_factor", r.step_factor)?;
        if !(r.step_factor >= 0.01 && r.step_factor <= 8.0) {
            return Err(err("render.step_factor", format!("must be within [0.01, 8], got {}", r.step_factor)));
        }
        at_least("render.exposure", r.exposure, 0.0)?;
        finite("render.tau_target", r.tau_target)?;
        if !(r.tau_target > 0.0 && r.tau_target <= 4.0) {
            return Err(err("render.tau_target", format!("must be within (0, 4], got {}", r.tau_target)));
        }
        for (name, v) in [("render.near_steps", r.near_steps), ("render.far_steps", r.far_steps)] {
            if v == 0 || v > 100_000 {
                return Err(err(name, format!("must be within 1..=100000, got {v}")));
            }
        }
        finite("render.near_fraction", r.near_fraction)?;
        if !(0.0..=1.0).contains(&r.near_fraction) {
            return Err(err("render.near_fraction", format!("must be within [0, 1], got {}", r.near_fraction)));
        }
        finite("render.transmittance_cutoff", r.transmittance_cutoff)?;
        if !(0.0..1.0).contains(&r.transmittance_cutoff) {
            return Err(err(
                "render.transmittance_cutoff",
                format!("must be within [0, 1), got {}", r.transmittance_cutoff),
            ));
        }
        let albedo_ok = |v: Vec3| v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= 1.0;
        let phong = |at: &str, specular: f32, exponent: f32| {
            if !(0.0..=1.0).contains(&specular) {
                return Err(err(format!("{at}.specular"), format!("must be within [0, 1], got {specular}")));
            }
            let max = crate::surface_table::SPEC_N_MAX as f32;
            if !(0.0..=max).contains(&exponent) {
                return Err(err(format!("{at}.phong_exponent"), format!("must be within [0, {max}], got {exponent}")));
            }
            Ok(())
        };
        if let Some(g) = &self.surfaces.ground {
            finite("surfaces.ground.height", g.height)?;
            if g.height.abs() > MAX_COORDINATE {
                return Err(err(
                    "surfaces.ground.height",
                    format!("must be within ±{MAX_COORDINATE:e} m, got {}", g.height),
                ));
            }
            if !albedo_ok(g.albedo) {
                return Err(err("surfaces.ground.albedo", "components must be within [0, 1]"));
            }
            phong("surfaces.ground", g.specular, g.phong_exponent)?;
        }
        for (i, b) in self.surfaces.boxes.iter().enumerate() {
            position(&format!("surfaces.boxes[{i}].min"), b.min)?;
            position(&format!("surfaces.boxes[{i}].max"), b.max)?;
            if b.min.cmpge(b.max).any() {
                return Err(err(format!("surfaces.boxes[{i}].max"), "must be greater than min on every axis"));
            }
            if !albedo_ok(b.albedo) {
                return Err(err(format!("surfaces.boxes[{i}].albedo"), "components must be within [0, 1]"));
            }
            phong(&format!("surfaces.boxes[{i}]"), b.specular, b.phong_exponent)?;
        }
        if let Some(b) = &self.base_volume {
            at_least("base_volume.scale", b.scale, 0.0)?;
            if b.grid.is_empty() {
                return Err(err("base_volume.grid", "must name a grid, e.g. \"density\""));
            }
        }
        let stride = self.propagation.sweep_stride;
        if !(3..=16).contains(&stride) {
            return Err(err("propagation.sweep_stride", format!("must be within 3..=16, got {stride}")));
        }
        let tolerance = self.propagation.sweep_tolerance;
        if !super::SWEEP_TOLERANCE_RANGE.contains(&tolerance) {
            let (range, default) = (super::SWEEP_TOLERANCE_RANGE, super::DEFAULT_SWEEP_TOLERANCE);
            return Err(err(
                "propagation.sweep_tolerance",
                format!("must be within {:e}..={} (default {default:e}), got {tolerance}", range.start(), range.end()),
            ));
        }
        Ok(())
    }

    /// The frame range and the tracks: each on an existing object and a value it has, one
    /// track per value, keys in frame order, one per frame, of the value's kind and range.
    fn validate_animation(&self) -> Result<(), ValidationError> {
        if let Some(a) = &self.animation {
            if !(a.fps.is_finite() && a.fps > 0.0) {
                return Err(err(
                    "animation.fps",
                    format!("frames per second must be a finite number > 0, got {}; e.g. 24.0", a.fps),
                ));
            }
            if a.start > a.end {
                return Err(err(
                    "animation.end",
                    format!("the last frame ({}) is before the first ({}); make end ≥ start", a.end, a.start),
                ));
            }
        } else if !self.tracks.is_empty() {
            return Err(err(
                "tracks",
                "keyframe tracks need a frame range: add `animation: Some((fps: 24.0, start: 1, end: 120))` or remove the tracks",
            ));
        }
        for (i, t) in self.tracks.iter().enumerate() {
            let name = format!("track {i} ({})", t.on);
            if let Some(j) = self.tracks[..i].iter().position(|u| u.on == t.on) {
                return Err(err(
                    format!("tracks[{i}].on"),
                    format!("{name}: track {j} already animates this value; merge their keys into one track"),
                ));
            }
            self.check_channel(t.on).map_err(|problem| err(format!("tracks[{i}].on"), format!("{name}: {problem}")))?;
            if t.keys.is_empty() {
                return Err(err(
                    format!("tracks[{i}].keys"),
                    format!("{name} has no keys; add a key or remove the track"),
                ));
            }
            for (k, key) in t.keys.iter().enumerate() {
                let at = format!("tracks[{i}].keys[{k}]");
                let key_name = format!("{name}, key {k} (frame {})", key.frame);
                if let Some(prev) = t.keys[..k].iter().position(|p| p.frame == key.frame) {
                    return Err(err(
                        format!("{at}.frame"),
                        format!("{key_name}: key {prev} is on the same frame; keep one key per frame"),
                    ));
                }
                if k > 0 && t.keys[k - 1].frame > key.frame {
                    return Err(err(
                        format!("{at}.frame"),
                        format!(
                            "{key_name}: comes after key {} (frame {}); list the keys in frame order",
                            k - 1,
                            t.keys[k - 1].frame
                        ),
                    ));
                }
                let field = format!("{at}.value");
                key_value(&field, t.on.1, &key.value)
                    .map_err(|e| err(field.clone(), format!("{key_name}: {}", e.problem)))?;
            }
        }
        Ok(())
    }

    /// Why `channel` names nothing in this project, if it does not.
    fn check_channel(&self, channel: Channel) -> Result<(), String> {
        let Channel(object, prop) = channel;
        let exists = match object {
            Object::Particle(id) if self.particle_index(id).is_none() => {
                return Err(format!("there is no particle with id {id}; key an existing particle or remove the track"))
            }
            Object::Light(id) if self.light_index(id).is_none() => {
                return Err(format!("there is no light with id {id}; key an existing light or remove the track"))
            }
            Object::Medium if prop == Prop::NoiseAmplitude && self.medium.noise.is_none() => {
                return Err("the medium has no noise; add `medium.noise` or remove the track".into())
            }
            _ => self.value_of(channel).is_some(),
        };
        if exists {
            Ok(())
        } else {
            let what = match object {
                Object::Particle(_) => "a particle".to_string(),
                Object::Light(id) => match self.light_index(id).map(|i| self.lights[i].kind) {
                    Some(LightKind::Point) => "a point light".into(),
                    Some(LightKind::Spot { .. }) => "a spot light".into(),
                    _ => "a directional light".into(),
                },
                Object::Camera => "the camera".into(),
                Object::Medium => "the medium".into(),
            };
            let valid: Vec<String> = self.animatable(object).iter().map(|c| format!("{:?}", c.1)).collect();
            Err(format!("{what} has no {prop:?} value; animatable: {}", valid.join(", ")))
        }
    }
}

/// A key's value for `prop`: its kind, finite, and within the range of the still field.
fn key_value(field: &str, prop: Prop, value: &KeyValue) -> Result<(), ValidationError> {
    let range = |v: f32, ok: bool, range: &str| {
        if ok {
            Ok(())
        } else {
            Err(err(field, format!("must be within {range}, got {v}")))
        }
    };
    match (prop.kind(), *value) {
        (ValueKind::Bool, KeyValue::Bool(_)) => Ok(()),
        (ValueKind::Vec3, KeyValue::Vec3(v)) => match prop {
            Prop::SpotDirection | Prop::SunDirection => direction(field, v),
            Prop::Color => {
                finite3(field, v)?;
                if v.min_element() < 0.0 {
                    return Err(err(field, "colour components must be ≥ 0"));
                }
                Ok(())
            }
            _ => position(field, v),
        },
        (ValueKind::Float, KeyValue::Float(v)) => {
            finite(field, v)?;
            match prop {
                Prop::Radius => range(v, v > 0.0 && v <= MAX_COORDINATE, &format!("(0, {MAX_COORDINATE:e}] m")),
                Prop::Density | Prop::BaseExtinction => extinction(field, v),
                Prop::Intensity => at_least(field, v, 0.0),
                Prop::AngleDeg => range(v, v > 0.0 && v <= 90.0, "(0, 90] degrees"),
                Prop::Blend => range(v, (0.0..=1.0).contains(&v), "[0, 1]"),
                Prop::FovYDeg => range(v, v > 0.0 && v < 180.0, "(0, 180) degrees"),
                Prop::HeightFalloff => {
                    range(v, (0.0..=MAX_HEIGHT_FALLOFF).contains(&v), &format!("[0, {MAX_HEIGHT_FALLOFF:e}] /m"))
                }
                Prop::HeightOrigin => range(v, v.abs() <= MAX_COORDINATE, &format!("±{MAX_COORDINATE:e} m")),
                Prop::NoiseAmplitude => {
                    range(v, (0.0..=MAX_NOISE_AMPLITUDE).contains(&v), &format!("[0, {MAX_NOISE_AMPLITUDE}]"))
                }
                _ => Ok(()),
            }
        }
        (kind, _) => {
            let example = match kind {
                ValueKind::Float => "Float(1.0)",
                ValueKind::Vec3 => "Vec3((0.0, 1.0, 0.0))",
                ValueKind::Bool => "Bool(true)",
            };
            Err(err(field, format!("{prop:?} takes a {kind:?} value, e.g. {example}, got {value:?}")))
        }
    }
}

impl super::MultipleScattering {
    fn validate(&self) -> Result<(), ValidationError> {
        let field = "medium.multiple_scattering";
        if !(1..=64).contains(&self.orders) {
            return Err(err(format!("{field}.orders"), format!("must be within 1..=64, got {}", self.orders)));
        }
        finite(&format!("{field}.strength"), self.strength)?;
        if !(0.0..=10.0).contains(&self.strength) {
            return Err(err(format!("{field}.strength"), format!("must be within [0, 10], got {}", self.strength)));
        }
        if !(4..=128).contains(&self.resolution) {
            return Err(err(
                format!("{field}.resolution"),
                format!("must be within 4..=128 coarse cells, got {}", self.resolution),
            ));
        }
        Ok(())
    }
}

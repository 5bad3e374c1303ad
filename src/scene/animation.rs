//! Time in a project: a frame range and keyframe tracks on the animatable values of
//! particles, lights, the camera and the medium.
//!
//! A project with `animation: Some((fps: 24.0, start: 1, end: 120))` is an animation of the
//! frames `start..=end`; frame f is at time f / fps seconds. Without `animation` the project
//! is a still. Each [`Track`] keys one [`Channel`] (one value of one object, objects named
//! by their stable ids, see `ids.rs`); [`Project::at_frame`] turns the project into the
//! still of one frame, which is what the pipeline renders.
//!
//! Interpolation between the key at frame a (value A) and the next key at frame b (value
//! B) uses the interp of the key at a; with u = (f − a) / (b − a):
//! - `Hold`: A until b;
//! - `Linear`: A + (B − A)·u;
//! - `Smooth`: A + (B − A)·(3u² − 2u³), a cubic Hermite with zero slope at both keys (an
//!   ease in and out). Chosen over Catmull–Rom because it never overshoots: every value
//!   between two keys lies between them, so keys within a value's valid range keep every
//!   frame within it.
//!
//! Before the first key and after the last the value holds. Booleans (`hidden`) always
//! step. Vec3 values interpolate per component; directions are then re-normalised, and a
//! zero result keeps the earlier key's direction.
//!
//! In a project file (RON):
//!
//! ```ron
//! animation: Some((fps: 24.0, start: 1, end: 120)),
//! tracks: [
//!     (on: (Light(3), Position), keys: [
//!         (frame: 1, value: Vec3((0.0, 1.0, 0.0)), interp: Smooth),
//!         (frame: 48, value: Vec3((2.0, 1.5, 0.0))),
//!     ]),
//!     (on: (Particle(0), Density), keys: [(frame: 1, value: Float(2.0), interp: Hold), (frame: 60, value: Float(0.5))]),
//!     (on: (Particle(0), Hidden), keys: [(frame: 90, value: Bool(true))]),
//!     (on: (Camera, FovYDeg), keys: [(frame: 1, value: Float(40.0)), (frame: 120, value: Float(25.0))]),
//! ],
//! ```
//!
//! `interp` defaults to `Linear`. Objects are `Particle(id)`, `Light(id)`, `Camera` and
//! `Medium`; the values each has are listed on [`Prop`].

use super::{LightKind, Project};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::ops::RangeInclusive;

/// The frame range and rate of an animated project.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Animation {
    /// Frames per second, > 0.
    pub fps: f32,
    /// First and last frame, inclusive; `start` ≤ `end`.
    pub start: i32,
    pub end: i32,
}

impl Default for Animation {
    /// 24 fps, frames 1 to 120.
    fn default() -> Self {
        Self { fps: 24.0, start: 1, end: 120 }
    }
}

impl Animation {
    /// The time of `frame` in seconds: frame / fps.
    pub fn time(&self, frame: i32) -> f64 {
        frame as f64 / self.fps as f64
    }

    /// The frames of the animation, `start..=end`.
    pub fn frames(&self) -> RangeInclusive<i32> {
        self.start..=self.end
    }
}

/// An object whose values can be animated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Object {
    /// The particle with this id.
    Particle(u32),
    /// The light with this id.
    Light(u32),
    Camera,
    Medium,
}

/// An animatable value of an object.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Prop {
    /// Particle: `center` (Vec3).
    Center,
    /// Particle: `radius` (Float, > 0).
    Radius,
    /// Particle: `density` (Float, ≥ 0).
    Density,
    /// Particle: `hidden` (Bool).
    Hidden,
    /// Light or camera: `position` (Vec3).
    Position,
    /// Light: `intensity` (Float, ≥ 0).
    Intensity,
    /// Light: `color` (Vec3, components ≥ 0).
    Color,
    /// Spot light: the cone's axis `direction` (Vec3, non-zero).
    SpotDirection,
    /// Spot light: the half-angle `angle_deg` (Float, in (0, 90]).
    AngleDeg,
    /// Spot light: `blend` (Float, in [0, 1]).
    Blend,
    /// Directional light: `direction` of travel (Vec3, non-zero).
    SunDirection,
    /// Camera: `target` (Vec3).
    Target,
    /// Camera: `fov_y_deg` (Float, in (0, 180)).
    FovYDeg,
    /// Medium: `base_extinction` (Float, ≥ 0).
    BaseExtinction,
    /// Medium: `height_falloff` (Float, ≥ 0).
    HeightFalloff,
    /// Medium: `height_origin` (Float).
    HeightOrigin,
    /// Medium: the noise's `amplitude` (Float, in [0, 100]); needs `medium.noise`.
    NoiseAmplitude,
}

/// The kind of value a [`Prop`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueKind {
    Float,
    Vec3,
    Bool,
}

impl Prop {
    /// The kind of value this holds.
    pub fn kind(self) -> ValueKind {
        match self {
            Prop::Center | Prop::Position | Prop::Color | Prop::SpotDirection | Prop::SunDirection | Prop::Target => {
                ValueKind::Vec3
            }
            Prop::Hidden => ValueKind::Bool,
            _ => ValueKind::Float,
        }
    }

    /// Whether the value is a direction (re-normalised after interpolation).
    pub fn is_direction(self) -> bool {
        matches!(self, Prop::SpotDirection | Prop::SunDirection)
    }

    /// The name of the field in the project file.
    pub fn field(self) -> &'static str {
        match self {
            Prop::Center => "center",
            Prop::Radius => "radius",
            Prop::Density => "density",
            Prop::Hidden => "hidden",
            Prop::Position => "position",
            Prop::Intensity => "intensity",
            Prop::Color => "color",
            Prop::SpotDirection | Prop::SunDirection => "kind.direction",
            Prop::AngleDeg => "kind.angle_deg",
            Prop::Blend => "kind.blend",
            Prop::Target => "target",
            Prop::FovYDeg => "fov_y_deg",
            Prop::BaseExtinction => "base_extinction",
            Prop::HeightFalloff => "height_falloff",
            Prop::HeightOrigin => "height_origin",
            Prop::NoiseAmplitude => "noise.amplitude",
        }
    }
}

/// One animatable value of one object: what a [`Track`] keys. Written `(Light(3), Position)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Channel(pub Object, pub Prop);

impl std::fmt::Display for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Object::Particle(id) => write!(f, "Particle #{id}")?,
            Object::Light(id) => write!(f, "Light #{id}")?,
            Object::Camera => f.write_str("Camera")?,
            Object::Medium => f.write_str("Medium")?,
        }
        write!(f, " {:?}", self.1)
    }
}

/// A key's value. Written `Float(2.0)`, `Vec3((0.0, 1.0, 0.0))` or `Bool(true)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum KeyValue {
    Float(f32),
    Vec3(Vec3),
    Bool(bool),
}

impl KeyValue {
    /// The kind of this value.
    pub fn kind(&self) -> ValueKind {
        match self {
            KeyValue::Float(_) => ValueKind::Float,
            KeyValue::Vec3(_) => ValueKind::Vec3,
            KeyValue::Bool(_) => ValueKind::Bool,
        }
    }
}

/// How a key's value changes towards the next key (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Interp {
    Hold,
    #[default]
    Linear,
    Smooth,
}

/// A value at a frame. `interp` (default `Linear`) shapes the way to the next key.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Key {
    pub frame: i32,
    pub value: KeyValue,
    #[serde(default)]
    pub interp: Interp,
}

/// The keys of one channel, in ascending frame order, one per frame (validation requires
/// it of a file; the editing API keeps it).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Track {
    pub on: Channel,
    pub keys: Vec<Key>,
}

impl Track {
    /// The value at `frame` (see the module doc), or None without keys.
    pub fn sample(&self, frame: i32) -> Option<KeyValue> {
        let first = self.keys.first()?;
        let last = self.keys.last()?;
        if frame <= first.frame {
            return Some(first.value);
        }
        if frame >= last.frame {
            return Some(last.value);
        }
        let i = self.keys.partition_point(|k| k.frame <= frame) - 1;
        let (a, b) = (self.keys[i], self.keys[i + 1]);
        if frame == a.frame {
            return Some(a.value);
        }
        let u = (frame - a.frame) as f64 / (b.frame - a.frame) as f64;
        let w = match a.interp {
            Interp::Hold => return Some(a.value),
            Interp::Linear => u,
            Interp::Smooth => u * u * (3.0 - 2.0 * u),
        };
        let lerp = |x: f32, y: f32| (x as f64 + (y as f64 - x as f64) * w) as f32;
        Some(match (a.value, b.value) {
            (KeyValue::Float(x), KeyValue::Float(y)) => KeyValue::Float(lerp(x, y)),
            (KeyValue::Vec3(x), KeyValue::Vec3(y)) => {
                let v = Vec3::new(lerp(x.x, y.x), lerp(x.y, y.y), lerp(x.z, y.z));
                if self.on.1.is_direction() {
                    KeyValue::Vec3(v.try_normalize().unwrap_or(x))
                } else {
                    KeyValue::Vec3(v)
                }
            }
            // Booleans step; mismatched kinds (an invalid project) hold.
            _ => a.value,
        })
    }

    fn sort(&mut self) {
        self.keys.sort_by_key(|k| k.frame);
    }
}

/// Why an edit of keys was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{0}")]
pub struct KeyError(pub String);

impl Project {
    /// The still project of `frame`: every track's value at that frame applied, the noise's
    /// `offset` set to velocity·t (f32), and `animation` and `tracks` removed, so the
    /// pipeline sees a plain still. A project without animation is returned as it is.
    /// Tracks on missing objects or values a light's kind lacks are skipped.
    pub fn at_frame(&self, frame: i32) -> Project {
        let mut still = self.clone();
        let Some(animation) = self.animation else { return still };
        still.animation = None;
        let tracks = std::mem::take(&mut still.tracks);
        for track in &tracks {
            if let Some(v) = track.sample(frame) {
                still.apply(track.on, v);
            }
        }
        if let Some(n) = &mut still.medium.noise {
            n.offset = n.velocity * animation.time(frame) as f32;
        }
        still
    }

    /// The values of `object` that can be animated (for a light, those of its kind); empty
    /// when the object does not exist.
    pub fn animatable(&self, object: Object) -> Vec<Channel> {
        let props: &[Prop] = match object {
            Object::Particle(id) => match self.particle_index(id) {
                Some(_) => &[Prop::Center, Prop::Radius, Prop::Density, Prop::Hidden],
                None => &[],
            },
            Object::Light(id) => match self.light_index(id).map(|i| self.lights[i].kind) {
                Some(LightKind::Point) => &[Prop::Position, Prop::Intensity, Prop::Color],
                Some(LightKind::Spot { .. }) => {
                    &[Prop::Position, Prop::Intensity, Prop::Color, Prop::SpotDirection, Prop::AngleDeg, Prop::Blend]
                }
                Some(LightKind::Directional { .. }) => &[Prop::Intensity, Prop::Color, Prop::SunDirection],
                None => &[],
            },
            Object::Camera => &[Prop::Position, Prop::Target, Prop::FovYDeg],
            Object::Medium if self.medium.noise.is_some() => {
                &[Prop::BaseExtinction, Prop::HeightFalloff, Prop::HeightOrigin, Prop::NoiseAmplitude]
            }
            Object::Medium => &[Prop::BaseExtinction, Prop::HeightFalloff, Prop::HeightOrigin],
        };
        props.iter().map(|&p| Channel(object, p)).collect()
    }

    /// The channel's value in the project's still fields, or None when the object does not
    /// exist or has no such value.
    pub fn value_of(&self, channel: Channel) -> Option<KeyValue> {
        use KeyValue::{Bool, Float, Vec3 as V};
        let Channel(object, prop) = channel;
        match object {
            Object::Particle(id) => {
                let p = &self.particles[self.particle_index(id)?];
                match prop {
                    Prop::Center => Some(V(p.center)),
                    Prop::Radius => Some(Float(p.radius)),
                    Prop::Density => Some(Float(p.density)),
                    Prop::Hidden => Some(Bool(p.hidden)),
                    _ => None,
                }
            }
            Object::Light(id) => {
                let l = &self.lights[self.light_index(id)?];
                match (prop, l.kind) {
                    (Prop::Position, LightKind::Point | LightKind::Spot { .. }) => Some(V(l.position)),
                    (Prop::Intensity, _) => Some(Float(l.intensity)),
                    (Prop::Color, _) => Some(V(l.color)),
                    (Prop::SpotDirection, LightKind::Spot { direction, .. }) => Some(V(direction)),
                    (Prop::AngleDeg, LightKind::Spot { angle_deg, .. }) => Some(Float(angle_deg)),
                    (Prop::Blend, LightKind::Spot { blend, .. }) => Some(Float(blend)),
                    (Prop::SunDirection, LightKind::Directional { direction }) => Some(V(direction)),
                    _ => None,
                }
            }
            Object::Camera => match prop {
                Prop::Position => Some(V(self.camera.position)),
                Prop::Target => Some(V(self.camera.target)),
                Prop::FovYDeg => Some(Float(self.camera.fov_y_deg)),
                _ => None,
            },
            Object::Medium => match prop {
                Prop::BaseExtinction => Some(Float(self.medium.base_extinction)),
                Prop::HeightFalloff => Some(Float(self.medium.height_falloff)),
                Prop::HeightOrigin => Some(Float(self.medium.height_origin)),
                Prop::NoiseAmplitude => self.medium.noise.map(|n| Float(n.amplitude)),
                _ => None,
            },
        }
    }

    /// Writes `value` into the channel's still field; false (nothing written) when the
    /// channel does not exist or the value's kind is wrong. Editors pose a keyed project at
    /// a frame with it, so that its still fields show that frame.
    pub fn apply(&mut self, channel: Channel, value: KeyValue) -> bool {
        if self.value_of(channel).map(|v| v.kind()) != Some(value.kind()) {
            return false;
        }
        let Channel(object, prop) = channel;
        let (f, v, b) = match value {
            KeyValue::Float(f) => (f, Vec3::ZERO, false),
            KeyValue::Vec3(v) => (0.0, v, false),
            KeyValue::Bool(b) => (0.0, Vec3::ZERO, b),
        };
        match object {
            Object::Particle(id) => {
                let Some(i) = self.particle_index(id) else { return false };
                let p = &mut self.particles[i];
                match prop {
                    Prop::Center => p.center = v,
                    Prop::Radius => p.radius = f,
                    Prop::Density => p.density = f,
                    Prop::Hidden => p.hidden = b,
                    _ => return false,
                }
            }
            Object::Light(id) => {
                let Some(i) = self.light_index(id) else { return false };
                let l = &mut self.lights[i];
                match (prop, &mut l.kind) {
                    (Prop::Position, _) => l.position = v,
                    (Prop::Intensity, _) => l.intensity = f,
                    (Prop::Color, _) => l.color = v,
                    (Prop::SpotDirection, LightKind::Spot { direction, .. }) => *direction = v,
                    (Prop::AngleDeg, LightKind::Spot { angle_deg, .. }) => *angle_deg = f,
                    (Prop::Blend, LightKind::Spot { blend, .. }) => *blend = f,
                    (Prop::SunDirection, LightKind::Directional { direction }) => *direction = v,
                    _ => return false,
                }
            }
            Object::Camera => match prop {
                Prop::Position => self.camera.position = v,
                Prop::Target => self.camera.target = v,
                Prop::FovYDeg => self.camera.fov_y_deg = f,
                _ => return false,
            },
            Object::Medium => match prop {
                Prop::BaseExtinction => self.medium.base_extinction = f,
                Prop::HeightFalloff => self.medium.height_falloff = f,
                Prop::HeightOrigin => self.medium.height_origin = f,
                Prop::NoiseAmplitude => match &mut self.medium.noise {
                    Some(n) => n.amplitude = f,
                    None => return false,
                },
                _ => return false,
            },
        }
        true
    }

    /// The track of `channel`, if it has one.
    pub fn track(&self, channel: Channel) -> Option<&Track> {
        self.tracks.iter().find(|t| t.on == channel)
    }

    /// Sets a key on `channel` at `frame`, replacing a key on that frame, and creating the
    /// track (and, in a still, a default [`Animation`]) when needed. Refused when the
    /// channel does not exist (see [`Self::animatable`]) or `value` is of the wrong kind.
    pub fn set_key(&mut self, channel: Channel, frame: i32, value: KeyValue, interp: Interp) -> Result<(), KeyError> {
        let Some(current) = self.value_of(channel) else {
            return Err(KeyError(format!("{channel} cannot be animated: no such object or value")));
        };
        if current.kind() != value.kind() {
            return Err(KeyError(format!("{channel} holds a {:?}, not a {:?}", current.kind(), value.kind())));
        }
        if self.animation.is_none() {
            self.animation = Some(Animation::default());
        }
        let key = Key { frame, value, interp };
        match self.tracks.iter_mut().find(|t| t.on == channel) {
            Some(t) => match t.keys.iter_mut().find(|k| k.frame == frame) {
                Some(k) => *k = key,
                None => {
                    t.keys.push(key);
                    t.sort();
                }
            },
            None => self.tracks.push(Track { on: channel, keys: vec![key] }),
        }
        Ok(())
    }

    /// Removes the key of `channel` at `frame`, and the track with its last key; returns
    /// whether there was one.
    pub fn remove_key(&mut self, channel: Channel, frame: i32) -> bool {
        let Some(ti) = self.tracks.iter().position(|t| t.on == channel) else { return false };
        let t = &mut self.tracks[ti];
        let before = t.keys.len();
        t.keys.retain(|k| k.frame != frame);
        let removed = t.keys.len() < before;
        if t.keys.is_empty() {
            self.tracks.remove(ti);
        }
        removed
    }

    /// Moves the key of `channel` at `from` to `to`. Refused when there is no key at
    /// `from` or `to` already has one (moving a key onto itself is fine).
    pub fn move_key(&mut self, channel: Channel, from: i32, to: i32) -> Result<(), KeyError> {
        let Some(t) = self.tracks.iter_mut().find(|t| t.on == channel) else {
            return Err(KeyError(format!("{channel} has no keys")));
        };
        if from != to && t.keys.iter().any(|k| k.frame == to) {
            return Err(KeyError(format!("{channel} already has a key at frame {to}")));
        }
        let Some(k) = t.keys.iter_mut().find(|k| k.frame == from) else {
            return Err(KeyError(format!("{channel} has no key at frame {from}")));
        };
        k.frame = to;
        t.sort();
        Ok(())
    }

    /// The frames with a key on any value of `object`, ascending, each once.
    pub fn key_frames(&self, object: Object) -> Vec<i32> {
        let mut frames: Vec<i32> =
            self.tracks.iter().filter(|t| t.on.0 == object).flat_map(|t| t.keys.iter().map(|k| k.frame)).collect();
        frames.sort_unstable();
        frames.dedup();
        frames
    }

    /// Whether `channel` has a key at `frame`.
    pub fn has_key(&self, channel: Channel, frame: i32) -> bool {
        self.track(channel).is_some_and(|t| t.keys.iter().any(|k| k.frame == frame))
    }

    /// Whether `channel` has a track with keys.
    pub fn is_animated(&self, channel: Channel) -> bool {
        self.track(channel).is_some_and(|t| !t.keys.is_empty())
    }

    /// Drops every track whose channel no longer exists: an object deleted other than
    /// through [`Self::remove_particles`] or [`Self::remove_lights`], a light whose kind
    /// changed (a point light has no spot angle), or the medium's noise turned off. Edits
    /// that do any of these call it, so that the project stays valid.
    pub fn drop_inapplicable_tracks(&mut self) {
        let tracks = std::mem::take(&mut self.tracks);
        self.tracks = tracks.into_iter().filter(|t| self.value_of(t.on).is_some()).collect();
    }

    /// Drops the tracks of `object` (a deleted particle or light).
    pub fn remove_tracks_of(&mut self, object: Object) {
        self.tracks.retain(|t| t.on.0 != object);
    }

    /// Removes the particles at `indices` (positions in `particles`) and their tracks.
    pub fn remove_particles(&mut self, indices: &std::collections::BTreeSet<usize>) {
        let gone: Vec<u32> = indices.iter().filter_map(|&i| self.particles.get(i)).map(|p| p.id).collect();
        let mut i = 0;
        self.particles.retain(|_| {
            i += 1;
            !indices.contains(&(i - 1))
        });
        for id in gone {
            self.remove_tracks_of(Object::Particle(id));
        }
    }

    /// Removes the lights at `indices` (positions in `lights`) and their tracks.
    pub fn remove_lights(&mut self, indices: &std::collections::BTreeSet<usize>) {
        let gone: Vec<u32> = indices.iter().filter_map(|&i| self.lights.get(i)).map(|l| l.id).collect();
        let mut i = 0;
        self.lights.retain(|_| {
            i += 1;
            !indices.contains(&(i - 1))
        });
        for id in gone {
            self.remove_tracks_of(Object::Light(id));
        }
    }
}

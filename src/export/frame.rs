//! Axis and unit conventions of the tools Fogsmith exports to.
//!
//! Fogsmith works in a right-handed, Y-up frame measured in metres. An export [`Frame`] maps a
//! point p of that frame to `scale · M · p` in the target tool's frame, where M is a signed
//! permutation of the axes and scale is 1 (metres) or 100 (centimetres):
//!
//! | frame | M · (x, y, z) |
//! |---|---|
//! | Y-up, right-handed (Fogsmith, Houdini, Godot, Bevy) | (x, y, z) |
//! | Z-up, right-handed (Blender) | (x, −z, y): a rotation of +90° about X |
//! | Z-up, left-handed (Unreal) | (x, z, y) |
//! | Y-up, left-handed (Unity) | (−x, y, z) |
//!
//! The exporters put this map into the files' transforms (a VDB grid's index-to-world map, a
//! USD stage's coordinates and metadata, EXR header attributes); voxel values are never
//! resampled. Values keep their units: extinction stays in 1/m whatever the length unit.

use serde::{Deserialize, Serialize};
use std::fmt;

/// Which world axis points up.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
pub enum UpAxis {
    #[default]
    Y,
    Z,
}

/// The length unit of the target's world coordinates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
pub enum Units {
    /// Metres (scale 1).
    #[default]
    M,
    /// Centimetres (scale 100).
    Cm,
}

/// Whether the target's axes form a right- or left-handed system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, Serialize, Deserialize)]
pub enum Handedness {
    #[default]
    Right,
    Left,
}

/// The conventions of the tools Fogsmith's files are usually opened in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
pub enum Preset {
    /// Z-up, metres, right-handed.
    Blender,
    /// Y-up, metres, right-handed.
    Houdini,
    /// Z-up, centimetres, left-handed.
    Unreal,
    /// Y-up, metres, right-handed.
    Godot,
    /// Y-up, metres, left-handed (x mirrored, as Unity's own importers do).
    Unity,
}

/// An export frame: up axis, length unit and handedness. The default is Fogsmith's own frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct Frame {
    pub up: UpAxis,
    pub units: Units,
    pub handedness: Handedness,
}

impl Frame {
    /// Fogsmith's own frame: Y-up, metres, right-handed.
    pub const NATIVE: Frame = Frame { up: UpAxis::Y, units: Units::M, handedness: Handedness::Right };

    pub fn preset(p: Preset) -> Frame {
        let (up, units, handedness) = match p {
            Preset::Blender => (UpAxis::Z, Units::M, Handedness::Right),
            Preset::Houdini | Preset::Godot => (UpAxis::Y, Units::M, Handedness::Right),
            Preset::Unreal => (UpAxis::Z, Units::Cm, Handedness::Left),
            Preset::Unity => (UpAxis::Y, Units::M, Handedness::Left),
        };
        Frame { up, units, handedness }
    }

    /// Target length units per metre: 1 or 100.
    pub fn scale(&self) -> f64 {
        match self.units {
            Units::M => 1.0,
            Units::Cm => 100.0,
        }
    }

    /// Metres per target unit (USD's `metersPerUnit`).
    pub fn meters_per_unit(&self) -> f64 {
        match self.units {
            Units::M => 1.0,
            Units::Cm => 0.01,
        }
    }

    /// M as rows: `target[b] = Σ_a M[b][a] · source[a]`. A signed permutation.
    pub fn matrix(&self) -> [[f64; 3]; 3] {
        match (self.up, self.handedness) {
            (UpAxis::Y, Handedness::Right) => [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            (UpAxis::Z, Handedness::Right) => [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]],
            (UpAxis::Z, Handedness::Left) => [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]],
            (UpAxis::Y, Handedness::Left) => [[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// Whether M is the identity (only the unit may differ from Fogsmith's frame).
    pub fn keeps_axes(&self) -> bool {
        self.up == UpAxis::Y && self.handedness == Handedness::Right
    }

    /// A direction in the target frame (rotated or mirrored, not scaled).
    pub fn vector(&self, v: [f64; 3]) -> [f64; 3] {
        let m = self.matrix();
        [0, 1, 2].map(|b| m[b][0] * v[0] + m[b][1] * v[1] + m[b][2] * v[2])
    }

    /// A point in the target frame: `scale · M · p`.
    pub fn point(&self, p: [f64; 3]) -> [f64; 3] {
        let s = self.scale();
        self.vector(p).map(|c| c * s)
    }

    /// The inverse of [`Frame::point`]: a target-frame point back in Fogsmith's frame.
    pub fn inverse_point(&self, q: [f64; 3]) -> [f64; 3] {
        let m = self.matrix();
        let s = self.scale();
        // M is orthogonal: its inverse is its transpose.
        [0, 1, 2].map(|a| (m[0][a] * q[0] + m[1][a] * q[1] + m[2][a] * q[2]) / s)
    }

    /// [`Frame::point`] in f32, for metadata.
    pub fn point_f32(&self, p: [f32; 3]) -> [f32; 3] {
        self.point(p.map(f64::from)).map(|c| c as f32)
    }

    /// The up axis as USD and the file metadata spell it: "Y" or "Z".
    pub fn up_name(&self) -> &'static str {
        match self.up {
            UpAxis::Y => "Y",
            UpAxis::Z => "Z",
        }
    }

    /// "right" or "left".
    pub fn handedness_name(&self) -> &'static str {
        match self.handedness {
            Handedness::Right => "right",
            Handedness::Left => "left",
        }
    }

    /// The frame that [`Frame::up_name`], [`Frame::meters_per_unit`] and
    /// [`Frame::handedness_name`] describe, or None when they name no frame Fogsmith writes.
    pub fn from_names(up: &str, meters_per_unit: f64, handedness: &str) -> Option<Frame> {
        let up = match up {
            "Y" => UpAxis::Y,
            "Z" => UpAxis::Z,
            _ => return None,
        };
        let units = if meters_per_unit == 1.0 {
            Units::M
        } else if (meters_per_unit - 0.01).abs() < 1e-12 {
            Units::Cm
        } else {
            return None;
        };
        let handedness = match handedness {
            "right" => Handedness::Right,
            "left" => Handedness::Left,
            _ => return None,
        };
        Some(Frame { up, units, handedness })
    }
}

impl fmt::Display for Frame {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let units = match self.units {
            Units::M => "m",
            Units::Cm => "cm",
        };
        write!(f, "{}-up, {units}, {}-handed", self.up_name(), self.handedness_name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_frames() -> Vec<Frame> {
        let mut v = Vec::new();
        for up in [UpAxis::Y, UpAxis::Z] {
            for units in [Units::M, Units::Cm] {
                for handedness in [Handedness::Right, Handedness::Left] {
                    v.push(Frame { up, units, handedness });
                }
            }
        }
        v
    }

    fn det(m: [[f64; 3]; 3]) -> f64 {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    }

    #[test]
    fn up_goes_up_handedness_is_the_determinant_and_inverse_inverts() {
        for f in all_frames() {
            let up = f.vector([0.0, 1.0, 0.0]);
            let want = if f.up == UpAxis::Y { [0.0, 1.0, 0.0] } else { [0.0, 0.0, 1.0] };
            assert_eq!(up, want, "{f}");
            assert_eq!(det(f.matrix()), if f.handedness == Handedness::Right { 1.0 } else { -1.0 }, "{f}");
            let p = [0.25, -1.5, 3.0];
            let q = f.point(p);
            assert_eq!(f.inverse_point(q), p, "{f}");
            let len = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            assert!((len(q) - f.scale() * len(p)).abs() < 1e-12, "{f}");
            assert_eq!(Frame::from_names(f.up_name(), f.meters_per_unit(), f.handedness_name()), Some(f));
        }
    }

    #[test]
    fn presets_and_blender_rotation() {
        // Blender's Z-up is Fogsmith's frame turned +90° about X: +z (towards the default
        // camera) becomes −y.
        let b = Frame::preset(Preset::Blender);
        assert_eq!(b.point([1.0, 2.0, 3.0]), [1.0, -3.0, 2.0]);
        let u = Frame::preset(Preset::Unreal);
        assert_eq!(u.point([1.0, 2.0, 3.0]), [100.0, 300.0, 200.0]);
        assert_eq!(u.meters_per_unit(), 0.01);
        assert_eq!(Frame::preset(Preset::Houdini), Frame::NATIVE);
        assert_eq!(Frame::preset(Preset::Godot), Frame::NATIVE);
        assert_eq!(Frame::preset(Preset::Unity).point([1.0, 2.0, 3.0]), [-1.0, 2.0, 3.0]);
        assert_eq!(Frame::from_names("X", 1.0, "right"), None);
        assert_eq!(Frame::from_names("Y", 0.3048, "right"), None);
    }
}

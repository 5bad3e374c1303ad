//! Viewport tools and the geometry behind them: brush dabs, picking, box selection.
//! Pure functions of the project and the view, so tests can check them without a window.

use super::view::ViewProjection;
use crate::scene::{Particle, Project};
use egui::{Pos2, Rect};
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tool {
    #[default]
    Select,
    Paint,
    Scale,
    Erase,
    Light,
}

impl Tool {
    pub const ALL: [Tool; 5] = [Tool::Select, Tool::Paint, Tool::Scale, Tool::Erase, Tool::Light];

    pub fn label(self) -> &'static str {
        match self {
            Tool::Select => "Select",
            Tool::Paint => "Paint",
            Tool::Scale => "Scale",
            Tool::Erase => "Erase",
            Tool::Light => "Light",
        }
    }
    /// The command that picks this tool (its shortcut lives there).
    pub fn command(self) -> super::commands::Command {
        use super::commands::Command;
        match self {
            Tool::Select => Command::ToolSelect,
            Tool::Paint => Command::ToolPaint,
            Tool::Scale => Command::ToolScale,
            Tool::Erase => Command::ToolErase,
            Tool::Light => Command::ToolLight,
        }
    }
    pub fn tooltip(self) -> &'static str {
        match self {
            Tool::Select => "Select / Move: click to select, Shift/Ctrl-click to add or toggle, drag on empty space for a box, drag a selected item to move it in the view plane. G grabs, S scales the selection.",
            Tool::Paint => "Paint: click or drag to deposit particles on the working plane (through the grid centre, facing the camera). In the Slices panel, paints on the slice plane.",
            Tool::Scale => "Scale: wheel or horizontal drag grows/shrinks the radius of the selection, or of the particles under the brush when nothing is selected. Hold Alt to change density instead.",
            Tool::Erase => "Erase: click or drag to remove the particles under the brush (through all depths).",
            Tool::Light => "Light: click empty space to add a light on the working plane, drag a light to move it.",
        }
    }
}

/// Brush settings shared by Paint, Scale and Erase.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Brush {
    /// Radius of painted particles and of the brush footprint, metres.
    pub radius: f32,
    /// Peak extinction of painted particles, 1/m.
    pub density: f32,
    /// Distance between dabs along a stroke, as a fraction of the radius.
    pub spacing: f32,
    /// Random offset of each dab in the plane, as a fraction of the radius.
    pub jitter: f32,
}

impl Default for Brush {
    fn default() -> Self {
        Self { radius: 0.15, density: 2.0, spacing: 0.5, jitter: 0.3 }
    }
}

/// A small deterministic generator for brush jitter (xorshift64*).
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    /// Uniform in [0, 1).
    pub fn next_f32(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let v = self.0.wrapping_mul(0x2545_F491_4F6C_DD1D);
        (v >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A paint stroke in progress: where the last dab went, so dabs follow the spacing.
#[derive(Clone, Debug)]
pub struct Stroke {
    pub tag: super::session::EditTag,
    last: Option<Vec3>,
    rng: Rng,
}

impl Stroke {
    pub fn new(tag: super::session::EditTag) -> Self {
        Self { tag, last: None, rng: Rng::new(tag) }
    }

    /// Dabs for the pointer moving to `point` on a plane spanned by `right`, `up`.
    pub fn dabs_to(&mut self, point: Vec3, right: Vec3, up: Vec3, brush: &Brush) -> Vec<Particle> {
        let step = (brush.spacing.max(0.05) * brush.radius).max(1e-4);
        let mut out = Vec::new();
        let mut positions = Vec::new();
        match self.last {
            None => positions.push(point),
            Some(last) => {
                let d = point - last;
                let n = (d.length() / step).floor() as usize;
                for i in 1..=n.min(1000) {
                    positions.push(last + d.normalize_or_zero() * step * i as f32);
                }
            }
        }
        for p in positions {
            let a = self.rng.next_f32() * std::f32::consts::TAU;
            let r = self.rng.next_f32().sqrt() * brush.jitter.max(0.0) * brush.radius;
            let center = p + (right * a.cos() + up * a.sin()) * r;
            out.push(Particle::new(center, brush.radius.max(1e-4), brush.density.max(0.0)));
            self.last = Some(p);
        }
        out
    }
}

/// What a click hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Hit {
    Particle(usize),
    Light(usize),
}

/// Screen radius under which a light gizmo is picked.
pub const LIGHT_PICK_RADIUS: f32 = 10.0;

/// The nearest item to the camera whose screen footprint contains `pos`.
pub fn pick(project: &Project, view: &ViewProjection, pos: Pos2) -> Option<Hit> {
    let mut best: Option<(f32, Hit)> = None;
    for (i, l) in project.lights.iter().enumerate() {
        if let Some((s, z)) = view.project(l.position) {
            if s.distance(pos) <= LIGHT_PICK_RADIUS && best.is_none_or(|(bz, _)| z < bz) {
                best = Some((z, Hit::Light(i)));
            }
        }
    }
    if best.is_some() {
        return best.map(|b| b.1);
    }
    for (i, p) in project.particles.iter().enumerate() {
        if p.hidden {
            continue;
        }
        if let Some((s, z)) = view.project(p.center) {
            let r = (p.radius * view.points_per_metre(z)).max(4.0);
            if s.distance(pos) <= r && best.is_none_or(|(bz, _)| z < bz) {
                best = Some((z, Hit::Particle(i)));
            }
        }
    }
    best.map(|b| b.1)
}

/// Items whose centres project inside `rect`.
pub fn box_select(project: &Project, view: &ViewProjection, rect: Rect) -> (BTreeSet<usize>, BTreeSet<usize>) {
    let inside = |c: Vec3| view.project(c).is_some_and(|(s, _)| rect.contains(s));
    let particles = project
        .particles
        .iter()
        .enumerate()
        .filter(|(_, p)| !p.hidden && inside(p.center))
        .map(|(i, _)| i)
        .collect();
    let lights = project.lights.iter().enumerate().filter(|(_, l)| inside(l.position)).map(|(i, _)| i).collect();
    (particles, lights)
}

/// Visible particles whose centre lies within `radius` metres of the ray through `pos`.
pub fn under_brush(project: &Project, view: &ViewProjection, pos: Pos2, radius: f32) -> BTreeSet<usize> {
    let dir = view.ray(pos);
    project
        .particles
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            let d = p.center - view.position;
            let t = d.dot(dir);
            !p.hidden && t > 0.0 && (d - dir * t).length_squared() <= radius * radius
        })
        .map(|(i, _)| i)
        .collect()
}

/// The working plane: through the grid centre, facing the camera.
pub fn working_plane_point(project: &Project, view: &ViewProjection, pos: Pos2) -> Option<Vec3> {
    let center = (project.grid.min + project.grid.max) * 0.5;
    view.on_view_plane(pos, center)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_stroke_follows_the_spacing() {
        let brush = Brush { radius: 0.1, density: 1.0, spacing: 0.5, jitter: 0.0 };
        let mut s = Stroke::new(3);
        assert_eq!(s.dabs_to(Vec3::ZERO, Vec3::X, Vec3::Y, &brush).len(), 1);
        let dabs = s.dabs_to(Vec3::new(0.52, 0.0, 0.0), Vec3::X, Vec3::Y, &brush);
        assert_eq!(dabs.len(), 10);
        assert!((dabs[9].center.x - 0.5).abs() < 1e-5);
        assert!(s.dabs_to(Vec3::new(0.53, 0.0, 0.0), Vec3::X, Vec3::Y, &brush).is_empty());
    }

    #[test]
    fn jitter_stays_within_the_brush() {
        let brush = Brush { radius: 0.2, density: 1.0, spacing: 0.1, jitter: 0.5 };
        let mut s = Stroke::new(9);
        s.dabs_to(Vec3::ZERO, Vec3::X, Vec3::Y, &brush);
        for d in s.dabs_to(Vec3::new(1.0, 0.0, 0.0), Vec3::X, Vec3::Y, &brush) {
            assert!(d.center.y.abs() <= 0.1 + 1e-5 && d.center.z == 0.0);
        }
    }
}

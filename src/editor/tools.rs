//! Viewport tools and the geometry behind them: the tools, the brush and its dabs, where paint
//! lands (the fog's depth or the working plane). Picking is the view's (`view`), named here
//! too for the tools' callers.
//! Pure functions of the project and the view, so tests can check them without a window.

use super::view::ViewProjection;
pub use super::view::{box_select, box_select_with, pick, pick_with, under_brush, Hit, LIGHT_PICK_RADIUS};
use crate::scene::{GridSpec, Particle, Project};
use egui::Pos2;
use glam::Vec3;
use serde::{Deserialize, Serialize};

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
    pub fn tooltip(self) -> &'static str {
        match self {
            Tool::Select => "Select / Move: click to select, Shift/Ctrl-click to add or toggle, drag on empty space for a box, drag a selected item to move it in the view plane. The move gizmo at the selection's centre: drag an arrow to move along x, y or z, a square to move in that plane (Ctrl snaps the centre to a grid cell's centre, Esc or right click cancels). G grabs, S scales the selection.",
            Tool::Paint => "Paint: click or drag to deposit particles at the depth of the fog under the cursor (where its optical depth from the camera reaches 0.5), or on the working plane (through the grid centre, facing the camera) where there is no fog or when the brush is set to the plane. A stroke stays at the depth where it began. In the Slices panel, paints on the slice plane.",
            Tool::Scale => "Scale: wheel or horizontal drag grows/shrinks the radius of the selection, or of the particles under the brush when nothing is selected. Hold Alt to change density instead.",
            Tool::Erase => "Erase: click or drag to remove the particles under the brush (through all depths).",
            Tool::Light => "Light: click empty space to add a light on the working plane, drag a light to move it.",
        }
    }
}

/// Where Paint puts a stroke along the view ray.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum PaintDepth {
    /// Where the fog under the cursor starts: the first point along the ray where the
    /// optical depth reaches [`FOG_DEPTH_TAU`]; the working plane where the ray never does.
    #[default]
    Fog,
    /// The working plane: through the grid centre, facing the camera.
    Plane,
}

/// Optical depth from the camera at which Paint finds the fog's surface: e^−0.5 ≈ 61 % of the
/// light still gets through, so the point is where the fog visibly begins.
pub const FOG_DEPTH_TAU: f32 = 0.5;

/// The first point along `origin + t·dir` (unit `dir`) where the optical depth through `ev`
/// (nearest cell, steps of half the smallest cell edge, inside the grid box) reaches `tau`;
/// None when it never does.
pub fn fog_depth_point(ev: &crate::scene::Volume, origin: Vec3, dir: Vec3, tau: f32) -> Option<Vec3> {
    let g = &ev.grid;
    let (t0, t1) = ray_in_box(g, origin, dir)?;
    let cell = g.cell_size();
    let dt = 0.5 * cell.min_element();
    let n = g.resolution.as_ivec3();
    let mut acc = 0.0f32;
    let mut t = t0;
    while t < t1 {
        let step = dt.min(t1 - t);
        let p = origin + dir * (t + 0.5 * step);
        let c = ((p - g.min) / cell).floor().as_ivec3().clamp(glam::IVec3::ZERO, n - 1);
        let sigma = ev.get(c.x as u32, c.y as u32, c.z as u32).max(0.0);
        if acc + sigma * step >= tau {
            return Some(origin + dir * (t + (tau - acc) / sigma));
        }
        acc += sigma * step;
        t += step;
    }
    None
}

/// The part `t0..t1` (t0 ≥ 0) of the ray `origin + t·dir` inside `grid`'s box; None when the
/// ray misses the box.
fn ray_in_box(g: &GridSpec, origin: Vec3, dir: Vec3) -> Option<(f32, f32)> {
    let inv = dir.recip();
    let (ta, tb) = ((g.min - origin) * inv, (g.max - origin) * inv);
    let t0 = ta.min(tb).max_element().max(0.0);
    let t1 = ta.max(tb).min_element();
    // Also rejects NaN bounds.
    if t0.partial_cmp(&t1) != Some(std::cmp::Ordering::Less) || !t0.is_finite() || !t1.is_finite() {
        return None;
    }
    Some((t0, t1))
}

/// `point`, a point of the ray `origin + t·dir` (unit `dir`), moved along the ray to the
/// nearest point inside `grid`'s box: where Paint may lay a dab. None when the ray misses the
/// box, so that no painted fog lands where the grid cannot hold it.
pub fn into_grid_along_ray(grid: &GridSpec, origin: Vec3, dir: Vec3, point: Vec3) -> Option<Vec3> {
    let (t0, t1) = ray_in_box(grid, origin, dir)?;
    let inset = 1e-4 * (t1 - t0);
    let t = (point - origin).dot(dir).clamp(t0 + inset, t1 - inset);
    Some((origin + dir * t).clamp(grid.min, grid.max))
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
    /// Where Paint puts a stroke along the view ray.
    pub depth: PaintDepth,
    /// Whether painted particles take the medium's noise (their `noise` flag).
    pub noise: bool,
}

impl Default for Brush {
    fn default() -> Self {
        Self { radius: 0.15, density: 2.0, spacing: 0.5, jitter: 0.3, depth: PaintDepth::Fog, noise: true }
    }
}

/// A paint stroke in progress: where the last dab went, so dabs follow the spacing.
#[derive(Clone, Debug)]
pub struct Stroke {
    pub tag: super::session::EditTag,
    last: Option<Vec3>,
    /// The jitter of its dabs, seeded by its tag.
    rng: crate::rng::XorShiftStar,
    /// A point of the plane (facing the camera) the stroke paints on, fixed where it began:
    /// at the fog's depth or on the working plane.
    pub anchor: Option<Vec3>,
    /// Whether the pointer's last position looks past the grid box, where nothing is painted.
    pub outside: bool,
}

impl Stroke {
    pub fn new(tag: super::session::EditTag) -> Self {
        Self { tag, last: None, rng: crate::rng::XorShiftStar::new(tag), anchor: None, outside: false }
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
            let a = self.rng.f32() * std::f32::consts::TAU;
            let r = self.rng.f32().sqrt() * brush.jitter.max(0.0) * brush.radius;
            let center = p + (right * a.cos() + up * a.sin()) * r;
            let mut dab = Particle::new(center, brush.radius.max(1e-4), brush.density.max(0.0));
            dab.noise = brush.noise;
            out.push(dab);
            self.last = Some(p);
        }
        out
    }
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
    fn fog_depth_is_where_the_optical_depth_reaches_the_threshold() {
        use crate::scene::{GridSpec, Volume};
        let grid = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: glam::UVec3::new(4, 4, 16) };
        // Empty for z < 0.5, σ = 2/m beyond: τ = 0.5 is reached 0.25 m into the fog.
        let data = (0..grid.cell_count() as usize).map(|i| if grid.cell_of(i)[2] >= 8 { 2.0 } else { 0.0 }).collect();
        let ev = Volume::new(grid, data);
        let hit = fog_depth_point(&ev, Vec3::new(0.5, 0.5, -3.0), Vec3::Z, 0.5).unwrap();
        assert!((hit.z - 0.75).abs() < 1e-5, "{hit:?}");
        assert_eq!(fog_depth_point(&ev, Vec3::new(0.5, 0.5, -3.0), Vec3::Z, 1.5), None, "only τ = 1 in the box");
        assert_eq!(fog_depth_point(&ev, Vec3::new(0.5, 0.5, -3.0), -Vec3::Z, 0.5), None, "pointing away");
    }

    #[test]
    fn a_stroke_follows_the_spacing() {
        let brush =
            Brush { radius: 0.1, density: 1.0, spacing: 0.5, jitter: 0.0, depth: PaintDepth::Plane, noise: true };
        let mut s = Stroke::new(3);
        assert_eq!(s.dabs_to(Vec3::ZERO, Vec3::X, Vec3::Y, &brush).len(), 1);
        let dabs = s.dabs_to(Vec3::new(0.52, 0.0, 0.0), Vec3::X, Vec3::Y, &brush);
        assert_eq!(dabs.len(), 10);
        assert!((dabs[9].center.x - 0.5).abs() < 1e-5);
        assert!(s.dabs_to(Vec3::new(0.53, 0.0, 0.0), Vec3::X, Vec3::Y, &brush).is_empty());
    }

    #[test]
    fn jitter_stays_within_the_brush() {
        let brush =
            Brush { radius: 0.2, density: 1.0, spacing: 0.1, jitter: 0.5, depth: PaintDepth::Plane, noise: false };
        let mut s = Stroke::new(9);
        s.dabs_to(Vec3::ZERO, Vec3::X, Vec3::Y, &brush);
        for d in s.dabs_to(Vec3::new(1.0, 0.0, 0.0), Vec3::X, Vec3::Y, &brush) {
            assert!(d.center.y.abs() <= 0.1 + 1e-5 && d.center.z == 0.0);
            assert!(!d.noise, "the brush's noise toggle reaches its dabs");
        }
    }
}

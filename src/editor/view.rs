//! The view: the project camera mapped onto the viewport rectangle. Projecting the scene
//! onto it (for overlays, matching [`Camera::ray_dir`] exactly), the ray through a point of
//! it, what lies under a point or inside a box of it (picking: the scan, or the particle
//! bins of `pick_index` in large scenes, with the same answer), and the orbit / pan / zoom
//! camera moves that change it.

use super::pick_index::{Bin, ParticleIndex, SLACK};
use crate::scene::{Camera, GridSpec, Particle, Project};
use egui::{Pos2, Rect};
use glam::Vec3;
use std::collections::BTreeSet;

/// The project camera mapped onto a screen rectangle.
#[derive(Clone, Copy, Debug)]
pub struct ViewProjection {
    pub rect: Rect,
    pub position: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
    tan_half: f32,
    aspect: f32,
}

impl ViewProjection {
    pub fn new(camera: &Camera, rect: Rect) -> Self {
        let (right, up, forward) = camera.basis();
        let aspect = (rect.width() / rect.height().max(1.0)).max(1e-3);
        Self {
            rect,
            position: camera.position,
            right,
            up,
            forward,
            tan_half: (camera.fov_y_deg.to_radians() * 0.5).tan(),
            aspect,
        }
    }

    /// Screen position and view depth of a world point, or `None` behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(Pos2, f32)> {
        let d = p - self.position;
        let z = d.dot(self.forward);
        if z <= 1e-4 {
            return None;
        }
        let sx = d.dot(self.right) / (z * self.tan_half * self.aspect);
        let sy = d.dot(self.up) / (z * self.tan_half);
        let x = self.rect.min.x + (sx + 1.0) * 0.5 * self.rect.width();
        let y = self.rect.min.y + (1.0 - sy) * 0.5 * self.rect.height();
        Some((Pos2::new(x, y), z))
    }

    /// Unit direction of the ray through a screen point.
    pub fn ray(&self, pos: Pos2) -> Vec3 {
        let u = (pos.x - self.rect.min.x) / self.rect.width().max(1.0);
        let v = (pos.y - self.rect.min.y) / self.rect.height().max(1.0);
        let sx = (u * 2.0 - 1.0) * self.tan_half * self.aspect;
        let sy = (1.0 - v * 2.0) * self.tan_half;
        (self.forward + self.right * sx + self.up * sy).normalize()
    }

    /// Screen points per metre at view depth `z`.
    pub fn points_per_metre(&self, z: f32) -> f32 {
        self.rect.height() / (2.0 * self.tan_half * z.max(1e-4))
    }

    /// Where the ray through `pos` meets the plane through `point` facing the camera.
    pub fn on_view_plane(&self, pos: Pos2, point: Vec3) -> Option<Vec3> {
        let dir = self.ray(pos);
        let denom = dir.dot(self.forward);
        if denom <= 1e-6 {
            return None;
        }
        let t = (point - self.position).dot(self.forward) / denom;
        (t > 0.0).then(|| self.position + dir * t)
    }

    /// World displacement, in the view plane at depth `z`, of a screen drag `delta`.
    pub fn drag_to_world(&self, delta: egui::Vec2, z: f32) -> Vec3 {
        let s = 1.0 / self.points_per_metre(z);
        self.right * (delta.x * s) - self.up * (delta.y * s)
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
    pick_with(project, None, view, pos)
}

/// [`pick`], through `index` (built from the project's particles) when given: the same answer.
pub fn pick_with(project: &Project, index: Option<&ParticleIndex>, view: &ViewProjection, pos: Pos2) -> Option<Hit> {
    let mut best: Option<(f32, Hit)> = None;
    for (i, l) in project.lights.iter().enumerate() {
        if let Some((s, z)) = view.project(project.light_anchor(l)) {
            if s.distance(pos) <= LIGHT_PICK_RADIUS && best.is_none_or(|(bz, _)| z < bz) {
                best = Some((z, Hit::Light(i)));
            }
        }
    }
    if best.is_some() {
        return best.map(|b| b.1);
    }
    if let Some(index) = index.filter(|ix| ix.fits(&project.particles)) {
        return index.pick(&project.particles, view, pos).map(|(_, i)| Hit::Particle(i));
    }
    for (i, p) in project.particles.iter().enumerate() {
        if let Some(z) = pick_depth(p, view, pos) {
            if best.is_none_or(|(bz, _)| z < bz) {
                best = Some((z, Hit::Particle(i)));
            }
        }
    }
    best.map(|b| b.1)
}

/// Items whose centres project inside `rect`.
pub fn box_select(project: &Project, view: &ViewProjection, rect: Rect) -> (BTreeSet<usize>, BTreeSet<usize>) {
    box_select_with(project, None, view, rect)
}

/// [`box_select`], through `index` (built from the project's particles) when given: the same
/// answer.
pub fn box_select_with(
    project: &Project,
    index: Option<&ParticleIndex>,
    view: &ViewProjection,
    rect: Rect,
) -> (BTreeSet<usize>, BTreeSet<usize>) {
    let inside = |c: Vec3| view.project(c).is_some_and(|(s, _)| rect.contains(s));
    let particles = match index.filter(|ix| ix.fits(&project.particles)) {
        Some(index) => index.box_select(&project.particles, view, rect),
        None => (0..project.particles.len()).filter(|&i| in_box(&project.particles[i], view, rect)).collect(),
    };
    let lights =
        project.lights.iter().enumerate().filter(|(_, l)| inside(project.light_anchor(l))).map(|(i, _)| i).collect();
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

/// What a view picks through the bins.
impl ParticleIndex {
    /// The particle [`tools::pick`](super::tools::pick) picks at `pos` among `particles` (its
    /// view depth and index), or None; exactly the full scan's answer, ties included.
    pub fn pick(&self, particles: &[Particle], view: &ViewProjection, pos: Pos2) -> Option<(f32, usize)> {
        self.pick_counted(particles, view, pos).0
    }

    /// [`pick`](Self::pick), and how many particles it tested (for tests and benchmarks).
    pub fn pick_counted(
        &self,
        particles: &[Particle],
        view: &ViewProjection,
        pos: Pos2,
    ) -> (Option<(f32, usize)>, usize) {
        let degenerate = degenerate(view);
        let dir = view.ray(pos);
        let a = view.points_per_metre(1.0);
        let mut best: Option<(f32, usize)> = None;
        let mut tested = 0;
        let keep = |b: &Bin| {
            if degenerate {
                return true;
            }
            let d = b.center - view.position;
            let slack = SLACK * (d.length() + b.radius);
            let z_far = d.dot(view.forward) + b.radius + slack;
            if z_far <= 1e-4 {
                return false;
            }
            // A hit lies within max(radius, 4 points at its depth) of the ray, sideways at its
            // depth, so at least that close to the ray's line.
            let reach = b.max_particle.max(4.0 * z_far / a);
            let off_line = (d - dir * d.dot(dir)).length();
            off_line - b.radius <= reach * (1.0 + SLACK) + slack
        };
        for i in self.candidates(keep) {
            tested += 1;
            if let Some(z) = pick_depth(&particles[i], view, pos) {
                if best.is_none_or(|(bz, bi)| z < bz || (z == bz && i < bi)) {
                    best = Some((z, i));
                }
            }
        }
        (best, tested)
    }

    /// The visible particles whose centres project inside `rect`: exactly
    /// [`tools::box_select`](super::tools::box_select)'s particles.
    pub fn box_select(&self, particles: &[Particle], view: &ViewProjection, rect: Rect) -> BTreeSet<usize> {
        let degenerate = degenerate(view) || !rect.is_finite();
        // The wedge of the rect's screen bounds: X ≥ x0·Z, X ≤ x1·Z, likewise Y, in camera terms.
        let (kx, ky) = (1.0 / view.points_per_metre(1.0), 1.0 / view.points_per_metre(1.0));
        let centre = view.rect.center();
        let x0 = (rect.min.x - centre.x) * kx;
        let x1 = (rect.max.x - centre.x) * kx;
        let y0 = (centre.y - rect.max.y) * ky;
        let y1 = (centre.y - rect.min.y) * ky;
        let planes = [
            view.right - view.forward * x0,
            view.forward * x1 - view.right,
            view.up - view.forward * y0,
            view.forward * y1 - view.up,
        ];
        let keep = |b: &Bin| {
            if degenerate {
                return true;
            }
            let d = b.center - view.position;
            let slack = SLACK * (d.length() + b.radius);
            if d.dot(view.forward) + b.radius + slack <= 1e-4 {
                return false;
            }
            planes.iter().all(|n| n.dot(d) + b.radius * n.length() >= -slack * n.length())
        };
        self.candidates(keep).filter(|&i| in_box(&particles[i], view, rect)).collect()
    }
}

/// Whether the bin tests' geometry (screen offset = points_per_metre(z) × sideways offset)
/// fails for this view: below a point of width or height, or past the aspect's clamp. The
/// bins then all pass and the query is the scan.
fn degenerate(view: &ViewProjection) -> bool {
    let (w, h) = (view.rect.width(), view.rect.height());
    !(w >= 1.0 && h >= 1.0 && w / h >= 1e-3 && w.is_finite() && h.is_finite())
}

/// The scan's pick test for one particle: its view depth when `pos` falls on its footprint.
pub fn pick_depth(p: &Particle, view: &ViewProjection, pos: Pos2) -> Option<f32> {
    if p.hidden {
        return None;
    }
    let (s, z) = view.project(p.center)?;
    let r = (p.radius * view.points_per_metre(z)).max(4.0);
    (s.distance(pos) <= r).then_some(z)
}

/// The scan's box test for one particle.
pub fn in_box(p: &Particle, view: &ViewProjection, rect: Rect) -> bool {
    !p.hidden && view.project(p.center).is_some_and(|(s, _)| rect.contains(s))
}

/// Rotates the camera about its target: `dx`, `dy` in radians (yaw about +y, pitch).
pub fn orbit(camera: &Camera, dx: f32, dy: f32) -> Camera {
    let offset = camera.position - camera.target;
    let dist = offset.length().max(1e-4);
    let dir = offset / dist;
    let yaw = dir.z.atan2(dir.x) - dx;
    let pitch = (dir.y.clamp(-1.0, 1.0).asin() + dy).clamp(-1.50, 1.50);
    let new_dir = Vec3::new(pitch.cos() * yaw.cos(), pitch.sin(), pitch.cos() * yaw.sin());
    Camera { position: camera.target + new_dir * dist, up: Vec3::Y, ..*camera }
}

/// Slides camera and target in the view plane by a screen drag of `delta` points in a view
/// `height` points tall.
pub fn pan(camera: &Camera, delta: egui::Vec2, height: f32) -> Camera {
    let (right, up, _) = camera.basis();
    let dist = (camera.position - camera.target).length();
    let scale = 2.0 * (camera.fov_y_deg.to_radians() * 0.5).tan() * dist / height.max(1.0);
    let shift = (-right * delta.x + up * delta.y) * scale;
    Camera { position: camera.position + shift, target: camera.target + shift, ..*camera }
}

/// Moves the camera towards (factor < 1) or away from (factor > 1) its target.
pub fn zoom(camera: &Camera, factor: f32) -> Camera {
    let offset = camera.position - camera.target;
    let dist = (offset.length() * factor).clamp(0.01, 1.0e4);
    Camera { position: camera.target + offset.normalize_or(Vec3::Z) * dist, ..*camera }
}

/// Frames a sphere: aims at `center` from the current direction at a distance that fits `radius`.
pub fn frame(camera: &Camera, center: Vec3, radius: f32) -> Camera {
    let dir = (camera.position - camera.target).normalize_or(Vec3::Z);
    let half = (camera.fov_y_deg.to_radians() * 0.5).max(0.05);
    let dist = (radius.max(0.01) / half.sin()) * 1.1;
    Camera { position: center + dir * dist, target: center, ..*camera }
}

/// Axis-aligned views for numpad keys and the View menu.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AxisView {
    Front,
    Back,
    Right,
    Left,
    Top,
}

/// Looks at the grid centre from `view`, keeping the current distance.
pub fn axis_view(camera: &Camera, grid: &GridSpec, view: AxisView) -> Camera {
    let center = (grid.min + grid.max) * 0.5;
    let dist = (camera.position - camera.target).length().max(0.1);
    let (dir, up) = match view {
        AxisView::Front => (Vec3::Z, Vec3::Y),
        AxisView::Back => (Vec3::NEG_Z, Vec3::Y),
        AxisView::Right => (Vec3::X, Vec3::Y),
        AxisView::Left => (Vec3::NEG_X, Vec3::Y),
        AxisView::Top => (Vec3::Y, Vec3::NEG_Z),
    };
    Camera { position: center + dir * dist, target: center, up, ..*camera }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_matches_camera_rays() {
        let cam = Camera::default();
        let rect = Rect::from_min_size(Pos2::new(10.0, 20.0), egui::vec2(640.0, 360.0));
        let vp = ViewProjection::new(&cam, rect);
        let d = cam.ray_dir(100, 50, 640, 360);
        let p = cam.position + d * 3.0;
        let (s, _) = vp.project(p).unwrap();
        assert!((s.x - (10.0 + 100.5)).abs() < 1e-2 && (s.y - (20.0 + 50.5)).abs() < 1e-2, "{s:?}");
        assert!((vp.ray(s) - d).length() < 1e-5);
    }

    #[test]
    fn orbit_keeps_distance_and_target() {
        let cam = Camera::default();
        let c = orbit(&cam, 0.3, 0.2);
        assert!(((c.position - c.target).length() - (cam.position - cam.target).length()).abs() < 1e-4);
        assert_eq!(c.target, cam.target);
    }
}

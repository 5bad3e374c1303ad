//! Viewport geometry: projecting the scene through the project camera onto the viewport
//! rectangle (for overlays and picking, matching [`Camera::ray_dir`] exactly), and the
//! orbit / pan / zoom camera moves.

use crate::scene::{Camera, GridSpec};
use egui::{Pos2, Rect};
use glam::Vec3;

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

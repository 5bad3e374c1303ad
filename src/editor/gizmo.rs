//! The move gizmo at the selection's centre: three axis arrows (x red, y green, z blue, the
//! slice plane's colours) and three plane squares, drawn at a constant size on screen.
//! Its handles' places on screen (laid out once per view), picking one, and turning the
//! pointer into a displacement along its axis (the point of the axis nearest the pointer's
//! ray) or in its plane (where the ray meets the plane).
//! Pure geometry, so tests can check it without a window.

use super::view::ViewProjection;
use egui::Pos2;
use glam::Vec3;

/// Length of an arrow on screen, in points.
pub const ARROW_POINTS: f32 = 90.0;
/// The colour of the handle under the pointer or being dragged.
pub const LIT: egui::Color32 = egui::Color32::from_rgb(255, 230, 120);
/// How close to an arrow (in points) the pointer must be to pick it.
pub const PICK_POINTS: f32 = 8.0;
/// A plane square spans this part of the arrows' length along both of its axes.
const PLANE_SPAN: (f32, f32) = (0.22, 0.42);
/// Arrows shorter than this on screen (pointing at the viewer) cannot be picked, nor
/// planes seen nearly edge-on.
const MIN_SCREEN: f32 = 12.0;

/// A handle of the gizmo.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Handle {
    /// Moves along world axis 0, 1 or 2.
    Axis(usize),
    /// Moves in the plane whose normal is world axis 0, 1 or 2.
    Plane(usize),
}

impl Handle {
    /// Which components of a displacement this handle may change.
    pub fn mask(self) -> Vec3 {
        match self {
            Handle::Axis(a) => Vec3::AXES[a],
            Handle::Plane(n) => Vec3::ONE - Vec3::AXES[n],
        }
    }
}

/// The gizmo at `center` as seen through a view, with its handles laid out on screen.
#[derive(Clone, Copy, Debug)]
pub struct Gizmo {
    pub center: Vec3,
    /// The arrows' length in metres: [`ARROW_POINTS`] on screen at the centre's depth.
    pub length: f32,
    pub screen: Pos2,
    arrows: [Option<(Pos2, Pos2)>; 3],
    squares: [Option<[Pos2; 4]>; 3],
}

impl Gizmo {
    /// None when the centre is behind the camera.
    pub fn new(center: Vec3, vp: &ViewProjection) -> Option<Self> {
        let (screen, z) = vp.project(center)?;
        let length = ARROW_POINTS / vp.points_per_metre(z);
        let arrow = |a: usize| {
            let (tip, _) = vp.project(center + Vec3::AXES[a] * length)?;
            (tip.distance(screen) >= MIN_SCREEN).then_some((screen, tip))
        };
        let square = |n: usize| {
            let (u, v) = (Vec3::AXES[(n + 1) % 3] * length, Vec3::AXES[(n + 2) % 3] * length);
            let (a, b) = PLANE_SPAN;
            let corners = [u * a + v * a, u * b + v * a, u * b + v * b, u * a + v * b];
            let mut out = [Pos2::ZERO; 4];
            for (o, c) in out.iter_mut().zip(corners) {
                *o = vp.project(center + c)?.0;
            }
            let area =
                0.5 * ((out[2] - out[0]).x * (out[3] - out[1]).y - (out[2] - out[0]).y * (out[3] - out[1]).x).abs();
            (area >= MIN_SCREEN * MIN_SCREEN * 0.25).then_some(out)
        };
        Some(Self { center, length, screen, arrows: [0, 1, 2].map(arrow), squares: [0, 1, 2].map(square) })
    }

    /// The arrow of axis `a` on screen (from the centre to its tip), if it is long enough
    /// to pick.
    pub fn arrow(&self, a: usize) -> Option<(Pos2, Pos2)> {
        self.arrows[a]
    }

    /// The square of the plane with normal `n` on screen, if it is not seen edge-on.
    pub fn square(&self, n: usize) -> Option<[Pos2; 4]> {
        self.squares[n]
    }

    /// The handle under `pos`: a plane square containing it, else the nearest arrow within
    /// [`PICK_POINTS`] (past the squares' inner corner, so the centre stays free).
    pub fn handle_at(&self, pos: Pos2) -> Option<Handle> {
        for n in 0..3 {
            if self.square(n).is_some_and(|q| inside_convex(&q, pos)) {
                return Some(Handle::Plane(n));
            }
        }
        let mut best: Option<(f32, Handle)> = None;
        for a in 0..3 {
            let Some((from, tip)) = self.arrow(a) else { continue };
            let d = distance_to_segment(pos, from + (tip - from) * 0.15, tip + (tip - from).normalized() * 6.0);
            if d <= PICK_POINTS && best.is_none_or(|(bd, _)| d < bd) {
                best = Some((d, Handle::Axis(a)));
            }
        }
        best.map(|b| b.1)
    }
}

/// The point the pointer at `pos` designates for `handle` of a gizmo at `center`: on the
/// axis line, the point nearest the pointer's ray; on a plane, where the ray meets it. None
/// where that point is undefined or behind the camera (an axis along the view ray, a plane
/// seen edge-on).
pub fn drag_point(handle: Handle, center: Vec3, vp: &ViewProjection, pos: Pos2) -> Option<Vec3> {
    let (o, d) = (vp.position, vp.ray(pos));
    match handle {
        Handle::Axis(a) => {
            let e = Vec3::AXES[a];
            let w = center - o;
            let b = e.dot(d);
            let denom = 1.0 - b * b;
            if denom < 1e-5 {
                return None;
            }
            let s = (b * w.dot(d) - w.dot(e)) / denom;
            let t = w.dot(d) + s * b;
            (t > 0.0 && s.is_finite()).then(|| center + e * s)
        }
        Handle::Plane(n) => {
            let normal = Vec3::AXES[n];
            let denom = d.dot(normal);
            if denom.abs() < 1e-4 {
                return None;
            }
            let t = (center - o).dot(normal) / denom;
            (t > 0.0 && t.is_finite()).then(|| o + d * t)
        }
    }
}

/// Snapping a drag to the grid: the gizmo's centre (where the drag started) lands on the
/// nearest cell centre along each axis the handle moves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Snap {
    pub center: Vec3,
    pub grid_min: Vec3,
    pub cell: Vec3,
}

/// The displacement of a drag on `handle` from `grab` to `point`: only along the handle's
/// axis or in its plane; with `snap`, such that the moved centre sits on a cell centre.
pub fn displacement(handle: Handle, grab: Vec3, point: Vec3, snap: Option<Snap>) -> Vec3 {
    let mask = handle.mask();
    let mut d = Vec3::select(mask.cmpeq(Vec3::ZERO), Vec3::ZERO, point - grab);
    if let Some(s) = snap {
        for a in 0..3 {
            if mask[a] != 0.0 && s.cell[a] > 0.0 {
                let k = ((s.center[a] + d[a] - s.grid_min[a]) / s.cell[a] - 0.5).round();
                d[a] = s.grid_min[a] + (k + 0.5) * s.cell[a] - s.center[a];
            }
        }
    }
    d
}

fn distance_to_segment(p: Pos2, a: Pos2, b: Pos2) -> f32 {
    let ab = b - a;
    let t = ((p - a).dot(ab) / ab.length_sq().max(1e-6)).clamp(0.0, 1.0);
    p.distance(a + ab * t)
}

fn inside_convex(q: &[Pos2; 4], p: Pos2) -> bool {
    let cross = |a: Pos2, b: Pos2| (b - a).x * (p - a).y - (b - a).y * (p - a).x;
    let signs: Vec<f32> = (0..4).map(|i| cross(q[i], q[(i + 1) % 4])).collect();
    signs.iter().all(|&s| s >= 0.0) || signs.iter().all(|&s| s <= 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;

    fn front_view() -> ViewProjection {
        let camera = Camera { position: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 };
        ViewProjection::new(&camera, egui::Rect::from_min_size(Pos2::ZERO, egui::vec2(800.0, 600.0)))
    }

    #[test]
    fn arrows_pick_and_drag_along_their_axis_only() {
        let vp = front_view();
        let g = Gizmo::new(Vec3::ZERO, &vp).unwrap();
        let (_, tip) = g.arrow(0).unwrap();
        assert!((tip.x - g.screen.x - ARROW_POINTS).abs() < 1e-3 && (tip.y - g.screen.y).abs() < 1e-3, "{tip:?}");
        assert!(g.arrow(2).is_none(), "the z arrow points at the viewer");
        let grab_pos = g.screen + egui::vec2(60.0, 3.0);
        assert_eq!(g.handle_at(grab_pos), Some(Handle::Axis(0)));
        assert_eq!(g.handle_at(g.screen + egui::vec2(3.0, -60.0)), Some(Handle::Axis(1)));
        assert_eq!(g.handle_at(g.screen + egui::vec2(30.0, -30.0)), Some(Handle::Plane(2)));
        assert_eq!(g.handle_at(g.screen + egui::vec2(60.0, 40.0)), None);
        let grab = drag_point(Handle::Axis(0), g.center, &vp, g.screen + egui::vec2(60.0, 0.0)).unwrap();
        let to = drag_point(Handle::Axis(0), g.center, &vp, g.screen + egui::vec2(140.0, 0.0)).unwrap();
        let d = displacement(Handle::Axis(0), grab, to, None);
        let ppm = vp.points_per_metre(5.0);
        assert!((d.x - 80.0 / ppm).abs() < 1e-5 && d.y == 0.0 && d.z == 0.0, "{d:?}");
        let snap = Snap { center: g.center, grid_min: Vec3::splat(-1.0), cell: Vec3::splat(0.25) };
        let snapped = displacement(Handle::Axis(0), grab, to, Some(snap));
        let moved = g.center + snapped;
        let k = (moved.x + 1.0) / 0.25 - 0.5;
        assert!((k - k.round()).abs() < 1e-4, "{moved} is on a cell centre");
        assert!((snapped.x - d.x).abs() <= 0.125 + 1e-5, "{snapped} is within half a cell of {d}");
        assert_eq!((snapped.y, snapped.z), (0.0, 0.0));
    }

    #[test]
    fn planes_move_within_the_plane() {
        let vp = front_view();
        let c = Vec3::new(0.2, -0.1, 0.0);
        let p = drag_point(Handle::Plane(2), c, &vp, Pos2::new(500.0, 200.0)).unwrap();
        assert!(p.z.abs() < 1e-5, "{p:?}");
        assert_eq!(drag_point(Handle::Plane(1), c, &vp, Pos2::new(400.0, 300.0)), None, "seen edge-on");
        let d = displacement(Handle::Plane(0), Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0), None);
        assert_eq!(d, Vec3::new(0.0, 2.0, 3.0));
    }
}

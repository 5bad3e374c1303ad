//! Editing a light as an artist sees it: where a light stands in a view (a sun, which has
//! no position, stands outside the grid up-sun of its centre), moving that point (which
//! re-aims a sun), and turning a light into another kind without changing how brightly it
//! lights the grid's centre.

use super::{Light, LightKind, Project};
use glam::Vec3;

/// The kinds a light can be turned into, as the editor names them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightKindChoice {
    Point,
    Spot,
    Sun,
}

impl LightKindChoice {
    pub const ALL: [LightKindChoice; 3] = [LightKindChoice::Point, LightKindChoice::Spot, LightKindChoice::Sun];
    pub fn of(kind: &LightKind) -> Self {
        match kind {
            LightKind::Point => LightKindChoice::Point,
            LightKind::Spot { .. } => LightKindChoice::Spot,
            LightKind::Directional { .. } => LightKindChoice::Sun,
        }
    }
    pub fn label(self) -> &'static str {
        match self {
            LightKindChoice::Point => "point",
            LightKindChoice::Spot => "spot",
            LightKindChoice::Sun => "sun",
        }
    }
    /// The unit of [`Light::intensity`] for this kind.
    pub fn intensity_unit(self) -> &'static str {
        match self {
            LightKindChoice::Sun => " W/m²",
            _ => " W/sr",
        }
    }
}

/// The cone a point light gets when it becomes a spot, degrees.
pub const DEFAULT_SPOT_ANGLE_DEG: f32 = 30.0;
/// The blend a point light gets when it becomes a spot.
pub const DEFAULT_SPOT_BLEND: f32 = 0.15;

impl Project {
    fn grid_centre(&self) -> Vec3 {
        (self.grid.min + self.grid.max) * 0.5
    }

    /// How far outside the grid's centre a sun stands in views: beyond the grid's corners.
    pub fn sun_distance(&self) -> f32 {
        ((self.grid.max - self.grid.min).length() * 0.5 * 1.2).max(1e-3)
    }

    /// The point that stands for light `l` in views and is picked and dragged there: its
    /// position, or for a sun the point [`Self::sun_distance`] up-sun of the grid's centre.
    pub fn light_anchor(&self, l: &Light) -> Vec3 {
        match l.kind {
            LightKind::Directional { direction } => {
                self.grid_centre() - direction.normalize_or(Vec3::NEG_Y) * self.sun_distance()
            }
            _ => l.position,
        }
    }

    /// Puts `light` in the place of light `i` (a light made as another kind) and drops the
    /// animation tracks that no longer apply to it.
    pub fn replace_light(&mut self, i: usize, light: Light) {
        if let Some(l) = self.lights.get_mut(i) {
            *l = light;
        }
        self.drop_inapplicable_tracks();
    }

    /// Moves light `i`'s anchor by `delta`: a point or spot light moves; a sun turns to shine
    /// from the moved anchor towards the grid's centre.
    pub fn move_light(&mut self, i: usize, delta: Vec3) {
        let centre = self.grid_centre();
        let Some(anchor) = self.lights.get(i).map(|l| self.light_anchor(l)) else { return };
        let Some(l) = self.lights.get_mut(i) else { return };
        match &mut l.kind {
            LightKind::Directional { direction } => {
                let moved = anchor + delta;
                *direction = (centre - moved).normalize_or(*direction);
                l.position = moved;
            }
            _ => l.position += delta,
        }
    }

    /// Where a spot's aim handle sits: on its axis, a quarter of the sun distance out.
    pub fn spot_tip(&self, l: &Light) -> Option<Vec3> {
        match l.kind {
            LightKind::Spot { direction, .. } => {
                Some(l.position + direction.normalize_or(Vec3::NEG_Y) * self.sun_distance() * 0.25)
            }
            _ => None,
        }
    }

    /// Points spot `i`'s axis at `target`; false (nothing changed) for another kind or a
    /// target at the light itself.
    pub fn aim_spot(&mut self, i: usize, target: Vec3) -> bool {
        let Some(l) = self.lights.get_mut(i) else { return false };
        let to = target - l.position;
        match &mut l.kind {
            LightKind::Spot { direction, .. } if to.length_squared() > 0.0 => {
                *direction = to.normalize();
                true
            }
            _ => false,
        }
    }

    /// Light `i` turned into `kind`: it keeps its position, and it lights the grid's centre
    /// as brightly as before (fog aside). A point or spot light of I W/sr at distance d gives
    /// E = I/d² W/m² there, which a sun takes as its irradiance; a sun becomes a light at its
    /// stored position with I = E·d² (at its anchor when that position is unusable: not
    /// finite, or at the centre). A new spot aims at the centre (or along a sun's direction);
    /// a new sun shines from where the light stands towards the centre (or along a spot's
    /// axis). A round trip through the kinds gives back the light it started from.
    pub fn light_as_kind(&self, i: usize, kind: LightKindChoice) -> Option<Light> {
        let l = self.lights.get(i)?;
        let centre = self.grid_centre();
        let mut out = l.clone();
        if LightKindChoice::of(&l.kind) == kind {
            return Some(out);
        }
        let towards_centre = (centre - l.position).normalize_or(Vec3::NEG_Y);
        match (&l.kind, kind) {
            (LightKind::Directional { direction }, _) => {
                let near = 1e-4 * self.sun_distance();
                let usable = l.position.is_finite() && (centre - l.position).length() > near;
                out.position = if usable { l.position } else { self.light_anchor(l) };
                out.intensity = l.intensity * (centre - out.position).length_squared();
                out.kind = match kind {
                    LightKindChoice::Spot => LightKind::Spot {
                        direction: direction.normalize_or(Vec3::NEG_Y),
                        angle_deg: DEFAULT_SPOT_ANGLE_DEG,
                        blend: DEFAULT_SPOT_BLEND,
                    },
                    _ => LightKind::Point,
                };
            }
            (_, LightKindChoice::Sun) => {
                let d2 = (centre - l.position).length_squared().max(1e-6);
                let direction = match l.kind {
                    LightKind::Spot { direction, .. } => direction.normalize_or(towards_centre),
                    _ => towards_centre,
                };
                out.intensity = l.intensity / d2;
                out.kind = LightKind::Directional { direction };
            }
            (_, LightKindChoice::Spot) => {
                out.kind = LightKind::Spot {
                    direction: towards_centre,
                    angle_deg: DEFAULT_SPOT_ANGLE_DEG,
                    blend: DEFAULT_SPOT_BLEND,
                };
            }
            (_, LightKindChoice::Point) => out.kind = LightKind::Point,
        }
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn project(light: Light) -> Project {
        Project { lights: vec![light], ..Project::default() }
    }

    fn centre(p: &Project) -> Vec3 {
        (p.grid.min + p.grid.max) * 0.5
    }

    /// Every kind change keeps the irradiance at the grid's centre (with the spot aimed at it),
    /// and a round trip through the other kinds comes back to the same light's brightness.
    #[test]
    fn kind_changes_keep_the_centre_lit_as_before() {
        let mut rng = crate::rng::XorShift(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.f32() * 2.0 - 1.0;
        for _ in 0..50 {
            let base = Project::default();
            let c = centre(&base);
            let position = c + Vec3::new(next(), next(), next()) * 3.0 + Vec3::new(0.0, 0.2, 0.0);
            let p = project(Light::new(position, 1.0 + next().abs() * 10.0, Vec3::ONE));
            let irradiance = |p: &Project, l: &Light| match l.kind {
                LightKind::Directional { .. } => l.intensity,
                _ => l.intensity / (centre(p) - l.position).length_squared(),
            };
            let e0 = irradiance(&p, &p.lights[0]);
            for kind in LightKindChoice::ALL {
                let l = p.light_as_kind(0, kind).unwrap();
                assert_eq!(LightKindChoice::of(&l.kind), kind);
                let e = irradiance(&p, &l);
                assert!((e - e0).abs() <= 1e-4 * e0, "{kind:?}: {e} vs {e0}");
                if let LightKind::Spot { direction, .. } = l.kind {
                    assert!(direction.dot((c - l.position).normalize()) > 0.9999, "the spot aims at the centre");
                }
                let q = project(l);
                for back in LightKindChoice::ALL {
                    let m = q.light_as_kind(0, back).unwrap();
                    let e = irradiance(&q, &m);
                    assert!((e - e0).abs() <= 1e-3 * e0, "{kind:?} → {back:?}: {e} vs {e0}");
                }
            }
        }
    }

    /// Point → spot → sun → point (and every other order of the kinds) ends where it
    /// started, with the power it started with; a sun with no usable position stands at its
    /// anchor when it becomes a point light.
    #[test]
    fn a_round_trip_through_the_kinds_keeps_position_and_power() {
        let mut rng = crate::rng::XorShift(0x9e37_79b9_7f4a_7c15);
        let mut next = || rng.f32() * 2.0 - 1.0;
        use LightKindChoice::{Point, Spot, Sun};
        for _ in 0..50 {
            let c = centre(&Project::default());
            let position = c + Vec3::new(next(), next(), next()) * 4.0;
            let start = Light::new(position, 0.5 + next().abs() * 20.0, Vec3::ONE);
            for path in [[Spot, Sun, Point], [Sun, Spot, Point], [Sun, Point, Point], [Spot, Point, Point]] {
                let mut p = project(start.clone());
                for kind in path {
                    let l = p.light_as_kind(0, kind).unwrap();
                    assert!(
                        (l.position - position).length() < 1e-5,
                        "{path:?} at {kind:?}: {} vs {position}",
                        l.position
                    );
                    p.replace_light(0, l);
                }
                let l = &p.lights[0];
                assert!(matches!(l.kind, LightKind::Point));
                assert!(
                    (l.intensity - start.intensity).abs() <= 1e-4 * start.intensity,
                    "{path:?}: {} vs {}",
                    l.intensity,
                    start.intensity
                );
            }
        }
        let sun =
            Light { kind: LightKind::Directional { direction: Vec3::NEG_Y }, ..Light::new(Vec3::NAN, 2.0, Vec3::ONE) };
        let p = project(sun.clone());
        let l = p.light_as_kind(0, Point).unwrap();
        assert_eq!(l.position, p.light_anchor(&sun));
        assert!((l.intensity - 2.0 * p.sun_distance().powi(2)).abs() < 1e-3 * l.intensity);
    }

    /// A sun stands outside the grid up-sun of its centre; dragging that anchor re-aims it
    /// so it shines from the new anchor through the centre, and moves point lights as such.
    #[test]
    fn a_dragged_sun_re_aims_and_a_point_light_moves() {
        let mut p = project(Light {
            kind: LightKind::Directional { direction: Vec3::new(0.0, -1.0, 0.0) },
            ..Light::new(Vec3::ZERO, 3.0, Vec3::ONE)
        });
        let c = centre(&p);
        let anchor = p.light_anchor(&p.lights[0]);
        assert!((anchor - (c + Vec3::Y * p.sun_distance())).length() < 1e-5, "{anchor}");
        p.move_light(0, Vec3::new(p.sun_distance(), 0.0, 0.0));
        let LightKind::Directional { direction } = p.lights[0].kind else { panic!("still a sun") };
        let want = (c - (anchor + Vec3::new(p.sun_distance(), 0.0, 0.0))).normalize();
        assert!((direction - want).length() < 1e-5, "{direction} vs {want}");
        assert_eq!(p.lights[0].intensity, 3.0, "re-aiming keeps the irradiance");
        let mut q = project(Light::new(Vec3::ONE, 1.0, Vec3::ONE));
        q.move_light(0, Vec3::X);
        assert_eq!(q.lights[0].position, Vec3::new(2.0, 1.0, 1.0));
        assert_eq!(q.light_anchor(&q.lights[0]), q.lights[0].position);
    }
}

//! The medium's fractal value noise in f64 (the [`Noise`] doc defines it; the GPU's twin is
//! `shaders/noise.wgsl`), with the same integer hash, so the references hold the same medium
//! the injection bakes.

use crate::scene::{noise_hash, GridSpec, Noise};
use glam::DVec3;

/// A project's noise with the octaves its grid keeps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise64 {
    pub amplitude: f64,
    pub frequency: f64,
    /// Octaves evaluated: [`Noise::effective_octaves`] on the project's grid.
    pub octaves: u32,
    pub seed: u32,
    /// The drift of the pattern ([`Noise::offset`]), in f32 as the project holds it.
    pub offset: glam::Vec3,
}

impl Noise64 {
    /// `noise` on `grid`: the octaves above the grid's Nyquist limit dropped, as on the GPU.
    pub fn new(noise: &Noise, grid: &GridSpec) -> Self {
        Self {
            amplitude: noise.amplitude as f64,
            frequency: noise.frequency as f64,
            octaves: noise.effective_octaves(grid),
            seed: noise.seed,
            offset: noise.offset,
        }
    }

    /// n(x) in [−1, 1], without the drift: the pattern at its own coordinates.
    pub fn value(&self, x: DVec3) -> f64 {
        let (mut sum, mut norm, mut weight, mut frequency) = (0.0, 0.0, 1.0, self.frequency);
        for o in 0..self.octaves {
            sum += weight * value_noise(x * frequency, self.seed.wrapping_add(o));
            norm += weight;
            weight *= 0.5;
            frequency *= 2.0;
        }
        if norm > 0.0 {
            sum / norm
        } else {
            0.0
        }
    }

    /// The point of the pattern the medium shows at `x`: x − offset, with the project's f32
    /// offset, as on the GPU (which subtracts in f32, within an ulp of the larger of |x| and
    /// |offset|; the reference keeps f64 so that its quadrature sees a smooth integrand).
    pub fn drifted(&self, x: DVec3) -> DVec3 {
        x - self.offset.as_dvec3()
    }

    /// The factor on noisy particles' extinction: max(0, 1 + amplitude·n(x − offset)).
    pub fn modulation(&self, x: DVec3) -> f64 {
        (1.0 + self.amplitude * self.value(self.drifted(x))).max(0.0)
    }

    /// Lattice spacing of the finest octave evaluated, in metres.
    pub fn finest_spacing(&self) -> f64 {
        1.0 / (self.frequency * 2f64.powi(self.octaves.max(1) as i32 - 1))
    }
}

/// Lattice value h(i, j, k, s) = 2·(hash / 2³²) − 1.
pub fn lattice_value(i: i32, j: i32, k: i32, seed: u32) -> f64 {
    2.0 * (noise_hash(i, j, k, seed) as f64 / 4_294_967_296.0) - 1.0
}

/// 3D value noise at lattice coordinates `p`: trilinear with smoothstep weights. Lattice
/// indices are clamped to [−2³¹, 2³¹ − 128] (the f32 values i32 holds) and their neighbours
/// wrap, as on the GPU.
pub fn value_noise(p: DVec3, seed: u32) -> f64 {
    let f = p.floor();
    let t = p - f;
    let w = t * t * (DVec3::splat(3.0) - 2.0 * t);
    let c = [f.x, f.y, f.z].map(|v| v.clamp(-2_147_483_648.0, 2_147_483_520.0) as i32);
    let d = c.map(|v| v.wrapping_add(1));
    let h = |x: i32, y: i32, z: i32| lattice_value(x, y, z, seed);
    let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
    let x00 = lerp(h(c[0], c[1], c[2]), h(d[0], c[1], c[2]), w.x);
    let x10 = lerp(h(c[0], d[1], c[2]), h(d[0], d[1], c[2]), w.x);
    let x01 = lerp(h(c[0], c[1], d[2]), h(d[0], c[1], d[2]), w.x);
    let x11 = lerp(h(c[0], d[1], d[2]), h(d[0], d[1], d[2]), w.x);
    lerp(lerp(x00, x10, w.y), lerp(x01, x11, w.y), w.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec3, Vec3};

    fn grid(res: u32) -> GridSpec {
        GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(res) }
    }

    #[test]
    fn lattice_points_give_lattice_values_and_noise_is_continuous() {
        let n = Noise64::new(&Noise::new(1.0, 1.0, 1, 9), &grid(4));
        for (i, j, k) in [(0, 0, 0), (3, -2, 7), (-5, 1, -1)] {
            assert_eq!(n.value(DVec3::new(i as f64, j as f64, k as f64)), lattice_value(i, j, k, 9));
        }
        // Continuous across lattice planes, in [−1, 1] everywhere.
        let e = 1e-9;
        for s in 0..200 {
            let x = DVec3::new(s as f64 * 0.173 - 17.0, 2.0, s as f64 * 0.071);
            let on = DVec3::new(x.x, 2.0, x.z);
            assert!((n.value(on - DVec3::Y * e) - n.value(on + DVec3::Y * e)).abs() < 1e-7);
            assert!(n.value(x).abs() <= 1.0);
        }
    }

    #[test]
    fn octaves_are_weighted_and_normalised() {
        let noise = Noise::new(2.0, 1.0, 3, u32::MAX);
        let n = Noise64::new(&noise, &grid(64));
        assert_eq!(n.octaves, 3);
        let x = DVec3::new(0.3, -1.7, 2.2);
        let want = (value_noise(x, u32::MAX) + 0.5 * value_noise(2.0 * x, 0) + 0.25 * value_noise(4.0 * x, 1)) / 1.75;
        assert!((n.value(x) - want).abs() < 1e-15);
        assert_eq!(n.modulation(x), (1.0 + 2.0 * want).max(0.0));
        // Octaves finer than two cells are dropped: on 4 cells of 0.25 m, spacing 0.25 goes.
        assert_eq!(Noise64::new(&noise, &grid(4)).octaves, 2);
    }

    /// The noisy optical depth (adaptive quadrature between lattice crossings) against a
    /// fine midpoint sum of the extinction itself, for noise that clips (a = 4) and not.
    #[test]
    fn noisy_optical_depth_matches_fine_quadrature() {
        use crate::reference::Medium64;
        use crate::scene::{Particle, Project};
        let mut p = Project {
            grid: GridSpec { min: Vec3::splat(-1.0), max: Vec3::ONE, resolution: UVec3::splat(32) },
            particles: vec![
                Particle::new(Vec3::new(0.1, 0.0, -0.2), 0.5, 3.0),
                Particle::new(Vec3::new(-0.4, 0.3, 0.2), 0.2, 6.0),
            ],
            ..Project::default()
        };
        p.particles[1].noise = false;
        p.medium.base_extinction = 0.1;
        for amplitude in [0.5f32, 4.0] {
            p.medium.noise = Some(Noise::new(amplitude, 2.0, 4, 5));
            let m = Medium64::from_project(&p);
            for (a, b) in [
                (DVec3::new(-1.0, -0.3, -0.9), DVec3::new(1.0, 0.2, 0.7)),
                (DVec3::new(0.1, -1.0, 0.0), DVec3::new(0.1, 1.0, -0.2)),
            ] {
                let n = 400_000;
                let h = (b - a).length() / n as f64;
                let fine: f64 =
                    (0..n).map(|i| m.extinction(a + (b - a) * ((i as f64 + 0.5) / n as f64))).sum::<f64>() * h;
                let exact = m.optical_depth(a, b);
                assert!((exact - fine).abs() < 1e-7 * fine, "a = {amplitude}: {exact} vs {fine}");
                // The noise matters: without it the depth differs.
                let mut q = p.clone();
                q.medium.noise = None;
                assert!((Medium64::from_project(&q).optical_depth(a, b) - exact).abs() > 1e-3 * exact);
            }
        }
    }

    #[test]
    fn extreme_inputs_stay_finite() {
        let n = Noise64 { amplitude: 100.0, frequency: 1e6, octaves: 16, seed: u32::MAX, offset: glam::Vec3::ZERO };
        for x in [DVec3::splat(1e9), DVec3::splat(-1e9), DVec3::new(3.3e-7, 0.0, -2.0)] {
            let v = n.modulation(x);
            assert!(v.is_finite() && (0.0..=101.0).contains(&v), "{v}");
        }
    }
}

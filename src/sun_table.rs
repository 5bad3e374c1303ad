//! Sun et al. 2005's special function F(u, v) = ∫_0^v exp(−u tan ξ) dξ and the lookup tables
//! a shader can afford (physics.md §6): what the GPU's homogeneous-fog shortcut reads, built
//! here so that production code does not depend on the reference. `reference::sun` measures
//! the tables against the exact closed form.
//!
//! Why a second table layout: the paper's evaluation subtracts two table values of F and
//! multiplies by A0 ∝ exp(−T_sv cosγ). Looking away from a light through thick fog the
//! difference is many orders below F itself and the factor is up to exp(T_sv), so f32
//! rounding and interpolation error dominate. [`TableLayout::Remapped`] keeps every
//! exponential exact and tabulates only a bounded smooth remainder.

use crate::quad;
use std::f64::consts::FRAC_PI_2;

/// γ is clamped to [GAMMA_MIN, π − GAMMA_MIN]. sinγ → 0 is a removable singularity (A0 → ∞,
/// the bracket → 0) wherever the limit is finite, and L_a is even in γ about 0 and π, so the
/// clamp changes those values by O(GAMMA_MIN²) relative (1e-12). Where the ray passes
/// through the light (γ = 0 with the surface beyond it) the true radiance is infinite and
/// the clamp returns the large finite value at γ = GAMMA_MIN.
pub const GAMMA_MIN: f64 = 1e-6;

/// (γ, D_sv, D_vp, β, L_a for I0 = 1) from physics.md §6, independently integrated to 1e-10.
pub const REFERENCE_VALUES: [(f64, f64, f64, f64, f64); 5] = [
    (0.3, 5.0, 20.0, 0.1, 7.091720182588e-03),
    (1.2, 2.0, 3.0, 0.5, 5.569299442594e-03),
    (2.5, 10.0, 1000.0, 0.04, 1.045792310871e-04),
    (0.05, 3.0, 8.0, 0.2, 1.663514116936e-01),
    (1.0, 1.0, 0.5, 1.0, 1.557462522318e-02),
];

/// u range of the paper's table layout.
pub const PAPER_U_MAX: f64 = 10.0;

/// F(u, v) = ∫_0^v exp(−u tan ξ) dξ for u ≥ 0, 0 ≤ v ≤ π/2, to about 1e-13 relative.
pub fn f_exact(u: f64, v: f64) -> f64 {
    f_between(u, 0.0, v)
}

/// ∫_{v0}^{v1} exp(−u tan ξ) dξ = F(u, v1) − F(u, v0), integrated directly so that a narrow
/// interval does not cancel. Arguments are clamped to 0 ≤ v0 ≤ v1 ≤ π/2.
pub fn f_between(u: f64, v0: f64, v1: f64) -> f64 {
    let (v0, v1) = (v0.max(0.0), v1.min(FRAC_PI_2));
    if v1 <= v0 {
        return 0.0;
    }
    if u <= 0.0 {
        return v1 - v0;
    }
    // The integrand is smooth (all derivatives vanish at π/2 for u > 0); its only scale is
    // where the exponent u·tan ξ passes through O(1), so split at u·tan ξ = 2^k.
    let points = quad::breakpoints(KNEES.iter().map(|k| (k / u).atan()).collect(), v0, v1);
    quad::integrate(|x| (-u * x.tan()).exp(), &points, 1e-14, 0.0, 10_000).0
}

/// Exponent offsets 2^k at which the integrands exp(−u tan ξ) and exp(−u cot η) are split.
pub(crate) const KNEES: [f64; 14] =
    [1.0 / 64.0, 1.0 / 16.0, 0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0, 128.0, 256.0, 512.0];

/// Angles η where u·(cot η − cot0) equals each of [`KNEES`].
pub(crate) fn knees_cot(u: f64, cot0: f64) -> Vec<f64> {
    KNEES.iter().map(|k| (u / (u * cot0 + k)).atan()).collect()
}

/// How an [`FTable`]'s entries are laid out.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TableLayout {
    /// The paper's: F itself on a uniform grid over u in [0, PAPER_U_MAX], v in [0, π/2];
    /// beyond PAPER_U_MAX an asymptotic tail.
    Paper,
    /// A smooth ratio q(u, k) on remapped axes, what the GPU reads; see [`FTable::remapped`].
    Remapped,
}

/// How table entries are interpolated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interp {
    Nearest,
    Bilinear,
}

/// A tabulated special function for the GPU. Entry (i, j) lies at `data[j * nu + i]`, i along
/// the u axis; nodes sit on both ends of each axis.
#[derive(Clone, Debug, PartialEq)]
pub struct FTable {
    pub nu: usize,
    pub nv: usize,
    pub layout: TableLayout,
    pub data: Vec<f32>,
}

/// Remapped u axis: x = sqrt(u / (U_SCALE + u)) covers all u ≥ 0 on [0, 1] and resolves the
/// u·ln u behaviour of F near u = 0.
pub const U_SCALE: f64 = 3.0;

pub(crate) fn remap_x(u: f64) -> f64 {
    (u / (U_SCALE + u)).sqrt()
}

fn unmap_x(x: f64) -> f64 {
    U_SCALE * x * x / (1.0 - x * x)
}

/// Remapped k axis (k = u·cot η, the exponent): y = k / (K_SCALE + k) on [0, 1].
pub const K_SCALE: f64 = 1.0;

pub(crate) fn remap_y(k: f64) -> f64 {
    if k < 1e30 {
        k / (K_SCALE + k)
    } else {
        1.0
    }
}

fn unmap_y(y: f64) -> f64 {
    K_SCALE * y / (1.0 - y)
}

/// The normaliser N(u, η) = η sin²η / (uη + sin²η) of R(u, η): exact at u = 0 (R = η) and
/// for u → ∞ (R ≈ sin²η / u).
pub(crate) fn norm_r(u: f64, eta: f64) -> f64 {
    if eta <= 0.0 {
        return 0.0;
    }
    let s2 = eta.sin().powi(2);
    eta * s2 / (u * eta + s2)
}

/// R(u, η) = exp(u cot η) · ∫_0^η exp(−u cot η') dη', exact.
pub(crate) fn r_exact(u: f64, eta: f64) -> f64 {
    if eta <= 0.0 {
        return 0.0;
    }
    if u <= 0.0 {
        return eta;
    }
    let cot = 1.0 / eta.tan();
    let points = quad::breakpoints(knees_cot(u, cot), 0.0, eta);
    quad::integrate(|e| (-u * (1.0 / e.tan() - cot)).exp(), &points, 1e-13, 0.0, 10_000).0
}

impl FTable {
    /// The paper's layout: F(u_i, v_j) at u_i = PAPER_U_MAX·i/(nu − 1), v_j = (π/2)·j/(nv − 1).
    pub fn paper(nu: usize, nv: usize) -> Self {
        let (nu, nv) = (nu.max(2), nv.max(2));
        let mut data = Vec::with_capacity(nu * nv);
        for j in 0..nv {
            let v = FRAC_PI_2 * j as f64 / (nv - 1) as f64;
            for i in 0..nu {
                data.push(f_exact(PAPER_U_MAX * i as f64 / (nu - 1) as f64, v) as f32);
            }
        }
        Self { nu, nv, layout: TableLayout::Paper, data }
    }

    /// Fogsmith's layout. With η = π/2 − v, F(u, v) = G(u, π/2) − G(u, η) where
    /// G(u, η) = ∫_0^η exp(−u cot η') dη' = exp(−k)·R(u, η), k = u·cot η. The exponential
    /// carries G's fast variation, R is smooth and bounded, and the table holds q = R / N
    /// (see `norm_r`), which tends to 1 for u → ∞ and k → ∞ and stays within [0.8, 1.07]
    /// elsewhere. Indexing by (u, k) rather than (u, η) keeps q continuous at u, η → 0
    /// (looking away from the light), where it depends on k alone. Axes:
    /// x = sqrt(u/(U_SCALE+u)) and y = k/(K_SCALE+k), both covering [0, ∞) on [0, 1], so
    /// there is no tail. Short rays, where the two G terms would cancel, are integrated
    /// directly by [`sun_la_table`].
    pub fn remapped(nu: usize, nv: usize) -> Self {
        let (nu, nv) = (nu.max(2), nv.max(2));
        let mut data = Vec::with_capacity(nu * nv);
        for j in 0..nv {
            let k = unmap_y(j as f64 / (nv - 1) as f64);
            for i in 0..nu {
                let q = if i + 1 == nu || j + 1 == nv {
                    1.0
                } else {
                    // u → 0 at fixed k is a smooth limit; 1e-9 is as good as 0 for f32.
                    let u = unmap_x(i as f64 / (nu - 1) as f64).max(1e-9);
                    let eta = u.atan2(k);
                    r_exact(u, eta) / norm_r(u, eta)
                };
                data.push(q as f32);
            }
        }
        Self { nu, nv, layout: TableLayout::Remapped, data }
    }

    pub fn new(layout: TableLayout, nu: usize, nv: usize) -> Self {
        match layout {
            TableLayout::Paper => Self::paper(nu, nv),
            TableLayout::Remapped => Self::remapped(nu, nv),
        }
    }

    /// The table at fractional coordinates x, y in [0, 1] (clamped).
    pub(crate) fn sample(&self, x: f64, y: f64, interp: Interp) -> f64 {
        let fx = x.clamp(0.0, 1.0) * (self.nu - 1) as f64;
        let fy = y.clamp(0.0, 1.0) * (self.nv - 1) as f64;
        let at = |i: usize, j: usize| self.data[j * self.nu + i] as f64;
        match interp {
            Interp::Nearest => at(fx.round() as usize, fy.round() as usize),
            Interp::Bilinear => {
                let (i, j) = ((fx as usize).min(self.nu - 2), (fy as usize).min(self.nv - 2));
                let (tx, ty) = (fx - i as f64, fy - j as f64);
                let bottom = at(i, j) * (1.0 - tx) + at(i + 1, j) * tx;
                let top = at(i, j + 1) * (1.0 - tx) + at(i + 1, j + 1) * tx;
                bottom * (1.0 - ty) + top * ty
            }
        }
    }

    /// R(u, η) from a Remapped table, given k = u·cot η.
    pub(crate) fn r(&self, u: f64, eta: f64, k: f64, interp: Interp) -> f64 {
        self.sample(remap_x(u), remap_y(k), interp) * norm_r(u, eta)
    }

    /// F(u, v) from the table.
    pub fn lookup(&self, u: f64, v: f64, interp: Interp) -> f64 {
        let (u, v) = (u.max(0.0), v.clamp(0.0, FRAC_PI_2));
        if v == 0.0 {
            return 0.0;
        }
        match self.layout {
            TableLayout::Paper if u <= PAPER_U_MAX => self.sample(u / PAPER_U_MAX, v / FRAC_PI_2, interp),
            TableLayout::Paper => {
                // F ≈ (1 − exp(−u tan v))/u for large u; scale the last column by that shape.
                let edge = self.sample(1.0, v / FRAC_PI_2, interp);
                let t = v.tan();
                edge * (PAPER_U_MAX / u) * ((-u * t).exp_m1() / (-PAPER_U_MAX * t).exp_m1())
            }
            TableLayout::Remapped => {
                if u == 0.0 {
                    return v;
                }
                if v >= FRAC_PI_2 - 1e-6 {
                    return self.r(u, FRAC_PI_2, 0.0, interp);
                }
                let k = u * v.tan();
                self.r(u, FRAC_PI_2, 0.0, interp) - (-k).exp() * self.r(u, FRAC_PI_2 - v, k, interp)
            }
        }
    }
}

/// See [`sun_la_table`]: the far term is skipped where T_vp > T_sv + FAR_SKIP.
pub const FAR_SKIP: f64 = 40.0;

/// Size of the table the GPU reads: `FTable::remapped(GPU_TABLE_SIZE, GPU_TABLE_SIZE)`,
/// matching `SUN_NU`/`SUN_NV` in `shaders/sun.wgsl`.
pub const GPU_TABLE_SIZE: usize = 64;

/// Where the far term exceeds this fraction of the near one, the Remapped evaluation
/// integrates the short bracket directly instead of subtracting.
pub const SHORT_RATIO: f64 = 0.5;

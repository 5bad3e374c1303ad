// Sun et al. 2005 airlight for a point light in homogeneous fog (physics.md §6), read from the
// Remapped table of src/reference/sun.rs (FTable::remapped(64, 64)); a direct transliteration
// of FTable::lookup and sun_la_table there, which are tested against the exact formula.
//
// The including shader declares the table, 64·64 f32 with u fastest:
//     var<storage, read> sun_table: array<f32>;

const SUN_HALF_PI: f32 = 0.5 * PI;

// Bilinear sample at fractional table coordinates x (u axis) and y (k axis) in [0, 1].
fn sun_sample(x: f32, y: f32) -> f32 {
    let fx = clamp(x, 0.0, 1.0) * f32(SUN_NU - 1u);
    let fy = clamp(y, 0.0, 1.0) * f32(SUN_NV - 1u);
    let i = min(u32(fx), SUN_NU - 2u);
    let j = min(u32(fy), SUN_NV - 2u);
    let tx = fx - f32(i);
    let ty = fy - f32(j);
    let r0 = j * SUN_NU + i;
    let r1 = r0 + SUN_NU;
    let bottom = mix(sun_table[r0], sun_table[r0 + 1u], tx);
    let top = mix(sun_table[r1], sun_table[r1 + 1u], tx);
    return mix(bottom, top, ty);
}

// N(u, η) = η sin²η / (uη + sin²η), the normaliser of R.
fn sun_norm_r(u: f32, eta: f32) -> f32 {
    if (eta <= 0.0) {
        return 0.0;
    }
    let s = sin(eta);
    let s2 = s * s;
    return eta * s2 / (u * eta + s2);
}

// R(u, η) = exp(u cot η) ∫_0^η exp(−u cot η') dη', given k = u cot η.
fn sun_r(u: f32, eta: f32, k: f32) -> f32 {
    let x = sqrt(u / (SUN_U_SCALE + u));
    let y = select(1.0, k / (SUN_K_SCALE + k), k < 1e30);
    return sun_sample(x, y) * sun_norm_r(u, eta);
}

// F(u, v) = ∫_0^v exp(−u tan ξ) dξ for u ≥ 0, v in [0, π/2].
fn sun_f(u: f32, v: f32) -> f32 {
    let uu = max(u, 0.0);
    let vv = clamp(v, 0.0, SUN_HALF_PI);
    if (vv == 0.0) {
        return 0.0;
    }
    if (uu == 0.0) {
        return vv;
    }
    if (vv >= SUN_HALF_PI - 1e-6) {
        return sun_r(uu, SUN_HALF_PI, 0.0);
    }
    let k = uu * tan(vv);
    return sun_r(uu, SUN_HALF_PI, 0.0) - exp(-k) * sun_r(uu, SUN_HALF_PI - vv, k);
}

fn sun_bracket_integrand(eta: f32, c: f32, a1: f32) -> f32 {
    return exp(-(c + a1 / tan(eta)));
}

// Airlight L_a (isotropic phase, albedo 1) from a light of intensity i0 at distance d_sv,
// gamma the angle between the view ray and the direction to the light, surface at d_vp
// (pass any value above d_sv + 40/beta, e.g. 1e30, for none), fog extinction beta.
// Unlike the Rust version, d_sv = 0 (light at the eye) returns 0 rather than +inf.
fn sun_la(gamma: f32, d_sv: f32, d_vp: f32, beta: f32, i0: f32) -> f32 {
    if (beta <= 0.0 || d_vp <= 0.0 || d_sv <= 0.0) {
        return 0.0;
    }
    let g = clamp(gamma, SUN_GAMMA_MIN, PI - SUN_GAMMA_MIN);
    let t_sv = beta * d_sv;
    let t_vp = beta * d_vp;
    let a1 = t_sv * sin(g);
    let a = 0.5 * (PI - g);
    let c = t_sv * cos(g);
    let scale = beta * beta * i0 / (2.0 * PI * a1);
    let sh = sin(0.5 * g);
    let k_a = 2.0 * t_sv * sh * sh;
    let near = exp(-t_sv) * sun_r(a1, a, k_a);
    if (t_vp > t_sv + SUN_FAR_SKIP) {
        return scale * near;
    }
    let t_sp = sqrt(max(t_vp * t_vp + t_sv * t_sv - 2.0 * t_vp * c, 0.0));
    // psi = 2(a − b), the angle the ray segment subtends at the light, computed without
    // subtracting angles near π (that would cancel for short rays).
    let psi = min(atan2(a1 * t_vp, t_sv * (t_sv - cos(g) * t_vp)), 2.0 * a);
    let b = a - 0.5 * psi;
    let k_b = t_vp + t_sp - c;
    let far = exp(-(t_vp + t_sp)) * sun_r(a1, b, k_b);
    if (far < SUN_SHORT_RATIO * near) {
        return scale * (near - far);
    }
    // A short ray: integrate the bracket over [b, a] with 4-point Gauss–Legendre.
    let h = 0.25 * psi;
    let mid = a - h;
    let x0 = 0.3399810435848563;
    let x1 = 0.8611363115940526;
    let sum = 0.6521451548625461 * (sun_bracket_integrand(mid - h * x0, c, a1) + sun_bracket_integrand(mid + h * x0, c, a1))
        + 0.3478548451374538 * (sun_bracket_integrand(mid - h * x1, c, a1) + sun_bracket_integrand(mid + h * x1, c, a1));
    return scale * h * sum;
}

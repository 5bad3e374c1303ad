// Sun et al. 2005's surface term for diffuse surfaces in homogeneous fog (src/surface_table.rs):
// the light the fog scatters onto a surface from a point light. The G table (GLOW_NT × GLOW_NTHETA,
// T fastest) follows the F table in `sun_table`, declared by the including shader.

// G(T, θ_s), bilinear on x = (T / T_MAX)^{1/4}, y = θ_s / π; a transliteration of
// surface_table::glow_lookup.
fn glow_g(t: f32, theta_s: f32) -> f32 {
    let tc = clamp(t, 0.0, GLOW_T_MAX);
    let fx = sqrt(sqrt(tc / GLOW_T_MAX)) * f32(GLOW_NT - 1u);
    let fy = clamp(theta_s / PI, 0.0, 1.0) * f32(GLOW_NTHETA - 1u);
    let i = min(u32(fx), GLOW_NT - 2u);
    let j = min(u32(fy), GLOW_NTHETA - 2u);
    let tx = fx - f32(i);
    let ty = fy - f32(j);
    let r0 = SUN_NU * SUN_NV + j * GLOW_NT + i;
    let r1 = r0 + GLOW_NT;
    let g = mix(mix(sun_table[r0], sun_table[r0 + 1u], tx), mix(sun_table[r1], sun_table[r1 + 1u], tx), ty);
    return select(g, g * GLOW_T_MAX / t, t > GLOW_T_MAX);
}

// Radiance per unit surface albedo and light intensity at distance d from the light, θ_s the
// angle between the normal and the direction to the light, fog extinction beta (isotropic
// phase, scattering albedo 1): e^{−βd} β G(βd, θ_s) / (2π² d).
fn glow_radiance(beta: f32, d: f32, theta_s: f32) -> f32 {
    if (beta <= 0.0) {
        return 0.0;
    }
    let dd = max(d, 1e-12);
    let t = beta * dd;
    return exp(-t) * beta * glow_g(t, theta_s) / (2.0 * PI * PI * dd);
}

// Sun et al.'s surface term for Phong-specular surfaces: the S_n table (SPEC_NT × SPEC_NTHETA ×
// SPEC_NN, T fastest) follows the G table. A transliteration of surface_table::spec_lookup.
fn spec_width(n: f32) -> f32 {
    return inverseSqrt(n + 1.0);
}

fn spec_node(k: u32, fx: f32, theta: f32) -> f32 {
    let n = pow(1.0 + SPEC_N_MAX, f32(k) / f32(SPEC_NN - 1u)) - 1.0;
    let w = spec_width(n);
    let fy = clamp(asinh(theta / w) / asinh(PI / w), 0.0, 1.0) * f32(SPEC_NTHETA - 1u);
    let i = min(u32(fx), SPEC_NT - 2u);
    let j = min(u32(fy), SPEC_NTHETA - 2u);
    let tx = fx - f32(i);
    let ty = fy - f32(j);
    let r0 = SUN_NU * SUN_NV + GLOW_NT * GLOW_NTHETA + (k * SPEC_NTHETA + j) * SPEC_NT + i;
    let r1 = r0 + SPEC_NT;
    return mix(mix(sun_table[r0], sun_table[r0 + 1u], tx), mix(sun_table[r1], sun_table[r1 + 1u], tx), ty);
}

// S_n(T, θ_r), θ_r the angle between the view's mirror direction and the direction to the light.
fn spec_s(t: f32, theta_r: f32, n: f32) -> f32 {
    let tc = clamp(t, 0.0, GLOW_T_MAX);
    let theta = clamp(theta_r, 0.0, PI);
    let nc = clamp(n, 0.0, SPEC_N_MAX);
    let fx = sqrt(sqrt(tc / GLOW_T_MAX)) * f32(SPEC_NT - 1u);
    let fz = log(1.0 + nc) / log(1.0 + SPEC_N_MAX) * f32(SPEC_NN - 1u);
    let k = min(u32(fz), SPEC_NN - 2u);
    let h = mix(spec_node(k, fx, theta), spec_node(k + 1u, fx, theta), fz - f32(k));
    let w = spec_width(nc);
    let s = h / sqrt(theta * theta + w * w);
    return select(s, s * GLOW_T_MAX / t, t > GLOW_T_MAX);
}

// Specular radiance per unit specular coefficient and light intensity: e^{−βd} β S_n(βd, θ_r) / (2π d).
fn spec_radiance(beta: f32, d: f32, theta_r: f32, n: f32) -> f32 {
    if (beta <= 0.0) {
        return 0.0;
    }
    let dd = max(d, 1e-12);
    let t = beta * dd;
    return exp(-t) * beta * spec_s(t, theta_r, n) / (2.0 * PI * dd);
}

// The Phong lobe's direct reflection per unit specular coefficient: (n + 1)/(2π)·cos^n α for
// cos α > 0 (cos^0 = 1 there), else 0.
fn phong_lobe(cos_alpha: f32, n: f32) -> f32 {
    if (cos_alpha <= 0.0) {
        return 0.0;
    }
    let c = select(pow(cos_alpha, n), 1.0, n == 0.0);
    return (n + 1.0) / (2.0 * PI) * c;
}

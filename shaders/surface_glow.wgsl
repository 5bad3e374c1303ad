// Sun et al. 2005's surface term for diffuse surfaces in homogeneous fog (src/surface_table.rs):
// the light the fog scatters onto a surface from a point light. The G table (GLOW_NT × GLOW_NTHETA,
// T fastest) follows the F table in `sun_table`, declared by the including shader.

// G(T, θ_s), bilinear on x = (T / T_MAX)^{1/4}, y = θ_s / π; a transliteration of
// surface_table::glow_lookup.
fn glow_g(t: f32, theta_s: f32) -> f32 {
    let tc = clamp(t, 0.0, GLOW_T_MAX);
    let fx = sqrt(sqrt(tc / GLOW_T_MAX)) * f32(GLOW_NT - 1u);
    let fy = clamp(theta_s / SUN_PI, 0.0, 1.0) * f32(GLOW_NTHETA - 1u);
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
    return exp(-t) * beta * glow_g(t, theta_s) / (2.0 * SUN_PI * SUN_PI * dd);
}

// The trilinear patch of the EV, written once for every lookup that interpolates σ_t between
// cells (volume_lookup.wgsl, sweep_sigma_loads.wgsl, march.wgsl). Expects the `ev` binding.

// σ_t at the eight corners of the patch from cell i0 to cell i1, x fastest, then y, then z.
fn ev_corners(i0: vec3i, i1: vec3i) -> array<f32, 8> {
    return array<f32, 8>(
        textureLoad(ev, i0, 0).r,
        textureLoad(ev, vec3i(i1.x, i0.y, i0.z), 0).r,
        textureLoad(ev, vec3i(i0.x, i1.y, i0.z), 0).r,
        textureLoad(ev, vec3i(i1.x, i1.y, i0.z), 0).r,
        textureLoad(ev, vec3i(i0.x, i0.y, i1.z), 0).r,
        textureLoad(ev, vec3i(i1.x, i0.y, i1.z), 0).r,
        textureLoad(ev, vec3i(i0.x, i1.y, i1.z), 0).r,
        textureLoad(ev, i1, 0).r,
    );
}

// Trilinear interpolation of corners c (ordered as ev_corners) at fractions f: along x, then
// y, then z.
fn lerp3(c: array<f32, 8>, f: vec3f) -> f32 {
    let x00 = mix(c[0], c[1], f.x);
    let x10 = mix(c[2], c[3], f.x);
    let x01 = mix(c[4], c[5], f.x);
    let x11 = mix(c[6], c[7], f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

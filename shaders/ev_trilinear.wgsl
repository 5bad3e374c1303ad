// The trilinear patch of the EV, written once for every lookup that interpolates σ_t between
// cells (volume_lookup.wgsl, sweep_sigma_loads.wgsl). Expects `ev_texel`, the load of one cell of
// the `ev` binding (its shader declares which kind of texture that is); lerp3 is in common.wgsl.

// σ_t at the eight corners of the patch from cell i0 to cell i1, x fastest, then y, then z.
fn ev_corners(i0: vec3i, i1: vec3i) -> array<f32, 8> {
    return array<f32, 8>(
        ev_texel(i0),
        ev_texel(vec3i(i1.x, i0.y, i0.z)),
        ev_texel(vec3i(i0.x, i1.y, i0.z)),
        ev_texel(vec3i(i1.x, i1.y, i0.z)),
        ev_texel(vec3i(i0.x, i0.y, i1.z)),
        ev_texel(vec3i(i1.x, i0.y, i1.z)),
        ev_texel(vec3i(i0.x, i1.y, i1.z)),
        ev_texel(i1),
    );
}

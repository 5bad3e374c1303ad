// The trilinear patch of the EV, written once for every lookup that interpolates σ_t between
// cells (volume_lookup.wgsl, sweep_sigma_loads.wgsl), from a sampled `ev` binding; lerp3 is in
// common.wgsl.

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

// σ_t pairs from eight texel loads: the sweep's variant where r32float cannot be filtered, and
// the directional sweep's always.
// The sweep binds a sampler at 7 either way; this variant does not use it.

// σ_t at cell-centre coordinates p and q (cell (i, j, k) at (i, j, k)), both within the
// trilinear patch around m: one set of eight loads for the two values.
fn sigma_pair(m: vec3f, p: vec3f, q: vec3f) -> vec2f {
    let hi = vec3f(grid.dims - 1u);
    let i0 = vec3i(min(floor(clamp(m, vec3f(0.0), hi)), max(hi - 1.0, vec3f(0.0))));
    let i1 = min(i0 + 1, vec3i(grid.dims) - 1);
    let c = ev_corners(i0, i1);
    let fp = clamp(clamp(p, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    let fq = clamp(clamp(q, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    return vec2f(lerp3(c, fp), lerp3(c, fq));
}

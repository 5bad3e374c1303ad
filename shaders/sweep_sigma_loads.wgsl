// σ_t pairs from eight texel loads: the sweep's variant where r32float cannot be filtered, and
// the directional sweep's always.
// The sweep binds a sampler at 7 either way; this variant does not use it.

// σ_t at cell-centre coordinates p and q (cell (i, j, k) at (i, j, k)), both within the
// trilinear patch around m: one set of eight loads for the two values.
fn sigma_pair(m: vec3f, p: vec3f, q: vec3f) -> vec2f {
    let hi = vec3f(grid.dims - 1u);
    let i0 = vec3i(min(floor(clamp(m, vec3f(0.0), hi)), max(hi - 1.0, vec3f(0.0))));
    let i1 = min(i0 + 1, vec3i(grid.dims) - 1);
    let c000 = textureLoad(ev, i0, 0).r;
    let c100 = textureLoad(ev, vec3i(i1.x, i0.y, i0.z), 0).r;
    let c010 = textureLoad(ev, vec3i(i0.x, i1.y, i0.z), 0).r;
    let c110 = textureLoad(ev, vec3i(i1.x, i1.y, i0.z), 0).r;
    let c001 = textureLoad(ev, vec3i(i0.x, i0.y, i1.z), 0).r;
    let c101 = textureLoad(ev, vec3i(i1.x, i0.y, i1.z), 0).r;
    let c011 = textureLoad(ev, vec3i(i0.x, i1.y, i1.z), 0).r;
    let c111 = textureLoad(ev, i1, 0).r;
    let fp = clamp(clamp(p, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    let fq = clamp(clamp(q, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    let sp = mix(
        mix(mix(c000, c100, fp.x), mix(c010, c110, fp.x), fp.y),
        mix(mix(c001, c101, fp.x), mix(c011, c111, fp.x), fp.y),
        fp.z,
    );
    let sq = mix(
        mix(mix(c000, c100, fq.x), mix(c010, c110, fq.x), fq.y),
        mix(mix(c001, c101, fq.x), mix(c011, c111, fq.x), fq.y),
        fq.z,
    );
    return vec2f(sp, sq);
}

// σ_t pairs for the sweep from hardware trilinear filtering: two filtered samples instead of
// eight texel loads and two manual interpolations. A clamp-to-edge sampler at cell-centre
// coordinate u reads (u + 0.5) / dims, which is the trilinear medium clamped at the faces.

@group(0) @binding(7) var ev_sampler: sampler;

fn sigma_pair(m: vec3f, p: vec3f, q: vec3f) -> vec2f {
    let inv = 1.0 / vec3f(grid.dims);
    let sp = textureSampleLevel(ev, ev_sampler, (p + 0.5) * inv, 0.0).r;
    let sq = textureSampleLevel(ev, ev_sampler, (q + 0.5) * inv, 0.0).r;
    return vec2f(sp, sq);
}

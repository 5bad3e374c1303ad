// The "as baked" render (physics.md §10), appended to the ray march's sources: what an engine
// that reads the baked density and emission draws, with no lights. σ_t (the EV, binding 2)
// and the emission j (binding 11, RGB per cell) are trilinear between cell centres through
// the march's own lookups (trilinear_at, same clamping); uniform steps of params.step hold
// both constant and are integrated exactly: L += Tr·j·(1 − e^{−σ_t Δ})/σ_t, Tr ·= e^{−σ_t Δ}.
// Rays stop at the first surface, which the bake does not hold. The camera and tone map are
// the march's.

@group(0) @binding(11) var<storage, read> baked_emission: array<vec4f>;

fn emission_at(t: Trilinear) -> vec3f {
    var j = vec3f(0.0);
    for (var n = 0u; n < 8u; n++) {
        let p = corner(t, n);
        let w3 = select(vec3f(1.0) - t.f, t.f, vec3<bool>((n & 1u) != 0u, (n & 2u) != 0u, (n & 4u) != 0u));
        j += w3.x * w3.y * w3.z * baked_emission[p.x + grid.dims.x * (p.y + grid.dims.y * p.z)].rgb;
    }
    return j;
}

// Below this transmittance the rest of a ray adds at most that fraction of its radiance.
const AS_BAKED_CUTOFF: f32 = 1e-6;

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn as_baked(@builtin(global_invocation_id) id: vec3u) {
    if any(id.xy >= params.size) {
        return;
    }
    let dir = camera_ray(id.xy);
    let o = params.origin;
    let hit = first_surface(o, dir);
    let slabs = ray_slabs(o, safe_inverse(dir), grid.min, grid.max);
    let t0 = max(max(slabs.near.x, slabs.near.y), max(slabs.near.z, 0.0));
    let t1 = min(min(min(slabs.far.x, slabs.far.y), slabs.far.z), hit.t);
    var l = vec3f(0.0);
    var tr = 1.0;
    if t1 > t0 {
        let n = max(u32(ceil((t1 - t0) / params.step)), 1u);
        let dt = (t1 - t0) / f32(n);
        for (var k = 0u; k < n; k++) {
            let t = trilinear_at(o + dir * (t0 + (f32(k) + 0.5) * dt));
            let sigma = ev_at(t);
            let tau = sigma * dt;
            // ∫_0^Δ e^{−σ s} ds, by its series where σΔ is small enough for f32 to lose it.
            let weight = select((1.0 - exp(-tau)) / sigma, dt * (1.0 - tau * (0.5 - tau / 6.0)), tau < 1e-3);
            l += tr * weight * emission_at(t);
            tr *= exp(-tau);
            if tr < AS_BAKED_CUTOFF {
                break;
            }
        }
    }
    textureStore(out_hdr, id.xy, vec4f(l, 1.0 - tr));
    textureStore(out_ldr, id.xy, vec4f(tonemap(l), 1.0));
}

// Baked in-scattered emission (physics.md §10), appended to the ray march's sources so that it
// reads the EV and the OPVs through the march's own lookups (opv_at, sun_opv_at, cone_factor,
// phase): per cell, j = albedo·σ_t · Σ_l rgb_l · ⟨E_l·exp(−T_l)·p⟩, where ⟨·⟩ is the mean
// over the cell, E_l the light's irradiance per unit of rgb (cone/d² for points and spots, 1
// for suns) and p the phase towards the camera (params.anisotropy is 0 for the isotropic bake).
// A surface between the point and the light (box or ground) shadows it, for every light kind.
// With multiple scattering on (params.scatter_factor > 0), each cell adds the multiply scattered
// light at its centre, ms_inscatter (smooth on the coarse grid, so the centre stands for the
// mean), with the same phase rule.
//
// Why the mean: trilinear interpolation between cell centres integrates to the sum of the cell
// values, so storing each cell's mean keeps every ray's integral of the emission, where a
// point sample of 1/d² would not (it varies by orders of magnitude inside the cells by a
// light). In the cell holding a point light the mean is taken in cones from the light
// (pyramid_mean), which removes the 1/d² singularity; within 2 cells of it by 4-point
// Gauss–Legendre per axis on 4³ sub-cells; within 8 cells, or where a spot's cone edge or a
// surface's shadow edge may cross the cell, by the same on the whole cell; elsewhere the
// centre value stands for it.
//
// params.row_offset is the first z layer of the dispatch: the output holds one slab.

@group(0) @binding(11) var<storage, read_write> emission_out: array<vec4f>;

const GL4_X = array<f32, 4>(-0.4305681557970263, -0.1699905217924281, 0.1699905217924281, 0.4305681557970263);
const GL4_W = array<f32, 4>(0.1739274225831146, 0.3260725774168854, 0.3260725774168854, 0.1739274225831146);

// E·exp(−T)·p at y from light l, per unit of its rgb, times d² for points and spots (the
// inverse square left out).
fn light_times_d2(y: vec3f, l: u32) -> f32 {
    let light = lights[l];
    let v = params.origin - y;
    let view = v / max(length(v), 1e-12);
    if light.kind == LIGHT_DIRECTIONAL {
        if params.surface_count > 0u && shadowed(y, vec3f(0.0), -light.direction, OPAQUE) {
            return 0.0;
        }
        return phase(dot(light.direction, view)) * exp(-sun_opv_at(trilinear_at(y), l, y));
    }
    let to_y = y - light.position;
    let d = length(to_y);
    if d <= 0.0 {
        return 0.0;
    }
    let cone = cone_factor(light, to_y);
    if cone <= 0.0 {
        return 0.0;
    }
    if params.surface_count > 0u && shadowed(y, vec3f(0.0), -to_y / d, d) {
        return 0.0;
    }
    return cone * phase(dot(to_y / d, view)) * exp(-opv_at(trilinear_at(y), l, y));
}

// E·exp(−T)·p at y from light l, per unit of its rgb.
fn light_at(y: vec3f, l: u32) -> f32 {
    if lights[l].kind == LIGHT_DIRECTIONAL {
        return light_times_d2(y, l);
    }
    let to_y = y - lights[l].position;
    let d2 = dot(to_y, to_y);
    if d2 <= 0.0 {
        return 0.0;
    }
    return light_times_d2(y, l) / d2;
}

// The mean of light_at over the cell holding a point light S, without its singularity: in
// cones from S over each face, y = S + t·(P − S) for P on the face and t in [0, 1], the
// inverse square cancels the volume element: f dV = g(y)·h/|P − S|² dt dA, g = light_times_d2
// and h the distance from S to the face's plane. Every integrand is smooth and positive.
// 4-point Gauss–Legendre in t and on 2×2 panels of each face. (The entry point of the ray,
// t0, is 0 here; it is kept so that the formula holds for any cell.)
fn pyramid_mean(c: vec3f, l: u32) -> f32 {
    let s = lights[l].position;
    let lo = c - 0.5 * grid.cell;
    let hi = c + 0.5 * grid.cell;
    var sum = 0.0;
    for (var a = 0u; a < 3u; a++) {
        let b = (a + 1u) % 3u;
        let e = (a + 2u) % 3u;
        for (var side = 0u; side < 2u; side++) {
            let sign = f32(side) * 2.0 - 1.0;
            let plane = c[a] + sign * 0.5 * grid.cell[a];
            // Rays leave through this face only when S lies on its inner side.
            let h = sign * (plane - s[a]);
            if h < 1e-7 * grid.cell[a] {
                continue;
            }
            var face = 0.0;
            for (var pb = 0u; pb < 8u; pb++) {
                for (var pe = 0u; pe < 8u; pe++) {
                    let ub = (f32(pb / 4u) - 0.5 + GL4_X[pb % 4u]) * 0.5;
                    let ue = (f32(pe / 4u) - 0.5 + GL4_X[pe % 4u]) * 0.5;
                    var p = c;
                    p[a] = plane;
                    p[b] = c[b] + ub * grid.cell[b];
                    p[e] = c[e] + ue * grid.cell[e];
                    let v = p - s;
                    let slabs = ray_slabs(s, safe_inverse(v), lo, hi);
                    let t0 = clamp(max(max(slabs.near.x, slabs.near.y), max(slabs.near.z, 0.0)), 0.0, 1.0);
                    let w = 0.25 * GL4_W[pb % 4u] * GL4_W[pe % 4u] * h / dot(v, v);
                    var along = 0.0;
                    for (var k = 0u; k < 4u; k++) {
                        along += GL4_W[k] * light_times_d2(s + (t0 + (1.0 - t0) * (0.5 + GL4_X[k])) * v, l);
                    }
                    face += w * (1.0 - t0) * along;
                }
            }
            sum += face * grid.cell[b] * grid.cell[e];
        }
    }
    return sum / (grid.cell.x * grid.cell.y * grid.cell.z);
}

// Whether a surface's shadow edge may cross the cell centred at c: its centre and corners
// disagree about being shadowed.
fn shadow_edge(c: vec3f, l: u32) -> bool {
    let light = lights[l];
    var first = false;
    for (var n = 0u; n < 9u; n++) {
        var y = c;
        if n > 0u {
            let s = vec3f(f32(n & 1u), f32((n >> 1u) & 1u), f32((n >> 2u) & 1u)) - 0.5;
            y = c + s * grid.cell;
        }
        var blocked: bool;
        if light.kind == LIGHT_DIRECTIONAL {
            blocked = shadowed(y, vec3f(0.0), -light.direction, OPAQUE);
        } else {
            let to_light = light.position - y;
            let d = max(length(to_light), 1e-12);
            blocked = shadowed(y, vec3f(0.0), to_light / d, d);
        }
        if n == 0u {
            first = blocked;
        } else if blocked != first {
            return true;
        }
    }
    return false;
}

// Sub-cells per axis of the quadrature of light l over the cell centred at c: 0 for the centre
// value alone.
fn subdivisions(c: vec3f, l: u32) -> u32 {
    let light = lights[l];
    let h = max(grid.cell.x, max(grid.cell.y, grid.cell.z));
    var sub = 0u;
    if light.kind != LIGHT_DIRECTIONAL {
        let v = c - light.position;
        let d = length(v);
        if d < 2.0 * h {
            return 4u;
        }
        if d < 8.0 * h {
            sub = 1u;
        }
        if light.kind == LIGHT_SPOT && sub == 0u {
            // The cell spans about this angle around its centre, seen from the light.
            let spread = 0.5 * length(grid.cell) / d;
            let theta = acos(clamp(dot(light.direction, v) / d, -1.0, 1.0));
            let inner = light.angle * (1.0 - light.blend);
            if theta + spread > inner && theta - spread < light.angle {
                sub = 1u;
            }
        }
    }
    if sub == 0u && params.surface_count > 0u && shadow_edge(c, l) {
        sub = 1u;
    }
    return sub;
}

// The cell mean of light_at over the cell centred at c.
fn cell_mean(c: vec3f, l: u32) -> f32 {
    let sub = subdivisions(c, l);
    if sub == 0u {
        return light_at(c, l);
    }
    if sub == 4u && all(abs(lights[l].position - c) <= 0.5 * grid.cell) {
        return pyramid_mean(c, l);
    }
    let step = grid.cell / f32(sub);
    var sum = 0.0;
    for (var sz = 0u; sz < sub; sz++) {
        for (var sy = 0u; sy < sub; sy++) {
            for (var sx = 0u; sx < sub; sx++) {
                let centre = c + (vec3f(f32(sx), f32(sy), f32(sz)) + 0.5 - 0.5 * f32(sub)) * step;
                var part = 0.0;
                for (var k = 0u; k < 4u; k++) {
                    for (var j = 0u; j < 4u; j++) {
                        for (var i = 0u; i < 4u; i++) {
                            let y = centre + vec3f(GL4_X[i], GL4_X[j], GL4_X[k]) * step;
                            part += GL4_W[i] * GL4_W[j] * GL4_W[k] * light_at(y, l);
                        }
                    }
                }
                sum += part;
            }
        }
    }
    return sum / f32(sub * sub * sub);
}

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn bake(@builtin(global_invocation_id) gid: vec3u) {
    let id = gid + vec3u(0u, 0u, params.row_offset);
    if any(id >= grid.dims) || gid.z >= params.size.y {
        return;
    }
    let sigma = textureLoad(ev, id).r;
    var j = vec3f(0.0);
    if sigma > 0.0 && params.albedo > 0.0 {
        let c = cell_center(id);
        for (var l = 0u; l < grid.light_count; l++) {
            if all(lights[l].rgb == vec3f(0.0)) {
                continue;
            }
            j += lights[l].rgb * cell_mean(c, l);
        }
        j += ms_inscatter(c, normalize(params.origin - c));
        j *= params.albedo * sigma;
    }
    emission_out[gid.x + grid.dims.x * (gid.y + grid.dims.y * gid.z)] = vec4f(j, 0.0);
}

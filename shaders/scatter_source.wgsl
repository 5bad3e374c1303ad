// The first-scattering source of multiple scattering (src/gpu/scattering.rs), appended to the
// bake's sources so that it reads the EV, the OPVs and the surfaces through the same lookups
// and light rules (bake.wgsl light_at and pyramid_mean, params.anisotropy 0 so that the phase
// is 1/(4π)).
//
// One thread per coarse cell of params.scatter_factor³ fine cells: the means over it of
// σ_s·φ₀ per channel, σ_s·φ₀ of the mean channel, the flux σ_s·Σ_l φ₀,l·ω_l of the mean channel
// (ω_l the direction light l travels) and σ_t, where φ₀ is the unscattered fluence
// Σ_l rgb_l·E_l·exp(−T_l). Fine cells beyond the grid count as empty. Over every fine cell
// where a coarse cell holds at most 2³ of them, a point or spot light is near or the fog is
// optically thick; elsewhere from 2³ points, which makes the pass's cost follow the coarse
// grid, not the fine one.

// The mean of light_at over the fine cell centred at c, cheaper than the bake's cell_mean,
// since the coarse cell sums many fine ones: in cones from a point or spot light in the cell
// (pyramid_mean, the 1/d² singularity removed), by 4³ Gauss–Legendre points within 2 cells of
// it, and by the centre value elsewhere (cone and shadow edges average out over the coarse
// cell).
fn source_mean(c: vec3f, l: u32) -> f32 {
    let light = lights[l];
    if light.kind != LIGHT_DIRECTIONAL {
        let v = c - light.position;
        if all(abs(v) <= 0.5 * grid.cell) {
            return pyramid_mean(c, l);
        }
        if length(v) < 2.0 * max(grid.cell.x, max(grid.cell.y, grid.cell.z)) {
            var sum = 0.0;
            for (var k = 0u; k < 4u; k++) {
                for (var j = 0u; j < 4u; j++) {
                    for (var i = 0u; i < 4u; i++) {
                        let y = c + vec3f(GL4_X[i], GL4_X[j], GL4_X[k]) * grid.cell;
                        sum += GL4_W[i] * GL4_W[j] * GL4_W[k] * light_at(y, l);
                    }
                }
            }
            return sum;
        }
    }
    return light_at(c, l);
}

// Per coarse cell, 2 entries: (σ_s·φ₀ rgb, its channel mean), (flux, mean σ_t).
@group(0) @binding(15) var<storage, read_write> first_source: array<vec4f>;

// What a coarse cell's source sums: σ_t·φ₀ per channel, its flux, σ_t.
struct Sums {
    rgb: vec3f,
    flux: vec3f,
    sigma: f32,
}

// Adds σ_t·φ₀ of every light at y (σ_t·E·exp(−T) per unit of rgb `e_sigma` of light l, times
// 4π), with the direction its light travels there, to `sums`.
fn add_light(sums: ptr<function, Sums>, y: vec3f, l: u32, e_sigma: f32) {
    let light = lights[l];
    var w = light.direction;
    if light.kind != LIGHT_DIRECTIONAL {
        let v = y - light.position;
        w = v / max(length(v), 1e-12);
    }
    let e = 4.0 * PI * e_sigma;
    (*sums).rgb += light.rgb * e;
    (*sums).flux += ((light.rgb.r + light.rgb.g + light.rgb.b) / 3.0 * e) * w;
}

// The mean of σ_t·light_at over the fine cell centred at c of σ_t `sigma`: source_mean by a
// light; in an optically thick cell (σ_t·h > ½, where the light dies within the cell and its
// centre value is far below its mean) by 2³ Gauss–Legendre points, σ_t and the optical depth
// trilinear there; else the centre value.
fn sigma_light_mean(c: vec3f, sigma: f32, l: u32) -> f32 {
    let h = max(grid.cell.x, max(grid.cell.y, grid.cell.z));
    let light = lights[l];
    let by_light = light.kind != LIGHT_DIRECTIONAL && length(c - light.position) < 2.0 * h;
    if by_light || sigma * h <= 0.5 {
        return sigma * source_mean(c, l);
    }
    var sum = 0.0;
    for (var k = 0u; k < 8u; k++) {
        let side = vec3f(f32(k & 1u), f32((k >> 1u) & 1u), f32(k >> 2u)) * 2.0 - 1.0;
        let y = c + side * (0.2886751 * grid.cell);
        sum += ev_at(trilinear_at(y)) * light_at(y, l);
    }
    return sum / 8.0;
}

// The source sums over every fine cell of coarse cell `gid`.
fn fine_sums(gid: vec3u, f: u32) -> Sums {
    var sums = Sums(vec3f(0.0), vec3f(0.0), 0.0);
    let n = f * f * f;
    for (var k = 0u; k < n; k++) {
        let id = gid * f + vec3u(k % f, (k / f) % f, k / (f * f));
        if any(id >= grid.dims) {
            continue;
        }
        let sigma = textureLoad(ev, id).r;
        if sigma <= 0.0 {
            continue;
        }
        sums.sigma += sigma;
        let c = cell_center(id);
        for (var l = 0u; l < grid.light_count; l++) {
            if any(lights[l].rgb != vec3f(0.0)) {
                add_light(&sums, c, l, sigma_light_mean(c, sigma, l));
            }
        }
    }
    let scale = 1.0 / f32(n);
    return Sums(sums.rgb * scale, sums.flux * scale, sums.sigma * scale);
}

// Whether a point or spot light lies within the coarse cell [lo, hi] grown by one fine cell.
fn light_near(l: u32, lo: vec3f, hi: vec3f) -> bool {
    let light = lights[l];
    return light.kind != LIGHT_DIRECTIONAL && all(light.position >= lo - grid.cell) && all(light.position <= hi + grid.cell);
}

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn scatter_source(@builtin(global_invocation_id) gid: vec3u) {
    let f = params.scatter_factor;
    let dims = (grid.dims + f - 1u) / f;
    if any(gid >= dims) {
        return;
    }
    let coarse = grid.cell * f32(f);
    let lo = grid.min + vec3f(gid) * coarse;
    let hi = lo + coarse;
    var near = false;
    for (var l = 0u; l < grid.light_count; l++) {
        near = near || light_near(l, lo, hi);
    }
    var sums = Sums(vec3f(0.0), vec3f(0.0), 0.0);
    var fine = f <= 2u || near;
    if !fine {
        // Far from point lights the light varies little over a coarse cell of thin fog: 2³
        // points at the centres of its octants, σ_t trilinear there, stand for its f³ fine
        // cells. Thick fog (σ_t·h > ½ at a point) takes every fine cell.
        let h = max(grid.cell.x, max(grid.cell.y, grid.cell.z));
        for (var k = 0u; k < 8u; k++) {
            let y = lo + (vec3f(f32(k & 1u), f32((k >> 1u) & 1u), f32(k >> 2u)) + 0.5) * 0.5 * coarse;
            if !inside_grid(y) {
                continue;
            }
            let sigma = ev_at(trilinear_at(y));
            if sigma <= 0.0 {
                continue;
            }
            if sigma * h > 0.5 {
                fine = true;
                break;
            }
            sums.sigma += sigma;
            for (var l = 0u; l < grid.light_count; l++) {
                if any(lights[l].rgb != vec3f(0.0)) {
                    add_light(&sums, y, l, sigma * light_at(y, l));
                }
            }
        }
        sums = Sums(sums.rgb / 8.0, sums.flux / 8.0, sums.sigma / 8.0);
    }
    if fine {
        sums = fine_sums(gid, f);
    }
    let a = params.albedo;
    let out = gid.x + dims.x * (gid.y + dims.y * gid.z);
    first_source[2u * out] = vec4f(a * sums.rgb, a * (sums.rgb.r + sums.rgb.g + sums.rgb.b) / 3.0);
    first_source[2u * out + 1u] = vec4f(a * sums.flux, sums.sigma);
}

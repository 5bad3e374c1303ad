// Multiple scattering on a coarse grid (src/gpu/scattering.rs): source iteration of the
// discrete-ordinates equations, one scattering order per sweep.
//
// Each coarse cell holds the scattering source of the current order as a colour and one
// Henyey–Greenstein lobe: η_d = src.rgb · HG(ω_d·ê, ḡ), W·m⁻³·sr⁻¹ per direction d of the S6
// level-symmetric set (48 directions, weights summing to 4π). The lobe keeps the source's first
// angular moment exactly: light of mean cosine μ̄ scattered by HG(g) has mean cosine g·μ̄, and
// src.rgb is divided by the discrete sum Σ w_d HG(ω_d·ê, ḡ) so that each order's power is exact
// on the quadrature. ḡ is capped at LOBE_CAP, which the 48 directions still resolve.
//
// Each cell holds its σ_t and emission up to the planes halfway to its neighbours, and each
// direction's line through a cell centre crosses it along a chord of one cell's length along
// the sweep axis.
//
// `seed`: the first order's source from the source pass. `sweep`: one workgroup per direction
// marches the layers of cells along the axis where the direction moves fastest (in cells),
// upwind. A line enters its cell with the upstream cells' exit radiance, bilinear at its entry
// point, and crosses the chord with the cell's σ_t and emission, exactly for constant values
// (L = L₀·e^{−τ} + η·h·(1 − e^{−τ})/τ); it stores its exit radiance for the next layer and
// its mean over the chord. So each cell attenuates exactly what enters it and what it emits,
// and an order cannot scatter more than the one before emitted: radiance at the centres,
// interpolated from centre to centre, creates light where a thick cell sits beside a light (the
// interpolated radiance and σ_t together attenuate less than the cells do), and a segment from
// centre to centre with the cell's own emission counts its light twice. Lines entering through
// a side of the box start there with no radiance (nothing scatters back in from outside the
// grid). `gather`: the order's fluence φ = Σ w L̄ and flux E = Σ w L̄ ω from the chord means,
// added to the totals, and the next order's source σ_s·φ with the lobe of E. `power`: the
// order's total scattered power, and after the last one the tail factor (`tail_factor`).
// `finish`: the totals plus the orders not swept, the last order's fluence times the tail
// factor, times the strength, for the march and the bake.

struct ScatterParams {
    dims: vec3u,
    count: u32,
    cell: vec3f,
    albedo: f32,
    min: vec3f,
    anisotropy: f32,
    order: u32,
    orders: u32,
    strength: f32,
    _pad: u32,
}

const DIRECTIONS: u32 = 48u;
const LOBE_CAP: f32 = 0.75;
// Ratios of successive orders' powers are capped here (a medium that loses under 2 % of its
// light per order is beyond what the tail can stand for).
const RATIO_CAP: f32 = 0.98;
// Where `power` leaves the tail factor in `powers`.
const TAIL_SLOT: u32 = 79u;

@group(0) @binding(1) var<uniform> sp: ScatterParams;
// Per direction: (ω, weight).
@group(0) @binding(2) var<storage, read> directions: array<vec4f>;
// Per coarse cell: mean σ_t.
@group(0) @binding(3) var<storage, read_write> sigma: array<f32>;
// Per coarse cell, 2 entries: (η colour, scattered power), (ê, ḡ).
@group(0) @binding(4) var<storage, read_write> source: array<vec4f>;
// Per direction and coarse cell: radiance where its line leaves the cell (rgb, 0).
@group(0) @binding(5) var<storage, read_write> radiance: array<vec4f>;
// Per direction and coarse cell: the mean radiance over its line's chord (rgb, 0).
@group(0) @binding(11) var<storage, read_write> chord_mean: array<vec4f>;
// Per coarse cell, 2 entries: this order's (φ rgb, φ mean), (E of the mean channel, 0).
@group(0) @binding(6) var<storage, read_write> order_moments: array<vec4f>;
// The same summed over the orders so far.
@group(0) @binding(7) var<storage, read_write> totals: array<vec4f>;
// Scattered power of each order: [0] first scattering.
@group(0) @binding(8) var<storage, read_write> powers: array<f32>;
// What the march and the bake read: (φ_ms rgb, 0), (E_ms, φ_ms mean), times the strength.
@group(0) @binding(9) var<storage, read_write> moments: array<vec4f>;

// The source pass's output (shaders/scatter_source.wgsl).
@group(0) @binding(10) var<storage, read> first_source: array<vec4f>;

var<workgroup> partial: array<f32, SWEEP_WORKGROUP>;

fn coarse_index(c: vec3u) -> u32 {
    return c.x + sp.dims.x * (c.y + sp.dims.y * c.z);
}

// The source entries of a cell whose scattered light has colour `rgb` (σ_s·φ), mean-channel
// power `power` and mean-channel flux `flux` (σ_s·E).
fn write_source(i: u32, rgb: vec3f, power: f32, flux: vec3f, anisotropy: f32) {
    let f = length(flux);
    var e = vec3f(0.0, 1.0, 0.0);
    var g = 0.0;
    if power > 0.0 && f > 0.0 {
        e = flux / f;
        g = clamp(anisotropy * min(f / power, 1.0), -LOBE_CAP, LOBE_CAP);
    }
    var norm = 0.0;
    for (var d = 0u; d < DIRECTIONS; d++) {
        norm += directions[d].w * hg(dot(directions[d].xyz, e), g);
    }
    source[2u * i] = vec4f(rgb / max(norm, 1e-20), power);
    source[2u * i + 1u] = vec4f(e, g);
}

// Radiance along a piece of length h of constant σ and emission η per unit length, entering
// with l0: the radiance at its end, and its integral over the piece (σ times it is what the
// piece attenuates), exact, and accurate for tiny σ·h too.
fn piece(l0: vec3f, sigma: f32, eta: vec3f, h: f32) -> array<vec3f, 2> {
    let tau = sigma * h;
    // f = (1 − e^{−τ})/τ and m = (1 − f)/τ.
    var f: f32;
    var m: f32;
    if tau < 1e-3 {
        f = 1.0 - tau * (0.5 - tau / 6.0);
        m = 0.5 - tau * (1.0 / 6.0 - tau / 24.0);
    } else {
        f = (1.0 - exp(-tau)) / tau;
        m = (1.0 - f) / tau;
    }
    return array<vec3f, 2>(l0 * (1.0 - tau * f) + eta * (h * f), l0 * (h * f) + eta * (h * h * m));
}

// δ-M scaling for forward scattering: the fraction f = g² of each scattering that goes
// straight on is treated as not scattered, so the sweeps see σ_t − f·σ_s, scatter (1 − f)·σ_s
// and a lobe of g/(1 + g), which keeps the transport mean free path and the first moment while
// the 48 directions need not resolve a sharp forward peak (which they would spread sideways,
// letting the light out of thick fog too early). The first scattering's source keeps g: its
// straight-on part is the light's own direction. None for backward scattering.
fn forward_peak() -> f32 {
    let g = max(sp.anisotropy, 0.0);
    return g * g;
}

// Bilinear weights and corners on a layer of `n` cells per axis at fractional cell coordinate u.
fn lerp_pair(u: f32, n: u32) -> vec3f {
    let c = clamp(u, 0.0, f32(n - 1u));
    let i0 = min(u32(floor(c)), n - 1u);
    let i1 = min(i0 + 1u, n - 1u);
    return vec3f(f32(i0), f32(i1), c - f32(i0));
}

@compute @workgroup_size(SWEEP_WORKGROUP)
fn sweep(@builtin(workgroup_id) wid: vec3u, @builtin(local_invocation_index) lid: u32) {
    let d = wid.x;
    let omega = directions[d].xyz;
    let speed = abs(omega) / sp.cell;
    var a = 0u;
    if speed.y > speed[a] {
        a = 1u;
    }
    if speed.z > speed[a] {
        a = 2u;
    }
    let b = (a + 1u) % 3u;
    let c = (a + 2u) % 3u;
    let na = sp.dims[a];
    let nb = sp.dims[b];
    let nc = sp.dims[c];
    let box_min = sp.min;
    let box_max = sp.min + vec3f(sp.dims) * sp.cell;
    let base = d * sp.count;
    for (var t = 0u; t < na; t++) {
        let ia = select(na - 1u - t, t, omega[a] > 0.0);
        for (var k = lid; k < nb * nc; k += SWEEP_WORKGROUP) {
            var cell = vec3u(0u);
            cell[a] = ia;
            cell[b] = k % nb;
            cell[c] = k / nb;
            let i = coarse_index(cell);
            let x = box_min + (vec3f(cell) + 0.5) * sp.cell;
            // The cell's chord: from the plane halfway to the upstream layer (the box's face
            // for the first layer), or from where the line enters the box through a side,
            // to the plane halfway to the downstream layer.
            let half = 0.5 * sp.cell[a] / abs(omega[a]);
            var s_in = half;
            var inside = t > 0u;
            for (var q = 1u; q < 3u; q++) {
                let ax = (a + q) % 3u;
                let exit = select((box_max[ax] - x[ax]) / -omega[ax], (x[ax] - box_min[ax]) / omega[ax], omega[ax] > 0.0);
                if exit < s_in {
                    s_in = exit;
                    inside = false;
                }
            }
            var entering = vec3f(0.0);
            if inside {
                // The upstream cells' exits, bilinear at the line's entry.
                let p = x - omega * (2.0 * half);
                let ub = lerp_pair((p[b] - box_min[b]) / sp.cell[b] - 0.5, nb);
                let uc = lerp_pair((p[c] - box_min[c]) / sp.cell[c] - 0.5, nc);
                let prev = select(ia + 1u, ia - 1u, omega[a] > 0.0);
                for (var n = 0u; n < 4u; n++) {
                    var up = vec3u(0u);
                    up[a] = prev;
                    up[b] = u32(select(ub.x, ub.y, (n & 1u) != 0u));
                    up[c] = u32(select(uc.x, uc.y, (n & 2u) != 0u));
                    let w = select(1.0 - ub.z, ub.z, (n & 1u) != 0u) * select(1.0 - uc.z, uc.z, (n & 2u) != 0u);
                    entering += w * radiance[base + coarse_index(up)].rgb;
                }
            }
            let sigma_x = sigma[i];
            let lobe = source[2u * i + 1u];
            let eta = source[2u * i].rgb * hg(dot(omega, lobe.xyz), lobe.w);
            let chord = piece(entering, sigma_x, eta, s_in + half);
            radiance[base + i] = vec4f(chord[0], 0.0);
            chord_mean[base + i] = vec4f(chord[1] / (s_in + half), 0.0);
        }
        storageBarrier();
    }
}

@compute @workgroup_size(SWEEP_WORKGROUP)
fn gather(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = gid.x + gid.y * groups.x * SWEEP_WORKGROUP;
    if i >= sp.count {
        return;
    }
    var phi = vec3f(0.0);
    var flux = vec3f(0.0);
    for (var d = 0u; d < DIRECTIONS; d++) {
        let dir = directions[d];
        let l = chord_mean[d * sp.count + i].rgb;
        phi += dir.w * l;
        flux += (dir.w * (l.r + l.g + l.b) / 3.0) * dir.xyz;
    }
    let mean = (phi.r + phi.g + phi.b) / 3.0;
    order_moments[2u * i] = vec4f(phi, mean);
    order_moments[2u * i + 1u] = vec4f(flux, 0.0);
    totals[2u * i] += vec4f(phi, mean);
    totals[2u * i + 1u] += vec4f(flux, 0.0);
    let peak = forward_peak();
    let ss = sp.albedo * (1.0 - peak) / (1.0 - peak * sp.albedo) * sigma[i];
    write_source(i, ss * phi, ss * mean, ss * flux, sp.anisotropy / (1.0 + sqrt(peak)));
}

// The first-scattering source with its lobe, and σ_t, from the source pass.
@compute @workgroup_size(SWEEP_WORKGROUP)
fn seed(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = gid.x + gid.y * groups.x * SWEEP_WORKGROUP;
    if i >= sp.count {
        return;
    }
    let a = first_source[2u * i];
    let b = first_source[2u * i + 1u];
    sigma[i] = b.w * (1.0 - forward_peak() * sp.albedo);
    write_source(i, a.rgb, a.w, b.xyz, sp.anisotropy);
}

@compute @workgroup_size(SWEEP_WORKGROUP)
fn power(@builtin(local_invocation_index) lid: u32) {
    var sum = 0.0;
    for (var i = lid; i < sp.count; i += SWEEP_WORKGROUP) {
        sum += source[2u * i].w;
    }
    partial[lid] = sum;
    workgroupBarrier();
    for (var half = SWEEP_WORKGROUP / 2u; half > 0u; half /= 2u) {
        if lid < half {
            partial[lid] += partial[lid + half];
        }
        workgroupBarrier();
    }
    if lid == 0u {
        powers[sp.order] = partial[0];
        if sp.order == sp.orders {
            powers[TAIL_SLOT] = tail_factor();
        }
    }
}

// The ratio of order k's power to order k − 1's, 0 without light.
fn ratio(k: u32) -> f32 {
    let before = powers[k - 1u];
    if before <= 0.0 {
        return 0.0;
    }
    return clamp(powers[k] / before, 0.0, RATIO_CAP);
}

// ρ/(1 − ρ) for the last two orders' ratio ρ: the orders after the last swept one in units of
// its fluence, as a geometric series. The ratios still grow after the last order in thick,
// bright fog (towards the slowest mode's), so this is short there; extrapolating their growth
// was tried and overshoots, since the later orders sit deeper in the fog than the last one,
// where the camera sees less of them.
fn tail_factor() -> f32 {
    let rho = ratio(sp.orders);
    return rho / (1.0 - rho);
}

@compute @workgroup_size(SWEEP_WORKGROUP)
fn finish(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = gid.x + gid.y * groups.x * SWEEP_WORKGROUP;
    if i >= sp.count {
        return;
    }
    let tail = powers[TAIL_SLOT];
    let phi = totals[2u * i] + tail * order_moments[2u * i];
    let flux = totals[2u * i + 1u] + tail * order_moments[2u * i + 1u];
    moments[2u * i] = vec4f(sp.strength * phi.rgb, 0.0);
    moments[2u * i + 1u] = vec4f(sp.strength * flux.xyz, sp.strength * phi.w);
}

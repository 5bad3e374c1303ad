// Ray march: camera rays through the medium, single scattering from every light
// (physics.md §4). Each step holds σ_t and the in-scattered radiance constant and is
// integrated exactly: radiance += Tr·albedo·S'·(1 − exp(−σ_t Δ)), Tr *= exp(−σ_t Δ), where
// S' is the phase-weighted light reaching the sample. Inside the grid σ_t and each light's
// optical depth come from trilinear lookups in the EV and OPVs; outside it only the base fog
// exists (optical depth to a light = β·distance). Marching stops once Tr < tr_cutoff.

struct MarchParams {
    origin: vec3f,
    step: f32,
    right: vec3f,
    albedo: f32,
    up: vec3f,
    anisotropy: f32,
    forward: vec3f,
    exposure: f32,
    size: vec2u,
    tr_cutoff: f32,
    far_distance: f32,
}

@group(0) @binding(0) var<uniform> grid: GridParams;
@group(0) @binding(1) var<uniform> params: MarchParams;
@group(0) @binding(2) var ev: texture_3d<f32>;
@group(0) @binding(3) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(4) var<storage, read> opv: array<f32>;
@group(0) @binding(5) var out_hdr: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var out_ldr: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;

const PI: f32 = 3.14159265358979;

var<private> radiance: vec3f;
var<private> transmittance: f32;
var<private> samples: u32;

struct Trilinear {
    i0: vec3u,
    i1: vec3u,
    f: vec3f,
}

fn trilinear_at(x: vec3f) -> Trilinear {
    let hi = vec3f(grid.dims - 1u);
    let u = clamp((x - grid.min) / grid.cell - 0.5, vec3f(0.0), hi);
    let i0 = vec3u(floor(u));
    var t: Trilinear;
    t.i0 = i0;
    t.i1 = min(i0 + 1u, grid.dims - 1u);
    t.f = u - vec3f(i0);
    return t;
}

fn lerp3(c: array<f32, 8>, f: vec3f) -> f32 {
    let x00 = mix(c[0], c[1], f.x);
    let x10 = mix(c[2], c[3], f.x);
    let x01 = mix(c[4], c[5], f.x);
    let x11 = mix(c[6], c[7], f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

fn ev_at(t: Trilinear) -> f32 {
    var c: array<f32, 8>;
    for (var n = 0u; n < 8u; n++) {
        let p = select(t.i0, t.i1, vec3<bool>((n & 1u) != 0u, (n & 2u) != 0u, (n & 4u) != 0u));
        c[n] = textureLoad(ev, p, 0).r;
    }
    return lerp3(c, t.f);
}

fn opv_at(t: Trilinear, light: u32) -> f32 {
    let base = light * cell_count();
    var c: array<f32, 8>;
    for (var n = 0u; n < 8u; n++) {
        let p = select(t.i0, t.i1, vec3<bool>((n & 1u) != 0u, (n & 2u) != 0u, (n & 4u) != 0u));
        c[n] = opv[base + linear_index(p)];
    }
    return lerp3(c, t.f);
}

fn phase(cos_theta: f32) -> f32 {
    let g = params.anisotropy;
    if g == 0.0 {
        return 1.0 / (4.0 * PI);
    }
    let denom = max(1.0 + g * g - 2.0 * g * cos_theta, 1e-6);
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
}

// One step of length `dt` centred at `x`.
fn integrate(x: vec3f, dir: vec3f, dt: f32, inside: bool) {
    var sigma = grid.base_extinction;
    var tri: Trilinear;
    if inside {
        tri = trilinear_at(x);
        sigma = ev_at(tri);
    }
    samples += 1u;
    if sigma <= 0.0 {
        return;
    }
    var inscatter = vec3f(0.0);
    for (var l = 0u; l < grid.light_count; l++) {
        let light = lights[l];
        if all(light.rgb == vec3f(0.0)) {
            continue;
        }
        let to_x = x - light.position;
        let d2 = max(dot(to_x, to_x), 1e-12);
        var depth: f32;
        if inside {
            depth = opv_at(tri, l);
        } else {
            depth = grid.base_extinction * sqrt(d2);
        }
        let cos_theta = dot(to_x * inverseSqrt(d2), -dir);
        inscatter += light.rgb * (phase(cos_theta) * exp(-depth) / d2);
    }
    let tau = sigma * dt;
    radiance += transmittance * params.albedo * inscatter * one_minus_exp_neg(tau);
    transmittance *= exp(-tau);
}

// 1 − e^{−τ}, accurate for tiny τ too (σ_s·S·(1 − e^{−σ_t Δ})/σ_t with σ_s = albedo·σ_t).
fn one_minus_exp_neg(tau: f32) -> f32 {
    if tau < 1e-3 {
        return tau * (1.0 - tau * (0.5 - tau / 6.0));
    }
    return 1.0 - exp(-tau);
}

// Uniform steps of about `step` over [t0, t1].
fn march_uniform(o: vec3f, dir: vec3f, t0: f32, t1: f32, step: f32, inside: bool) {
    if t1 <= t0 {
        return;
    }
    let n = max(1u, u32(ceil((t1 - t0) / step)));
    let dt = (t1 - t0) / f32(n);
    for (var k = 0u; k < n; k++) {
        if transmittance < params.tr_cutoff {
            return;
        }
        integrate(o + dir * (t0 + (f32(k) + 0.5) * dt), dir, dt, inside);
    }
}

// Steps growing linearly over [t0, t1] (Tan et al.'s far level), for base fog beyond the grid.
fn march_growing(o: vec3f, dir: vec3f, t0: f32, t1: f32, n: u32) {
    var t = t0;
    let scale = (t1 - t0) * 2.0 / f32(n * (n + 1u));
    for (var k = 0u; k < n; k++) {
        if transmittance < params.tr_cutoff {
            return;
        }
        let dt = scale * f32(k + 1u);
        integrate(o + dir * (t + 0.5 * dt), dir, dt, false);
        t += dt;
    }
}

fn tonemap(c: vec3f) -> vec3f {
    let l = vec3f(1.0) - exp(-params.exposure * c);
    let lo = l * 12.92;
    let hi = 1.055 * pow(l, vec3f(1.0 / 2.4)) - 0.055;
    return select(hi, lo, l <= vec3f(0.0031308));
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if any(id.xy >= params.size) {
        return;
    }
    let size = vec2f(params.size);
    let sx = (f32(id.x) + 0.5) / size.x * 2.0 - 1.0;
    let sy = 1.0 - (f32(id.y) + 0.5) / size.y * 2.0;
    let dir = normalize(params.forward + params.right * sx + params.up * sy);
    let o = params.origin;

    radiance = vec3f(0.0);
    transmittance = 1.0;
    samples = 0u;

    let inv = 1.0 / dir;
    let ta = (grid.min - o) * inv;
    let tb = (grid.max - o) * inv;
    let t_enter = max(max(min(ta.x, tb.x), min(ta.y, tb.y)), max(min(ta.z, tb.z), 0.0));
    let t_exit = min(min(max(ta.x, tb.x), max(ta.y, tb.y)), max(ta.z, tb.z));
    let hit = t_exit > t_enter;
    let fog = grid.base_extinction > 0.0;

    if hit {
        if fog {
            march_uniform(o, dir, 0.0, t_enter, max(params.step, t_enter / 64.0), false);
        }
        march_uniform(o, dir, t_enter, t_exit, params.step, true);
        if fog {
            march_growing(o, dir, t_exit, t_exit + params.far_distance, 64u);
        }
    } else if fog {
        march_growing(o, dir, 0.0, params.far_distance, 96u);
    }

    atomicAdd(&counters[0], samples);
    textureStore(out_hdr, id.xy, vec4f(radiance, 1.0 - transmittance));
    textureStore(out_ldr, id.xy, vec4f(tonemap(radiance), 1.0));
}

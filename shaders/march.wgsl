// Ray march: camera rays through the medium, single scattering from every light
// (physics.md §4). Each step holds σ_t and the in-scattered radiance constant and is
// integrated exactly: radiance += Tr·albedo·S'·(1 − exp(−σ_t Δ)), Tr *= exp(−σ_t Δ), where
// S' is the phase-weighted light reaching the sample, with the inverse-square falloff
// averaged exactly over the step (so a ray passing close to a light stays accurate). Inside
// the grid σ_t and each light's optical depth come from trilinear lookups in the EV and
// OPVs; outside it σ_t is the base fog, and light paths that cross the grid still pick up
// its optical depth from the OPV where they leave it.
//
// Homogeneous base fog outside the grid uses Sun et al.'s closed form (shaders/sun.wgsl) for
// every point light whose light paths cannot meet the grid or a surface, and is marched
// otherwise; height fog (physics.md §9) is always marched there, each step's optical thickness
// and every light path's optical depth outside the grid taken from its closed form. A spot light is a
// point light times its cone factor (common.wgsl); samples outside its cone skip it entirely.
// A directional light (sun) adds σ_s·p·E·exp(−T_sun) with no falloff, T_sun from its OPV
// where its path crosses the grid and the base fog's closed form elsewhere (physics.md §9).
//
// Step policies inside the grid: FIXED (uniform steps), TWO_LEVEL (Tan et al.: uniform near
// steps, then linearly growing far steps) and ADAPTIVE (step = τ_target / (local max σ_t from
// the brick occupancy grid × √Tr), at most a tenth of the distance to the nearest light, clamped
// to [¼, 4] × the fixed step). A step's error grows like its optical thickness squared and is
// seen through the transmittance Tr in front of it, so optical thickness τ_target/√Tr keeps
// every step's share of the pixel's error that of a step at the ray's start, while a ray deep in
// dense fog takes a fraction of the steps. With skip_empty, bricks whose dilated maximum σ_t is 0
// are jumped over (exact: every sample in them would add nothing). A ray stops once its
// transmittance falls below tr_cutoff, and at the first surface, which is shaded by every
// light through the fog (Lambert, shadowed by the other surfaces, plus Sun et al.'s surface
// term; see shade_surface).
//
// Surfaces shadow the fog as they shadow each other: a sample gets no light from a light that a
// surface hides (fog_shadowed, by shadowed()'s rules, the bake's too). Inside the grid box each
// light tests only the surfaces in its `occluders` mask, those that can block a path from the
// box to it (src/gpu/frame_inputs.rs); outside the box point and spot lights test the surfaces
// that meet the box around the base-fog segment and those lights (fog_candidates), suns every
// surface, and a light that one surface hides from both a base-fog sample and the end of its
// segment is dark for the rest of the segment (the points a box or the ground hides from a light
// form a convex set): where every marched light is dark, the march leaves the segment to the
// fog's closed form.
//
// The pipeline compiles the march per combination of the features below that a scene uses
// (src/gpu/march.rs `MarchFeatures`): everything here is inlined into one loop, and code for
// what a scene lacks still slows every sample on software adapters.
override spot_lights: bool = true;
override sun_lights: bool = true;
// Base fog outside the grid.
override base_fog: bool = true;
// Surfaces, which shadow the fog.
override fog_shadows: bool = true;
// Point and spot lights in base fog test only the surfaces that can hide them (fog_candidates).
override fog_culling: bool = true;
// Multiple scattering inside the grid (ms_inscatter), where params.scatter_factor > 0.
override multiple_scattering: bool = true;

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
    policy: u32,
    near_steps: u32,
    far_steps: u32,
    skip_empty: u32,
    tau_target: f32,
    near_fraction: f32,
    min_step: f32,
    max_step: f32,
    surface_count: u32,
    row_offset: u32,
    // Directional lights among the lights, visited after the others in a loop of their own:
    // their code inside the point lights' loop slows every sample.
    sun_count: u32,
    col_offset: u32,
    // Image-space sampling (main_list): rays [list_offset, list_end) of the lattice of this
    // stride (stride 0: of the list in `work`), into the padded image.
    list_offset: u32,
    list_end: u32,
    lattice_stride: u32,
    padded_width: u32,
    padded_height: u32,
    // Fine cells per coarse cell edge of the multiple-scattering grid (ms_moments); 0: none.
    scatter_factor: u32,
    _pad1: u32,
    _pad2: u32,
}

// kind SURFACE_BOX: an axis-aligned box [min, max]; SURFACE_GROUND: the plane y = min.y, facing +y.
struct Surface {
    min: vec3f,
    kind: u32,
    max: vec3f,
    specular: f32,
    albedo: vec3f,
    phong_exponent: f32,
}

@group(0) @binding(1) var<uniform> params: MarchParams;
// Read-only storage: on llvmpipe its loads cost less than a sampled texture's.
@group(0) @binding(2) var ev: texture_storage_3d<r32float, read>;
@group(0) @binding(3) var<storage, read> lights: array<LightGpu>;
// binding 4: `lookup`, the per-light lookup volumes (shaders/march_lookup.wgsl), declared with
// its helper lookup_load by src/gpu/opv_store.rs.
@group(0) @binding(5) var out_hdr: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var out_ldr: texture_storage_2d<rgba8unorm, write>;
@group(0) @binding(7) var<storage, read_write> counters: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read> brick_max: array<f32>;
@group(0) @binding(9) var<storage, read> surfaces: array<Surface>;
@group(0) @binding(10) var<storage, read> sun_table: array<f32>;
// Multiple scattering's moments on its coarse grid (shaders/scatter_sweep.wgsl `finish`): per
// coarse cell (φ rgb, 0), (E, φ of the channel mean).
@group(0) @binding(14) var<storage, read> ms_moments: array<vec4f>;

var<private> radiance: vec3f;
var<private> transmittance: f32;
var<private> samples: u32;
var<private> skipped: u32;
// Lights (bit l for light l < 32) whose in-scattering on the current base-fog segment was
// added in closed form, so the numeric march skips them.
var<private> sun_mask: u32;
// Lights (bit l for light l < 32) that a surface hides from the rest of the current base-fog
// segment (note_blocker), and that segment's end.
var<private> dark: u32;
var<private> segment_end: vec3f;

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

fn corner(t: Trilinear, n: u32) -> vec3u {
    return select(t.i0, t.i1, vec3<bool>((n & 1u) != 0u, (n & 2u) != 0u, (n & 4u) != 0u));
}

fn ev_at(t: Trilinear) -> f32 {
    var c: array<f32, 8>;
    for (var n = 0u; n < 8u; n++) {
        c[n] = textureLoad(ev, corner(t, n)).r;
    }
    return lerp3(c, t.f);
}

// Optical depth from x to light l: |x − S| times the trilinear mean extinction T/|c − S| of
// the eight surrounding cells. The mean extinction is smooth where T itself has a kink (at
// the light) and constant in homogeneous fog, so this is exact there and accurate near lights.
fn opv_at(t: Trilinear, light: u32, x: vec3f) -> f32 {
    var c: array<f32, 8>;
    for (var n = 0u; n < 8u; n++) {
        c[n] = lookup_value(light, corner(t, n));
    }
    return lerp3(c, t.f) * length(x - lights[light].position);
}

// The lookup volume of light `light` at cell p (shaders/march_lookup.wgsl: the mean
// extinction along the cell centre's path to the light): every optical-depth read goes
// through here.
fn lookup_value(light: u32, p: vec3u) -> f32 {
    return lookup_load(light, p);
}

// A sun's optical depth from x in the grid box: the OPV holds G + B (propagate_directional.wgsl);
// the trilinear interpolation is of the mean in-box extinction G/(exit distance), exact in
// homogeneous fog, times x's own exit distance, plus x's own B.
fn sun_opv_at(t: Trilinear, light: u32, x: vec3f) -> f32 {
    let towards = -lights[light].direction;
    let beyond = sun_beyond(x, towards);
    if beyond >= OPAQUE {
        return OPAQUE;
    }
    var c: array<f32, 8>;
    for (var n = 0u; n < 8u; n++) {
        c[n] = lookup_value(light, corner(t, n));
    }
    return lerp3(c, t.f) * box_exit(x, towards) + beyond;
}

// A sun's optical depth from anywhere: base fog (closed form) up to the grid box, if the path
// meets it, then the box's volume; without the box, base fog all the way.
fn sun_depth(x: vec3f, l: u32) -> f32 {
    let towards = -lights[l].direction;
    if inside_grid(x) {
        return sun_opv_at(trilinear_at(x), l, x);
    }
    let span = box_span(x, towards);
    if span.y < span.x {
        return base_fog_depth(x, towards, -1.0);
    }
    let p = x + towards * span.x;
    return min(base_fog_depth(x, towards, span.x) + sun_opv_at(trilinear_at(p), l, p), OPAQUE);
}

fn inside_grid(x: vec3f) -> bool {
    return all(x >= grid.min) && all(x <= grid.max);
}

// Optical depth from x to light l, d = |x − S|. Inside the grid it comes from the OPV. Outside,
// the segment from the light to x may still cross the grid: then it is the OPV where the
// segment leaves the grid (everything between there and the light) plus the base fog beyond.
fn light_depth(x: vec3f, l: u32, d: f32) -> f32 {
    if inside_grid(x) {
        return opv_at(trilinear_at(x), l, x);
    }
    let s = lights[l].position;
    let u = (x - s) / max(d, 1e-30);
    let slabs = ray_slabs(s, 1.0 / u, grid.min, grid.max);
    let t_in = max(max(slabs.near.x, slabs.near.y), max(slabs.near.z, 0.0));
    let t_out = min(min(slabs.far.x, slabs.far.y), min(slabs.far.z, d));
    if t_out <= t_in {
        return base_fog_depth(s, u, d);
    }
    let p = s + u * t_out;
    return opv_at(trilinear_at(p), l, p) + base_fog_depth(p, u, d - t_out);
}

fn phase(cos_theta: f32) -> f32 {
    let g = params.anisotropy;
    if g == 0.0 {
        return 1.0 / (4.0 * PI);
    }
    return hg(cos_theta, g);
}

// 1 − e^{−τ}, accurate for tiny τ too (σ_s·S·(1 − e^{−σ_t Δ})/σ_t with σ_s = albedo·σ_t).
fn one_minus_exp_neg(tau: f32) -> f32 {
    if tau < 1e-3 {
        return tau * (1.0 - tau * (0.5 - tau / 6.0));
    }
    return 1.0 - exp(-tau);
}

// Mean of 1/|y − s|² over the step [x − dt/2·dir, x + dt/2·dir]: the exact integral of the
// inverse-square falloff (an arctangent), so a ray grazing a light is not under-sampled.
fn mean_inverse_square(x: vec3f, dir: vec3f, dt: f32, s: vec3f) -> f32 {
    let v = x - s;
    let d2 = dot(v, v);
    let mid = -dot(v, dir);
    let h = sqrt(max(d2 - mid * mid, 0.0));
    let a = -0.5 * dt - mid;
    let b = 0.5 * dt - mid;
    // Far from the light relative to the step the midpoint value is exact to f32 precision.
    if dt * dt < 1e-4 * d2 {
        return 1.0 / max(d2, 1e-30);
    }
    let hh = max(h, 1e-4 * dt);
    return (atan2(b, hh) - atan2(a, hh)) / (hh * dt);
}

// The multiply scattered light at x in the grid scattered into direction w, per unit of σ_s:
// the coarse fluence φ (trilinear between coarse cell centres) times an HG lobe about its flux
// E whose mean cosine is g·|E|/φ, the first moment of HG(g) applied to light of that spread.
fn ms_inscatter(x: vec3f, w: vec3f) -> vec3f {
    let f = params.scatter_factor;
    if f == 0u {
        return vec3f(0.0);
    }
    let dims = (grid.dims + f - 1u) / f;
    let u = clamp((x - grid.min) / (grid.cell * f32(f)) - 0.5, vec3f(0.0), vec3f(dims - 1u));
    let i0 = min(vec3u(floor(u)), dims - 1u);
    let i1 = min(i0 + 1u, dims - 1u);
    let t = u - vec3f(i0);
    var phi = vec3f(0.0);
    var flux = vec4f(0.0);
    for (var n = 0u; n < 8u; n++) {
        let bit = vec3<bool>((n & 1u) != 0u, (n & 2u) != 0u, (n & 4u) != 0u);
        let c = select(i0, i1, bit);
        let wt = select(1.0 - t, t, bit);
        let k = 2u * (c.x + dims.x * (c.y + dims.y * c.z));
        let weight = wt.x * wt.y * wt.z;
        phi += weight * ms_moments[k].rgb;
        flux += weight * ms_moments[k + 1u];
    }
    let e = length(flux.xyz);
    if flux.w <= 0.0 || e <= 0.0 {
        return phi / (4.0 * PI);
    }
    return phi * hg(dot(flux.xyz / e, w), params.anisotropy * min(e / flux.w, 1.0));
}

// One step of length `dt` centred at `x`.
fn integrate(x: vec3f, dir: vec3f, dt: f32, inside: bool) {
    // The step's optical thickness: trilinear σ_t inside the grid, the base (height) fog's
    // exact integral over the step outside it.
    var tau: f32;
    var sigma: f32;
    var tri: Trilinear;
    if inside {
        tri = trilinear_at(x);
        sigma = ev_at(tri);
        tau = sigma * dt;
    } else {
        tau = base_fog_depth(x - dir * (0.5 * dt), dir, dt);
        sigma = tau / max(dt, 1e-30);
    }
    samples += 1u;
    if sigma <= 0.0 {
        return;
    }
    var inscatter = vec3f(0.0);
    for (var l = 0u; l < grid.light_count; l++) {
        let light = lights[l];
        if all(light.rgb == vec3f(0.0)) || (l < 32u && ((sun_mask | dark) & (1u << l)) != 0u) {
            continue;
        }
        if light.kind == LIGHT_DIRECTIONAL {
            continue;
        }
        let to_x = x - light.position;
        var cone = 1.0;
        if spot_lights && light.kind == LIGHT_SPOT {
            cone = cone_mean(light, x, dir, dt);
            if cone <= 0.0 {
                continue;
            }
        }
        let d = max(length(to_x), 1e-12);
        if fog_hidden(x, inside, l, -to_x / d, d) {
            continue;
        }
        var depth: f32;
        if inside {
            depth = opv_at(tri, l, x);
        } else {
            depth = light_depth(x, l, d);
        }
        let cos_theta = dot(to_x / d, -dir);
        inscatter += light.rgb * (cone * phase(cos_theta) * exp(-depth) * mean_inverse_square(x, dir, dt, light.position));
    }
    if sun_lights && params.sun_count > 0u {
        for (var l = 0u; l < grid.light_count; l++) {
            let light = lights[l];
            if light.kind != LIGHT_DIRECTIONAL || all(light.rgb == vec3f(0.0)) || (l < 32u && (dark & (1u << l)) != 0u) {
                continue;
            }
            if fog_hidden(x, inside, l, -light.direction, OPAQUE) {
                continue;
            }
            var sun: f32;
            if inside {
                sun = sun_opv_at(tri, l, x);
            } else {
                sun = sun_depth(x, l);
            }
            inscatter += light.rgb * (phase(dot(light.direction, -dir)) * exp(-sun));
        }
    }
    if multiple_scattering && inside {
        inscatter += ms_inscatter(x, -dir);
    }
    radiance += transmittance * params.albedo * inscatter * one_minus_exp_neg(tau);
    transmittance *= exp(-tau);
}

// Uniform steps of about `step` over [t0, t1], outside the grid.
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

// n steps growing linearly over [t0, t1] (Tan et al.'s far level).
fn march_growing(o: vec3f, dir: vec3f, t0: f32, t1: f32, n: u32, inside: bool) {
    if t1 <= t0 {
        return;
    }
    var t = t0;
    let scale = (t1 - t0) * 2.0 / f32(n * (n + 1u));
    for (var k = 0u; k < n; k++) {
        if transmittance < params.tr_cutoff {
            return;
        }
        let dt = scale * f32(k + 1u);
        integrate(o + dir * (t + 0.5 * dt), dir, dt, inside);
        t += dt;
    }
}

// The distance to the nearest light where it can bound a step of dt from o + t·dir (a tenth of
// it is below dt), else a lower bound that cannot: the distance found at near_t less the way
// since (dir is a unit vector), which spares the loop over the lights on most steps.
var<private> near_d: f32;
var<private> near_t: f32;

fn light_bound(o: vec3f, dir: vec3f, t: f32, dt: f32) -> f32 {
    let bound = near_d - (t - near_t);
    if 0.0999 * bound >= dt {
        return bound;
    }
    near_d = nearest_light(o + dir * t);
    near_t = t;
    return near_d;
}

fn nearest_light(x: vec3f) -> f32 {
    var d = 3.4e38;
    for (var l = 0u; l < grid.light_count; l++) {
        if any(lights[l].rgb != vec3f(0.0)) && lights[l].kind != LIGHT_DIRECTIONAL {
            d = min(d, length(x - lights[l].position));
        }
    }
    return d;
}

// Mean cone factor of a spot over the step of length dt centred at x: a step turns the
// direction to the light by up to dt/d, so where that could cross the cone's ramp the step
// is split into up to 32 sub-steps of a quarter of the ramp's angular width A·B (at least
// 0.01 rad), each taken at its midpoint; elsewhere the factor is constant over the step.
fn cone_mean(light: LightGpu, x: vec3f, dir: vec3f, dt: f32) -> f32 {
    if light.kind != LIGHT_SPOT {
        return 1.0;
    }
    let v = x - light.position;
    let d = length(v);
    if d <= 0.0 {
        return 1.0;
    }
    let theta = acos(clamp(dot(light.direction, v) / d, -1.0, 1.0));
    let inner = light.angle * (1.0 - light.blend);
    let delta = max(max(inner - theta, theta - light.angle), 0.0);
    let turn = dt / d;
    if delta > turn {
        return select(0.0, 1.0, theta < inner);
    }
    let width = 0.25 * max(light.angle * light.blend, 0.01);
    let n = u32(clamp(ceil(turn / width), 1.0, 32.0));
    var sum = 0.0;
    for (var k = 0u; k < n; k++) {
        let y = x + dir * (dt * ((f32(k) + 0.5) / f32(n) - 0.5));
        sum += cone_factor(light, y - light.position);
    }
    return sum / f32(n);
}

// Base fog outside the grid, marched: steps grow geometrically with the distance to the grid
// box (20 % of it: the grid's shadows are sharpest near it) from the fixed step, but stay
// below a tenth of the distance to the nearest light, where phase and shadowing change
// fastest (a half made the image error 5× larger on the accuracy test). Ends away from the
// box (the camera, a surface, the far cut-off) need no small steps. Cost grows with the
// logarithm of the lengths involved, not with the lengths.
//
// `live` holds the marched lights (bit l for light l, 0 when one is beyond the 32nd): once all
// of them are dark (note_blocker), the rest of the segment only attenuates.
fn march_fog(o: vec3f, dir: vec3f, t0: f32, t1: f32, live: u32) {
    var t = t0;
    dark = 0u;
    segment_end = o + dir * t1;
    near_d = -1.0;
    loop {
        if t >= t1 || transmittance < params.tr_cutoff {
            break;
        }
        let x = o + dir * t;
        if live != 0u && (dark & live) == live {
            transmittance *= exp(-base_fog_depth(x, dir, t1 - t));
            break;
        }
        let to_box = length(max(max(grid.min - x, x - grid.max), vec3f(0.0)));
        var dt = max(params.step, 0.2 * to_box);
        dt = max(min(dt, 0.1 * light_bound(o, dir, t, dt)), params.min_step);
        dt = min(dt, t1 - t);
        integrate(o + dir * (t + 0.5 * dt), dir, dt, false);
        t += dt;
    }
    dark = 0u;
}

// Base fog outside the grid over [t0, t1]. For each light whose light paths from the whole
// segment provably miss the grid and every surface (the bounding box of the segment and the
// light misses the grid and the surface boxes, and no ground is above its bottom), with
// isotropic scattering, the in-scattering is Sun et al.'s closed form from the
// segment's start, attenuated by the transmittance so far; the other lights are marched (see
// march_fog). Without any marched light the transmittance is advanced analytically.
fn fog_segment(o: vec3f, dir: vec3f, t0: f32, t1: f32) {
    if t1 <= t0 || transmittance < params.tr_cutoff {
        return;
    }
    let beta = grid.base_extinction;
    let start = o + dir * t0;
    let end = o + dir * t1;
    sun_mask = 0u;
    // The box around the segment and the point and spot lights (fog_candidates).
    var around_lo = min(start, end);
    var around_hi = max(start, end);
    var marched = false;
    var live = 0u;
    var untracked = false;
    for (var l = 0u; l < grid.light_count; l++) {
        let light = lights[l];
        if all(light.rgb == vec3f(0.0)) {
            continue;
        }
        if light.kind != LIGHT_DIRECTIONAL {
            around_lo = min(around_lo, light.position);
            around_hi = max(around_hi, light.position);
        }
        let lo = min(min(start, end), light.position);
        let hi = max(max(start, end), light.position);
        let misses_grid = any(lo > grid.max) || any(hi < grid.min);
        if params.anisotropy == 0.0 && l < 32u && misses_grid && light.kind == LIGHT_POINT && grid.height_falloff == 0.0
            && clear_of_surfaces(lo, hi) {
            let to_light = light.position - start;
            let d_sv = length(to_light);
            let gamma = acos(clamp(dot(dir, to_light / max(d_sv, 1e-30)), -1.0, 1.0));
            radiance += transmittance * params.albedo * light.rgb * sun_la(gamma, d_sv, t1 - t0, beta, 1.0);
            sun_mask |= 1u << l;
        } else {
            marched = true;
            if l < 32u {
                live |= 1u << l;
            } else {
                untracked = true;
            }
        }
    }
    if marched {
        if fog_shadows && fog_culling && params.surface_count > 0u {
            fog_candidates = candidates_in(around_lo, around_hi);
        }
        march_fog(o, dir, t0, t1, select(live, 0u, untracked));
    } else {
        transmittance *= exp(-base_fog_depth(start, dir, t1 - t0));
    }
    sun_mask = 0u;
}

fn brick_of(x: vec3f) -> vec3u {
    let c = clamp(vec3i(floor((x - grid.min) / grid.cell)), vec3i(0), vec3i(grid.dims) - 1);
    return vec3u(c) / BRICK;
}

fn brick_max_at(b: vec3u) -> f32 {
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    return brick_max[b.x + bdims.x * (b.y + bdims.y * b.z)];
}

// Distance along the ray from o + dir·t to the exit of brick b.
fn brick_exit(o: vec3f, dir: vec3f, b: vec3u) -> f32 {
    let lo = grid.min + vec3f(b * BRICK) * grid.cell;
    let hi = min(grid.min + vec3f((b + 1u) * BRICK) * grid.cell, grid.max);
    let t_far = ray_slabs(o, safe_inverse(dir), lo, hi).far;
    return min(t_far.x, min(t_far.y, t_far.z));
}

// The in-grid part of the ray, [t0, t1], under the configured step policy.
fn march_grid(o: vec3f, dir: vec3f, t0: f32, t1: f32) {
    if t1 <= t0 {
        return;
    }
    if params.policy == POLICY_TWO_LEVEL {
        let split = t0 + params.near_fraction * (t1 - t0);
        march_uniform(o, dir, t0, split, (split - t0) / f32(max(params.near_steps, 1u)), true);
        march_growing(o, dir, split, t1, max(params.far_steps, 1u), true);
        return;
    }
    let eps = 1e-4 * min(grid.cell.x, min(grid.cell.y, grid.cell.z));
    var t = t0;
    near_d = -1.0;
    loop {
        if t >= t1 || transmittance < params.tr_cutoff {
            break;
        }
        let x = o + dir * t;
        let b = brick_of(x + dir * eps);
        let bmax = brick_max_at(b);
        if params.skip_empty != 0u && bmax <= 0.0 {
            skipped += 1u;
            t = max(brick_exit(o, dir, b), t) + eps;
            continue;
        }
        var dt = params.step;
        if params.policy == POLICY_ADAPTIVE {
            dt = clamp(params.tau_target / (max(bmax, 1e-12) * sqrt(transmittance)), params.min_step, params.max_step);
            // Radiance varies like 1/d² near a light: keep steps below a tenth of the distance.
            dt = max(min(dt, 0.1 * light_bound(o, dir, t, dt)), params.min_step);
            // Do not stride past the brick: its neighbour may be denser.
            dt = min(dt, max(brick_exit(o, dir, b) - t, params.min_step));
        }
        dt = min(dt, t1 - t);
        integrate(o + dir * (t + 0.5 * dt), dir, dt, true);
        t += dt;
    }
}

struct Hit {
    t: f32,
    // Index of the surface hit (NO_SURFACE for none).
    surface: u32,
    normal: vec3f,
    albedo: vec3f,
    specular: f32,
    phong_exponent: f32,
}

fn first_surface(o: vec3f, dir: vec3f) -> Hit {
    var hit: Hit;
    hit.t = 3.4e38;
    hit.surface = NO_SURFACE;
    for (var i = 0u; i < params.surface_count; i++) {
        let s = surfaces[i];
        if s.kind == SURFACE_GROUND {
            if dir.y < 0.0 && o.y > s.min.y {
                let t = (s.min.y - o.y) / dir.y;
                if t < hit.t {
                    hit.t = t;
                    hit.surface = i;
                    hit.normal = vec3f(0.0, 1.0, 0.0);
                    hit.albedo = s.albedo;
                    hit.specular = s.specular;
                    hit.phong_exponent = s.phong_exponent;
                }
            }
        } else {
            let slabs = ray_slabs(o, safe_inverse(dir), s.min, s.max);
            let tn = slabs.near;
            let tf = slabs.far;
            let t_in = max(tn.x, max(tn.y, tn.z));
            let t_out = min(tf.x, min(tf.y, tf.z));
            if t_in > 0.0 && t_in <= t_out && t_in < hit.t {
                hit.t = t_in;
                hit.surface = i;
                hit.albedo = s.albedo;
                hit.specular = s.specular;
                hit.phong_exponent = s.phong_exponent;
                if t_in == tn.x {
                    hit.normal = vec3f(-sign(dir.x), 0.0, 0.0);
                } else if t_in == tn.y {
                    hit.normal = vec3f(0.0, -sign(dir.y), 0.0);
                } else {
                    hit.normal = vec3f(0.0, 0.0, -sign(dir.z));
                }
            }
        }
    }
    return hit;
}

// Whether a surface blocks the path from x (on a surface with normal n) along unit u before
// distance t_max: boxes (entered from outside or containing the start) and the ground (from
// above). The start is lifted off its own surface along n; a light within 0.1 % of the
// distance of a face, on its outer side, is not blocked by that face.
fn shadowed(x: vec3f, n: vec3f, u: vec3f, t_max: f32) -> bool {
    let eps = 1e-5 * (1.0 + max(max(abs(x.x), abs(x.y)), abs(x.z)));
    return blocker(x + n * eps, u, t_max) != NO_SURFACE;
}

// Whether surface s blocks the path from o along unit u (inv = safe_inverse(u)) before `reach`.
fn blocks(s: Surface, o: vec3f, u: vec3f, inv: vec3f, reach: f32) -> bool {
    if s.kind == SURFACE_GROUND {
        return u.y < 0.0 && o.y > s.min.y && (s.min.y - o.y) / u.y < reach;
    }
    let slabs = ray_slabs(o, inv, s.min, s.max);
    let tn = slabs.near;
    let tf = slabs.far;
    let t_in = max(tn.x, max(tn.y, tn.z));
    let t_out = min(tf.x, min(tf.y, tf.z));
    return t_out > 0.0 && t_in <= t_out && t_in < reach;
}

// shadowed(x, 0, u, t_max) for a fog sample x and light l: in the grid box only the surfaces of
// the light's occluders mask (bit i: surface i < 32) and those from the 33rd on can block, the
// others provably cannot, so they are skipped.
fn fog_shadowed(x: vec3f, l: u32, u: vec3f, t_max: f32) -> bool {
    if !fog_shadows || params.surface_count == 0u {
        return false;
    }
    if !inside_grid(x) {
        return shadowed(x, vec3f(0.0), u, t_max);
    }
    return blocker_among(lights[l].occluders, x, u, t_max) != NO_SURFACE;
}

// fog_shadowed for a sample of the march: in base fog outside the grid, a light found hidden is
// also tested for the rest of the segment (note_blocker).
fn fog_hidden(x: vec3f, inside: bool, l: u32, u: vec3f, t_max: f32) -> bool {
    if inside {
        return fog_shadowed(x, l, u, t_max);
    }
    if !fog_shadows || params.surface_count == 0u {
        return false;
    }
    var candidates = ALL_SURFACES;
    if fog_culling && lights[l].kind != LIGHT_DIRECTIONAL {
        candidates = fog_candidates;
    }
    let i = blocker_among(candidates, x, u, t_max);
    if i == NO_SURFACE {
        return false;
    }
    note_blocker(i, l);
    return true;
}

// Surfaces (bit i for surface i < 32) that can hide a point or spot light from a sample of the
// current base-fog segment: those that meet the box around the segment and those lights, which
// holds every such light path (padded against rounding). A sun's paths leave any box: it tests
// every surface.
var<private> fog_candidates: u32;

fn candidates_in(lo: vec3f, hi: vec3f) -> u32 {
    let pad = 1e-4 * (1.0 + max(max(max(abs(lo.x), abs(lo.y)), abs(lo.z)), max(max(abs(hi.x), abs(hi.y)), abs(hi.z))));
    var mask = 0u;
    for (var i = 0u; i < min(params.surface_count, 32u); i++) {
        let s = surfaces[i];
        var meets: bool;
        if s.kind == SURFACE_GROUND {
            meets = s.min.y > lo.y - pad;
        } else {
            meets = all(s.min <= hi + pad) && all(s.max >= lo - pad);
        }
        if meets {
            mask |= 1u << i;
        }
    }
    return mask;
}

// The first surface (by index) among those of `mask` (bit i: surface i < 32) and those from the
// 33rd on that blocks the path from x along unit u before distance t_max, or NO_SURFACE. The
// order is the index order, so a mask that leaves out only surfaces that cannot block finds the
// same one.
fn blocker_among(mask: u32, x: vec3f, u: vec3f, t_max: f32) -> u32 {
    let reach = t_max * (1.0 - 1e-3);
    let inv = safe_inverse(u);
    var m = mask;
    while m != 0u {
        let i = firstTrailingBit(m);
        m &= m - 1u;
        if i >= params.surface_count {
            break;
        }
        if blocks(surfaces[i], x, u, inv, reach) {
            return i;
        }
    }
    for (var i = 32u; i < params.surface_count; i++) {
        if blocks(surfaces[i], x, u, inv, reach) {
            return i;
        }
    }
    return NO_SURFACE;
}

const NO_SURFACE: u32 = 0xffffffffu;
const ALL_SURFACES: u32 = 0xffffffffu;

// blocker_among(ALL_SURFACES, x, u, t_max) as a plain loop over the surfaces: shadowed()'s test
// from a point already lifted off its surface. Through blocker_among the march took about 5 %
// longer on llvmpipe (cornell, street).
fn blocker(x: vec3f, u: vec3f, t_max: f32) -> u32 {
    let reach = t_max * (1.0 - 1e-3);
    let inv = safe_inverse(u);
    for (var i = 0u; i < params.surface_count; i++) {
        if blocks(surfaces[i], x, u, inv, reach) {
            return i;
        }
    }
    return NO_SURFACE;
}

// Surface i hides light l from a base-fog sample. The points a box or the ground hides from a
// light (by blocks(), its reach included) form a convex set, so if i also hides l from the
// segment's end, it hides it from every sample between: l is dark for the rest of the segment.
fn note_blocker(i: u32, l: u32) {
    if l >= 32u {
        return;
    }
    let light = lights[l];
    var u = -light.direction;
    var reach = OPAQUE * (1.0 - 1e-3);
    if light.kind != LIGHT_DIRECTIONAL {
        let v = light.position - segment_end;
        let d = max(length(v), 1e-12);
        u = v / d;
        reach = d * (1.0 - 1e-3);
    }
    if blocks(surfaces[i], segment_end, u, safe_inverse(u), reach) {
        dark |= 1u << l;
    }
}

// Whether no surface can block a path between two points of the box [lo, hi]: no surface box's
// interior overlaps it and the ground is not above its bottom.
fn clear_of_surfaces(lo: vec3f, hi: vec3f) -> bool {
    for (var i = 0u; i < params.surface_count; i++) {
        let s = surfaces[i];
        if s.kind == SURFACE_GROUND {
            if s.min.y > lo.y {
                return false;
            }
        } else if all(s.min < hi) && all(s.max > lo) {
            return false;
        }
    }
    return true;
}

// Radiance leaving x towards the camera (view direction `dir`), Lambertian plus the surface's
// Phong-specular part: every light's direct light through the fog unless a surface shadows
// it, plus, in homogeneous base fog (no height falloff), Sun et al.'s surface term for point
// and spot lights (shaders/surface_glow.wgsl), diffuse and specular: isotropic scattering,
// the spot's cone factor towards x, the grid's extra optical depth on the direct path, no
// occlusion of the glow. A sun adds none: homogeneous fog without end extinguishes it.
fn shade_surface(x: vec3f, hit: Hit, dir: vec3f) -> vec3f {
    let n = hit.normal;
    let albedo = hit.albedo;
    let ks = hit.specular;
    let mirror = reflect(dir, n);
    var l_out = vec3f(0.0);
    let beta = grid.base_extinction;
    let glow = beta > 0.0 && grid.height_falloff == 0.0;
    for (var l = 0u; l < grid.light_count; l++) {
        let light = lights[l];
        if all(light.rgb == vec3f(0.0)) {
            continue;
        }
        if sun_lights && light.kind == LIGHT_DIRECTIONAL {
            let cos_sun = dot(n, -light.direction);
            if cos_sun > 0.0 && !shadowed(x, n, -light.direction, OPAQUE) {
                let brdf = albedo / PI * cos_sun + ks * phong_lobe(dot(mirror, -light.direction), hit.phong_exponent);
                l_out += brdf * light.rgb * exp(-sun_depth(x, l));
            }
            continue;
        }
        let to_light = light.position - x;
        let d2 = max(dot(to_light, to_light), 1e-12);
        let d = sqrt(d2);
        let cos_i = dot(n, to_light / d);
        var cone = 1.0;
        if spot_lights {
            cone = cone_factor(light, -to_light);
        }
        if cone <= 0.0 || (cos_i <= 0.0 && !glow) {
            continue;
        }
        let depth = light_depth(x, l, d);
        if glow {
            let theta_s = acos(clamp(cos_i, -1.0, 1.0));
            let extra = exp(-max(depth - beta * d, 0.0));
            var rho = albedo * glow_radiance(beta, d, theta_s);
            if ks > 0.0 {
                let theta_r = acos(clamp(dot(mirror, to_light / d), -1.0, 1.0));
                rho += vec3f(ks * spec_radiance(beta, d, theta_r, hit.phong_exponent));
            }
            l_out += rho * light.rgb * (params.albedo * cone * extra);
        }
        if cos_i > 0.0 && !shadowed(x, n, to_light / d, d) {
            let brdf = albedo / PI * cos_i + ks * phong_lobe(dot(mirror, to_light / d), hit.phong_exponent);
            l_out += brdf * light.rgb * (cone / d2 * exp(-depth));
        }
    }
    return l_out;
}

fn tonemap(c: vec3f) -> vec3f {
    let l = vec3f(1.0) - exp(-params.exposure * c);
    let lo = l * 12.92;
    let hi = 1.055 * pow(l, vec3f(1.0 / 2.4)) - 0.055;
    return select(hi, lo, l <= vec3f(0.0031308));
}

// The unit direction of the camera ray through the centre of pixel `px`.
fn camera_ray(px: vec2u) -> vec3f {
    let size = vec2f(params.size);
    let sx = (f32(px.x) + 0.5) / size.x * 2.0 - 1.0;
    let sy = 1.0 - (f32(px.y) + 0.5) / size.y * 2.0;
    return normalize(params.forward + params.right * sx + params.up * sy);
}

// Where the camera ray from o along dir enters the grid box (not before o) and leaves it: it
// crosses the box where y > x.
fn grid_span(o: vec3f, dir: vec3f) -> vec2f {
    let slabs = ray_slabs(o, safe_inverse(dir), grid.min, grid.max);
    let t_enter = max(max(slabs.near.x, slabs.near.y), max(slabs.near.z, 0.0));
    return vec2f(t_enter, min(min(slabs.far.x, slabs.far.y), slabs.far.z));
}

// The radiance (rgb) and opacity 1 − Tr (a) of the camera ray through pixel `px`, the first
// surface's shading included where `surface`; adds its samples, skipped bricks, termination
// and the ray itself to the counters.
fn march_ray(px: vec2u, surface: bool) -> vec4f {
    let dir = camera_ray(px);
    let o = params.origin;

    radiance = vec3f(0.0);
    transmittance = 1.0;
    samples = 0u;
    skipped = 0u;

    let hit = first_surface(o, dir);
    let span = grid_span(o, dir);
    let t_enter = span.x;
    let t_exit = span.y;
    let in_box = t_exit > t_enter;
    let fog = base_fog && grid.base_extinction > 0.0;

    sun_mask = 0u;
    if in_box {
        if fog {
            fog_segment(o, dir, 0.0, min(t_enter, hit.t));
        }
        march_grid(o, dir, t_enter, min(t_exit, hit.t));
        if fog {
            fog_segment(o, dir, t_exit, min(t_exit + params.far_distance, hit.t));
        }
    } else if fog {
        fog_segment(o, dir, 0.0, min(params.far_distance, hit.t));
    }
    if surface && hit.t < 3.4e38 && transmittance >= params.tr_cutoff {
        let x = o + dir * hit.t;
        radiance += transmittance * shade_surface(x, hit, dir);
    }
    let terminated = select(0u, 1u, transmittance < params.tr_cutoff);

    atomicAdd(&counters[0], samples);
    atomicAdd(&counters[1], skipped);
    atomicAdd(&counters[2], terminated);
    atomicAdd(&counters[3], 1u);
    return vec4f(radiance, 1.0 - transmittance);
}

// Per-pixel sampling: one ray per pixel of the band, straight into the image.
@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let id = gid + vec3u(params.col_offset, params.row_offset, 0u);
    if any(id.xy >= params.size) {
        return;
    }
    let v = march_ray(id.xy, true);
    textureStore(out_hdr, id.xy, v);
    textureStore(out_ldr, id.xy, vec4f(tonemap(v.rgb), 1.0));
}

// Image-space sampling (src/gpu/image_sampling.rs, shaders/image_refine.wgsl): rays of a
// lattice and of the lists refinement gathers go into `image_samples`, over an image padded right and
// below to a whole number of lattice cells (padding pixels are real rays, just off screen);
// refinement interpolates the rest, and `resolve` writes the image.
@group(0) @binding(12) var<storage, read_write> image_samples: array<vec4f>;
// work[0, padded pixels): each pixel's geometry class (classify); from there on, the ray list
// (x | y << 16) and refinement's cell flags.
@group(0) @binding(13) var<storage, read_write> work: array<u32>;

fn padded_index(px: vec2u) -> u32 {
    return px.y * params.padded_width + px.x;
}

// What the ray through `px` meets, as a number: neighbours with equal classes see the same
// face of the same surface (or none) and the same side of the grid box's silhouette, so the
// fog in front of them can jump only where classes differ.
fn geometry_class(px: vec2u) -> u32 {
    let o = params.origin;
    let dir = camera_ray(px);
    let hit = first_surface(o, dir);
    let span = grid_span(o, dir);
    var seen = select(0u, 1u, span.y > span.x);
    if hit.surface != NO_SURFACE {
        let n = hit.normal;
        let face = select(select(4u, 2u, n.y != 0.0), 0u, n.x != 0.0) + select(0u, 1u, n.x + n.y + n.z > 0.0);
        seen |= (1u + hit.surface * 6u + face) << 1u;
    }
    return seen;
}

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn classify(@builtin(global_invocation_id) gid: vec3u) {
    if gid.x >= params.padded_width || gid.y >= params.padded_height {
        return;
    }
    work[padded_index(gid.xy)] = geometry_class(gid.xy);
}

// Rays [list_offset, list_end) of a lattice or of the list, each into `samples`.
@compute @workgroup_size(64, 1, 1)
fn main_list(@builtin(global_invocation_id) gid: vec3u, @builtin(num_workgroups) groups: vec3u) {
    let i = params.list_offset + gid.x + gid.y * groups.x * 64u;
    if i >= params.list_end {
        return;
    }
    var px: vec2u;
    if params.lattice_stride > 0u {
        let columns = (params.padded_width - 1u) / params.lattice_stride + 1u;
        px = vec2u(i % columns, i / columns) * params.lattice_stride;
    } else {
        let e = work[params.padded_width * params.padded_height + i];
        px = vec2u(e & 0xffffu, e >> 16u);
    }
    image_samples[padded_index(px)] = march_ray(px, false);
}

// The image from the samples of the fog, marched or interpolated, and the first surface's
// shading, every pixel its own: detail on surfaces (shadow edges, highlights, the fog's
// shadows) stays sharp however coarsely the fog in front of them is sampled.
@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn resolve(@builtin(global_invocation_id) gid: vec3u) {
    if any(gid.xy >= params.size) {
        return;
    }
    var v = image_samples[padded_index(gid.xy)];
    let tr = 1.0 - v.a;
    if params.surface_count > 0u && tr >= params.tr_cutoff {
        let dir = camera_ray(gid.xy);
        let hit = first_surface(params.origin, dir);
        if hit.t < 3.4e38 {
            v = vec4f(v.rgb + tr * shade_surface(params.origin + dir * hit.t, hit, dir), v.a);
        }
    }
    textureStore(out_hdr, gid.xy, v);
    textureStore(out_ldr, gid.xy, vec4f(tonemap(v.rgb), 1.0));
}

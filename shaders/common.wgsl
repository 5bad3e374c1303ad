// Shared declarations, prepended to every Fogsmith compute shader after the constants that
// src/gpu/layout.rs generates (LIGHT_*, POLICY_*, SURFACE_*, workgroup sizes, PI, ...). Every
// pipeline binds the grid at binding 0.

struct GridParams {
    min: vec3f,
    base_extinction: f32,
    max: vec3f,
    light_count: u32,
    cell: vec3f,
    has_base_layer: u32,
    dims: vec3u,
    // Edge, in cells, of the bins particles are listed in for injection.
    bin_size: u32,
    // Exponential height fog: base fog β(y) = base_extinction·exp(−height_falloff·(y − height_origin)).
    height_falloff: f32,
    height_origin: f32,
    _pad_h0: u32,
    _pad_h1: u32,
    // Fractal noise on the particles (shaders/noise.wgsl); noise_octaves = 0: none.
    noise_amplitude: f32,
    noise_frequency: f32,
    noise_octaves: u32,
    noise_seed: u32,
    // The noise's drift (wind): n is evaluated at x − noise_offset.
    noise_offset: vec3f,
    _pad_n: u32,
}

// A light (kind LIGHT_POINT, LIGHT_SPOT or LIGHT_DIRECTIONAL): position, intensity per RGB
// channel (W/sr; W/m² for a directional light), unit direction (the spot's axis or the
// direction a sun's light travels), the spot's half-angle (radians) and blend. Hidden and
// culled lights have zero rgb. occluders: bit i set when surface i (< 32) can block a path
// from the grid box to the light (the march's fog_shadowed).
struct LightGpu {
    position: vec3f,
    kind: u32,
    rgb: vec3f,
    angle: f32,
    direction: vec3f,
    blend: f32,
    occluders: u32,
}

@group(0) @binding(0) var<uniform> grid: GridParams;

// The spot's cone factor at offset v from its apex (physics.md §9), 1 for other kinds:
// t = clamp((A − θ)/(A·B), 0, 1), factor t²(3 − 2t); a hard edge when B = 0.
fn cone_factor(light: LightGpu, v: vec3f) -> f32 {
    if light.kind != LIGHT_SPOT {
        return 1.0;
    }
    let len = length(v);
    if len <= 0.0 {
        return 1.0;
    }
    let theta = acos(clamp(dot(light.direction, v) / len, -1.0, 1.0));
    if light.blend <= 0.0 {
        return select(0.0, 1.0, theta <= light.angle);
    }
    let t = clamp((light.angle - theta) / (light.angle * light.blend), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

// The Henyey–Greenstein phase function of asymmetry g at cos θ, per steradian.
fn hg(cos_theta: f32, g: f32) -> f32 {
    let denom = max(1.0 + g * g - 2.0 * g * cos_theta, 1e-6);
    return (1.0 - g * g) / (4.0 * PI * denom * sqrt(denom));
}

fn cell_center(id: vec3u) -> vec3f {
    return grid.min + (vec3f(id) + 0.5) * grid.cell;
}

fn linear_index(id: vec3u) -> u32 {
    return id.x + grid.dims.x * (id.y + grid.dims.y * id.z);
}

fn cell_count() -> u32 {
    return grid.dims.x * grid.dims.y * grid.dims.z;
}

// An optical depth standing for "opaque": exp(−OPAQUE) is 0 and sums of it stay finite.
const OPAQUE: f32 = 1e30;
// Base-fog extinction at height y (physics.md §9), its exponent clamped at
// MAX_HEIGHT_EXPONENT far below y₀.
fn base_fog_at(y: f32) -> f32 {
    if grid.height_falloff == 0.0 {
        return grid.base_extinction;
    }
    return grid.base_extinction * exp(min(-grid.height_falloff * (y - grid.height_origin), MAX_HEIGHT_EXPONENT));
}

// False in a stage built for scenes without height fog (grid.height_falloff = 0), which then
// compiles without its closed form below.
override height_fog: bool = true;

// Optical depth of the base fog along o + t·d (|d| = 1) for t in [0, len]; len < 0 means to
// infinity. Closed form of physics.md §9, in log space so that neither a dense layer far
// below y₀ nor a long path into it overflows; at least OPAQUE means opaque.
fn base_fog_depth(o: vec3f, d: vec3f, len: f32) -> f32 {
    let beta = grid.base_extinction;
    if beta <= 0.0 {
        return 0.0;
    }
    let k = grid.height_falloff;
    if !height_fog || k == 0.0 {
        return select(OPAQUE, min(beta * len, OPAQUE), len >= 0.0);
    }
    let c = k * d.y;
    let a = min(-k * (o.y - grid.height_origin), MAX_HEIGHT_EXPONENT);
    // ∫_0^L e^{−c t} dt = L·φ(cL), φ(x) = (1 − e^{−x})/x; for x < 0 it grows like e^{|x|}/|x|.
    var log_f: f32;
    if len < 0.0 {
        if c <= 0.0 {
            return OPAQUE;
        }
        log_f = -log(c);
    } else {
        let x = c * len;
        if abs(x) < 0.1 {
            // The series of φ (error below x⁵/720): 1 − e^{−x} would cancel in f32 here.
            log_f = log(max(len, 1e-30)) + log(1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x / 120.0))));
        } else if x > 0.0 {
            log_f = log((1.0 - exp(-x)) / c);
        } else {
            // (e^{|x|} − 1)/|c| = e^{|x|}·(1 − e^{−|x|})/|c|
            log_f = -x + log((1.0 - exp(x)) / -c);
        }
    }
    let log_t = log(beta) + a + log_f;
    if log_t > 69.0 {
        return OPAQUE;
    }
    return exp(log_t);
}

// Distance from x (in or on the grid box) along u to where it leaves the box; axes with no
// component along u never bound it, so a direction parallel to a face gives no NaN.
fn box_exit(x: vec3f, u: vec3f) -> f32 {
    var t = 3.4e38;
    for (var a = 0u; a < 3u; a++) {
        if u[a] > 1e-12 {
            t = min(t, (grid.max[a] - x[a]) / u[a]);
        } else if u[a] < -1e-12 {
            t = min(t, (grid.min[a] - x[a]) / u[a]);
        }
    }
    return max(t, 0.0);
}

// Where the ray x + t·u (t ≥ 0) is inside the grid box: (t_in, t_out), empty when t_out < t_in.
fn box_span(x: vec3f, u: vec3f) -> vec2f {
    var t0 = 0.0;
    var t1 = 3.4e38;
    for (var a = 0u; a < 3u; a++) {
        if abs(u[a]) > 1e-12 {
            let ta = (grid.min[a] - x[a]) / u[a];
            let tb = (grid.max[a] - x[a]) / u[a];
            t0 = max(t0, min(ta, tb));
            t1 = min(t1, max(ta, tb));
        } else if x[a] < grid.min[a] || x[a] > grid.max[a] {
            return vec2f(1.0, -1.0);
        }
    }
    return vec2f(t0, t1);
}

// 1/d for the slab tests, with components below 1e-30 in magnitude taken as 1e-30: a ray
// parallel to a slab then gets finite distances, never 0·∞ = NaN when its origin lies on the
// slab's plane.
fn safe_inverse(d: vec3f) -> vec3f {
    return 1.0 / select(d, vec3f(1e-30), abs(d) < vec3f(1e-30));
}

// The slab test of the ray o + t·d against the box [lo, hi], given inv = safe_inverse(d): per
// axis, the distances where the ray enters (near) and leaves (far) that axis's slab.
struct Slabs {
    near: vec3f,
    far: vec3f,
}

fn ray_slabs(o: vec3f, inv: vec3f, lo: vec3f, hi: vec3f) -> Slabs {
    let ta = (lo - o) * inv;
    let tb = (hi - o) * inv;
    return Slabs(min(ta, tb), max(ta, tb));
}

// A sun's optical depth from a point x in the grid box: the base fog beyond the box exit
// towards the sun (−direction), in closed form.
fn sun_beyond(x: vec3f, towards: vec3f) -> f32 {
    let e = box_exit(x, towards);
    return base_fog_depth(x + towards * e, towards, -1.0);
}

// A sun's mean in-box extinction at x, from its optical depth `depth` there: (depth − B)/exit,
// B the base fog beyond the box (sun_beyond). Interpolated between cells, it is exact in
// homogeneous fog (propagate_directional.wgsl, march_lookup.wgsl).
fn sun_mean_extinction(depth: f32, x: vec3f, towards: vec3f) -> f32 {
    let e = box_exit(x, towards);
    let b = sun_beyond(x, towards);
    return max(depth - b, 0.0) / max(e, 1e-30);
}

// Trilinear interpolation of corners c (x fastest, then y, then z) at fractions f: along x, then
// y, then z.
fn lerp3(c: array<f32, 8>, f: vec3f) -> f32 {
    let x00 = mix(c[0], c[1], f.x);
    let x10 = mix(c[2], c[3], f.x);
    let x01 = mix(c[4], c[5], f.x);
    let x11 = mix(c[6], c[7], f.x);
    return mix(mix(x00, x10, f.y), mix(x01, x11, f.y), f.z);
}

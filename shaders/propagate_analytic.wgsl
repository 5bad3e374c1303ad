// Opacity propagation in closed form: every cell integrates the particles along its path to
// the light analytically, so its optical depth is exact at the cell centre whatever the grid
// resolution (the other schemes integrate the grid's trilinear medium, which resolves a
// particle of a cell or two poorly).
//
// The path is walked brick by brick (8³ cells, a 3D DDA) up to where it leaves the grid box.
// Each brick lists the particles whose cut-off sphere overlaps it (src/gpu/binning.rs), and
// each listed particle adds its gaussian's integral over the path's interval inside that
// brick: ρ·exp(−b²/r²)·r·√π/2·[erf((t₁ − t_c)/r) − erf((t₀ − t_c)/r)], with t_c the path
// parameter closest to its centre and b that closest distance. A particle listed in several
// bricks is thus counted once over the union of their intervals, which covers its support;
// what it has beyond its cut-off is below the EV's own cut-off. Base and height fog are added
// in closed form over the whole path, inside the box and beyond it. Noise and an imported base
// volume exist only on the grid, so this scheme refuses them (src/gpu/pipeline.rs).
//
// A sun's path is the ray along its reversed direction of travel: particles up to the box's
// exit, base and height fog to infinity.
//
// Cost: the list entries along the path, so it suits scenes whose bricks list few particles.

struct AnalyticParams {
    light: u32,
    _pad0: u32,
    z_offset: u32,
    _pad1: u32,
}

@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> params: AnalyticParams;
// binding 4: `opv`, declared with its helpers by src/gpu/opv_store.rs.
// Two entries per particle (src/gpu/gpu_types.rs, AnalyticParticle): its centre and 1/r, then
// ρ·r·√π/2 in x. Read as vec4s so that a lane gathers the second's x alone.
@group(0) @binding(5) var<storage, read> particles: array<vec4f>;
// Brick b lists items[offsets[b] .. offsets[b + 1]].
@group(0) @binding(6) var<storage, read> offsets: array<u32>;
@group(0) @binding(7) var<storage, read> items: array<u32>;

// erf by Abramowitz & Stegun 7.1.26 (absolute error below 1.5e-7).
fn erf_approx(x: f32) -> f32 {
    let a = abs(x);
    let t = 1.0 / (1.0 + 0.3275911 * a);
    let poly = ((((1.061405429 * t - 1.453152027) * t + 1.421413741) * t - 0.284496736) * t + 0.254829592) * t;
    return sign(x) * (1.0 - poly * exp(-a * a));
}

// ∫σ of the particles listed in brick `b` over [t0, t1] of the ray x + t·dir.
fn brick_depth(b: u32, x: vec3f, dir: vec3f, t0: f32, t1: f32) -> f32 {
    var sum = 0.0;
    for (var k = offsets[b]; k < offsets[b + 1u]; k++) {
        let i = 2u * items[k];
        let p = particles[i];
        let d = p.xyz - x;
        let tc = dot(d, dir);
        // |d|² − tc² would cancel in f32 for a particle far along the path.
        let perp = d - dir * tc;
        let b2 = dot(perp, perp);
        let span = erf_approx((t1 - tc) * p.w) - erf_approx((t0 - tc) * p.w);
        sum += particles[i + 1u].x * exp(-b2 * p.w * p.w) * span;
    }
    return sum;
}

// Rows of 64 cells along x: neighbouring lanes cross the same bricks.
@compute @workgroup_size(WORKGROUP_ROW, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let id = gid + vec3u(0u, 0u, params.z_offset);
    if any(id >= grid.dims) {
        return;
    }
    let x = grid.min + (vec3f(id) + 0.5) * grid.cell;
    let light = lights[params.light];
    // A sun's rays are parallel: the path runs along the reversed direction of travel to
    // infinity (len < 0 for base_fog_depth), its particles clipped to the box like a point
    // light's.
    let sun = light.kind == LIGHT_DIRECTIONAL;
    let s = light.position;
    var len = length(s - x);
    var dir = (s - x) / len;
    if sun {
        dir = -light.direction;
        len = -1.0;
    } else if len <= 0.0 {
        opv_store(params.light, id, 0.0);
        return;
    }
    let inside = select(min(box_exit(x, dir), len), box_exit(x, dir), sun);
    let size = grid.cell * f32(BRICK);
    let bdims = vec3i((grid.dims + BRICK - 1u) / BRICK);
    var b = min(vec3i(floor((x - grid.min) / size)), bdims - 1);
    var next = vec3f(3.4e38);
    var delta = vec3f(3.4e38);
    var step = vec3i(0);
    for (var i = 0u; i < 3u; i++) {
        if dir[i] > 0.0 {
            step[i] = 1;
            next[i] = (grid.min[i] + f32(b[i] + 1) * size[i] - x[i]) / dir[i];
            delta[i] = size[i] / dir[i];
        } else if dir[i] < 0.0 {
            step[i] = -1;
            next[i] = (grid.min[i] + f32(b[i]) * size[i] - x[i]) / dir[i];
            delta[i] = -size[i] / dir[i];
        }
    }
    var t = 0.0;
    var t0 = 0.0;
    // Each round enters the next brick along the path; it ends at the box's exit.
    loop {
        let t1 = min(min(next.x, next.y), min(next.z, inside));
        if t1 > t0 {
            t += brick_depth(u32(b.x + bdims.x * (b.y + bdims.y * b.z)), x, dir, t0, t1);
        }
        if t1 >= inside {
            break;
        }
        t0 = t1;
        if next.x <= next.y && next.x <= next.z {
            b.x += step.x;
            next.x += delta.x;
        } else if next.y <= next.z {
            b.y += step.y;
            next.y += delta.y;
        } else {
            b.z += step.z;
            next.z += delta.z;
        }
        if any(b < vec3i(0)) || any(b >= bdims) {
            break;
        }
    }
    opv_store(params.light, id, min(t + base_fog_depth(x, dir, len), OPAQUE));
}

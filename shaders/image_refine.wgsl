// Adaptive image-space sampling: one refinement level (src/gpu/image_sampling.rs). The march
// has marched (or this shader interpolated) every point of the lattice of stride `stride`
// over the padded image; this level gives every point of the lattice of stride `stride / 2`
// a value. A lattice cell whose four corners agree within the tolerance, whose pixels all see
// the same geometry seen (shaders/march.wgsl geometry_class: the same face of the same
// surface, the same side of the grid box's silhouette) and that holds no light's epipole has
// its new points interpolated (bilinear: edge midpoints from their edge, the centre from all
// four corners); every other new point goes on the list of rays to march, gathered per
// workgroup so that neighbouring rays stay neighbours in the list.
//
// Agreement: the interpolation's error, estimated from the second differences of the lattice
// at the cell's corners, is at most tolerance × (the corners' mean radiance + the image's mean
// radiance) in every channel, and at most the tolerance in opacity. The first term bounds the
// relative error where the image is bright, the second its absolute error where it is dark,
// against the image's own scale. A smooth gradient across a cell is interpolated however steep;
// an edge, a kink or noise between lattice points shows as a large second difference.

struct RefineParams {
    padded: vec2u,
    stride: u32,
    tolerance: f32,
    epipole_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
    // Pixel positions of the lights' epipoles on screen (xy; zw unused).
    epipoles: array<vec4f, 8>,
}

@group(0) @binding(0) var<uniform> rp: RefineParams;
@group(0) @binding(1) var<storage, read_write> samples: array<vec4f>;
@group(0) @binding(2) var<storage, read_write> work: array<u32>;
// [0]: rays listed by `points`; [1]: the image's mean radiance (f32 bits), from `reference`.
@group(0) @binding(3) var<storage, read_write> stats: array<atomic<u32>>;

fn index(p: vec2u) -> u32 {
    return p.y * rp.padded.x + p.x;
}

fn pixels() -> u32 {
    return rp.padded.x * rp.padded.y;
}

// Flags of the cells of this level, after the list's largest size (three new points in four).
fn flags_base() -> u32 {
    return 2u * pixels();
}

fn cells() -> vec2u {
    return (rp.padded - 1u) / rp.stride;
}

var<workgroup> partial: array<f32, 256>;

// The mean radiance of the lattice of stride `stride`, the image's scale for agreement.
@compute @workgroup_size(256, 1, 1)
fn reference(@builtin(local_invocation_index) lid: u32) {
    let n = (rp.padded - 1u) / rp.stride + 1u;
    let count = n.x * n.y;
    var sum = 0.0;
    for (var i = lid; i < count; i += 256u) {
        let v = samples[index(vec2u(i % n.x, i / n.x) * rp.stride)].rgb;
        // A NaN or infinite ray refines its own cells; here it must not spoil the scale.
        let m = (v.r + v.g + v.b) / 3.0;
        if m == m && m < 3.0e38 {
            sum += m;
        }
    }
    partial[lid] = sum;
    workgroupBarrier();
    for (var half = 128u; half > 0u; half /= 2u) {
        if lid < half {
            partial[lid] += partial[lid + half];
        }
        workgroupBarrier();
    }
    if lid == 0u {
        atomicStore(&stats[1], bitcast<u32>(partial[0] / f32(count)));
    }
}

// The sample at lattice point p + (dx, dy)·stride, clamped to the padded image.
fn at(p: vec2u, dx: i32, dy: i32) -> vec4f {
    let s = i32(rp.stride);
    let q = clamp(vec2i(p) + vec2i(dx, dy) * s, vec2i(0), vec2i(rp.padded - 1u));
    return samples[index(vec2u(q))];
}

// The largest second difference, per channel, at lattice point p along x and y (one-sided, so
// a first difference, at the image's edge).
fn curvature(p: vec2u) -> vec4f {
    let c = 2.0 * samples[index(p)];
    return max(abs(at(p, -1, 0) + at(p, 1, 0) - c), abs(at(p, 0, -1) + at(p, 0, 1) - c));
}

// Whether the cell with top-left corner `p0` may be interpolated.
fn cell_agrees(p0: vec2u) -> bool {
    let s = rp.stride;
    let c00 = samples[index(p0)];
    let c10 = samples[index(p0 + vec2u(s, 0u))];
    let c01 = samples[index(p0 + vec2u(0u, s))];
    let c11 = samples[index(p0 + vec2u(s, s))];
    // Bilinear interpolation errs by about an eighth of the second difference across the cell;
    // a quarter of the corners' largest one keeps a margin.
    let bend = 0.25
        * max(max(curvature(p0), curvature(p0 + vec2u(s, 0u))), max(curvature(p0 + vec2u(0u, s)), curvature(p0 + vec2u(s, s))));
    let mean = dot(c00.rgb + c10.rgb + c01.rgb + c11.rgb, vec3f(1.0 / 12.0));
    let scale = bitcast<f32>(atomicLoad(&stats[1]));
    let limit = rp.tolerance * (mean + scale);
    // Written so that a NaN anywhere disagrees.
    if !(all(bend.rgb <= vec3f(limit)) && bend.a <= rp.tolerance) {
        return false;
    }
    let lo_f = vec2f(p0) - 1.0;
    let hi_f = vec2f(p0 + s) + 1.0;
    for (var e = 0u; e < rp.epipole_count; e++) {
        let q = rp.epipoles[e].xy;
        if all(q >= lo_f) && all(q <= hi_f) {
            return false;
        }
    }
    let seen = work[index(p0)];
    for (var y = 0u; y <= s; y++) {
        for (var x = 0u; x <= s; x++) {
            if work[index(p0 + vec2u(x, y))] != seen {
                return false;
            }
        }
    }
    return true;
}

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn cells_pass(@builtin(global_invocation_id) gid: vec3u) {
    let n = cells();
    if any(gid.xy >= n) {
        return;
    }
    work[flags_base() + gid.y * n.x + gid.x] = select(0u, 1u, cell_agrees(gid.xy * rp.stride));
}

fn flag(c: vec2u) -> bool {
    return work[flags_base() + c.y * cells().x + c.x] != 0u;
}

var<workgroup> group_count: atomic<u32>;
var<workgroup> group_base: u32;

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn points_pass(@builtin(global_invocation_id) gid: vec3u, @builtin(local_invocation_index) lid: u32) {
    let h = rp.stride / 2u;
    let n = (rp.padded - 1u) / h + 1u;
    let q = gid.xy;
    let odd = (q % 2u) == vec2u(1u);
    var queue = false;
    let p = q * h;
    if all(q < n) && any(odd) {
        let last = cells() - 1u;
        var value: vec4f;
        var agree: bool;
        if all(odd) {
            agree = flag(q / 2u);
            value = 0.25 * (samples[index(p - h)] + samples[index(p + h)]
                + samples[index(p + vec2u(h, 0u) - vec2u(0u, h))] + samples[index(p - vec2u(h, 0u) + vec2u(0u, h))]);
        } else if odd.x {
            // On a horizontal edge: the cells above and below it.
            let cx = q.x / 2u;
            let cy = q.y / 2u;
            agree = (cy == 0u || flag(vec2u(cx, cy - 1u))) && (cy > last.y || flag(vec2u(cx, cy)));
            value = 0.5 * (samples[index(p - vec2u(h, 0u))] + samples[index(p + vec2u(h, 0u))]);
        } else {
            let cx = q.x / 2u;
            let cy = q.y / 2u;
            agree = (cx == 0u || flag(vec2u(cx - 1u, cy))) && (cx > last.x || flag(vec2u(cx, cy)));
            value = 0.5 * (samples[index(p - vec2u(0u, h))] + samples[index(p + vec2u(0u, h))]);
        }
        if agree {
            samples[index(p)] = value;
        } else {
            queue = true;
        }
    }
    if lid == 0u {
        atomicStore(&group_count, 0u);
    }
    workgroupBarrier();
    var slot = 0u;
    if queue {
        slot = atomicAdd(&group_count, 1u);
    }
    workgroupBarrier();
    if lid == 0u {
        group_base = atomicAdd(&stats[0], atomicLoad(&group_count));
    }
    workgroupBarrier();
    if queue {
        work[pixels() + group_base + slot] = p.x | (p.y << 16u);
    }
}

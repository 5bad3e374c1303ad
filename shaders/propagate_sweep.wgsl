// Opacity propagation, upwind "short characteristics" sweep (physics.md §5, upwind variant).
//
// A cell X steps from its centre towards the light S until the ray crosses the plane `stride`
// layers back along its dominant axis a (the axis of largest |X − S| in cell units). At that
// point P the mean extinction T/distance is interpolated bilinearly from the four cells of
// that layer around P (constant in a homogeneous medium, so exact there), T(P) is that times
// |P − S|, and ∫σ_t over [P, X] is added by Simpson's rule on the trilinear EV. A stride above
// 1 means fewer interpolations along a ray, hence less numerical diffusion; with stride ≥ 3
// every cell P's interpolation touches is at least one Manhattan index step closer to the
// light's cell. Cells are processed as diamond-shaped wavefronts of equal Manhattan distance
// ("level") from the light's cell, one dispatch per level, so each cell is computed exactly
// once per light: O(N³) work and O(N) dispatches. Cells within `stride` cells of the light
// integrate straight to it. Upstream cells outside the grid are ghosts holding the base fog.

struct SweepStep {
    light_cell: vec3i,
    level: i32,
    lo: vec2i,
    size: vec2u,
    light: u32,
    stride: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> grid: GridParams;
@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> sweep: SweepStep;
@group(0) @binding(4) var<storage, read_write> opv: array<f32>;

// Mean extinction T/|c − S| along the ray from cell c to the light: smoother than T near the
// light, and constant in a homogeneous medium, so interpolating it is exact there.
fn mean_extinction_at(c: vec3i, s: vec3f, base: u32) -> f32 {
    if !in_grid(c) {
        return grid.base_extinction;
    }
    let d = length(grid.min + (vec3f(c) + 0.5) * grid.cell - s);
    if d < 1e-6 * grid.cell.x {
        return sigma_cell(c);
    }
    return opv[base + linear_index(vec3u(c))] / d;
}

fn solve(c: vec3i) {
    let s = lights[sweep.light].position;
    let base = sweep.light * cell_count();
    let x = grid.min + (vec3f(c) + 0.5) * grid.cell;
    let off = x - s;
    let mag = abs(off / grid.cell);
    let rel = c - sweep.light_cell;
    var a = 0u;
    if mag.y > mag[a] {
        a = 1u;
    }
    if mag.z > mag[a] {
        a = 2u;
    }
    let stride = f32(sweep.stride);
    var t: f32;
    if mag[a] < stride + 0.5 || abs(rel[a]) < i32(sweep.stride) {
        t = integrate_segment(x, s, 1.0);
    } else {
        // P: where the ray to the light crosses the layer `stride` cells back along a; the
        // mean extinction there is interpolated bilinearly within that layer.
        let p = x - off * (stride / mag[a]);
        let b = (a + 1u) % 3u;
        let d = (a + 2u) % 3u;
        let u = (p - grid.min) / grid.cell - 0.5;
        var c00 = c;
        c00[a] = c[a] - i32(sweep.stride) * sign(rel[a]);
        c00[b] = i32(floor(u[b]));
        c00[d] = i32(floor(u[d]));
        let wb = u[b] - floor(u[b]);
        let wd = u[d] - floor(u[d]);
        var eb = vec3i(0);
        var ed = vec3i(0);
        eb[b] = 1;
        ed[d] = 1;
        // Within the grid's outer half-cell, clamp to the edge rather than reading ghosts.
        let dims = vec3i(grid.dims);
        if c00[a] >= 0 && c00[a] < dims[a] {
            if c00[b] < 0 {
                c00[b] = 0;
                eb[b] = 0;
            } else if c00[b] >= dims[b] - 1 {
                c00[b] = dims[b] - 1;
                eb[b] = 0;
            }
            if c00[d] < 0 {
                c00[d] = 0;
                ed[d] = 0;
            } else if c00[d] >= dims[d] - 1 {
                c00[d] = dims[d] - 1;
                ed[d] = 0;
            }
        }
        let mean = mix(
            mix(mean_extinction_at(c00, s, base), mean_extinction_at(c00 + eb, s, base), wb),
            mix(mean_extinction_at(c00 + ed, s, base), mean_extinction_at(c00 + eb + ed, s, base), wb),
            wd,
        );
        t = mean * length(p - s) + integrate_segment(p, x, 1.0);
    }
    opv[base + linear_index(vec3u(c))] = t;
}

@compute @workgroup_size(8, 8, 1)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    if any(gid.xy >= sweep.size) {
        return;
    }
    let di = sweep.lo.x + i32(gid.x);
    let dj = sweep.lo.y + i32(gid.y);
    let rest = sweep.level - abs(di) - abs(dj);
    if rest < 0 {
        return;
    }
    let c0 = sweep.light_cell + vec3i(di, dj, rest);
    if in_grid(c0) {
        solve(c0);
    }
    if rest > 0 {
        let c1 = sweep.light_cell + vec3i(di, dj, -rest);
        if in_grid(c1) {
            solve(c1);
        }
    }
}

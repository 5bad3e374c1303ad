// Opacity propagation, upwind "short characteristics" sweep (physics.md §5, upwind variant).
//
// The optical depth from cell X to the light S splits at the point E where the segment leaves
// the grid box: T(X) = T_in(X) + T_fog(E, S), the base (height) fog in closed form beyond E,
// with T_in the integral of the grid's medium
// over [X, E] (E = S for a light inside the box). Along with T, each cell stores its mean
// in-box extinction m = T_in / |X − E| in a second buffer.
//
// X steps from its centre towards S to a plane P at least `stride` layers closer along its
// dominant axis a (the axis of largest |X − S| in cell units). The plane is a layer of the axis
// whose face the ray leaves the box of cell centres through, else of a: the cells around P
// then lie at the same distance from that face and see nearly the same length of box ahead,
// and P never lies in an outer half-cell. If that layer lies beyond the grid or the ray leaves
// the box before P (or S is that close), X integrates its whole in-box path directly: so the
// cells on the faces that see an outside light start the sweep. Otherwise m at P is
// interpolated from the cells of that layer around P, T_in(P) = m·|P − E|, and ∫σ_t over
// [P, X] is added exactly for the trilinear EV. m is constant in a homogeneous medium, so that
// case is exact. A larger stride means fewer interpolations along a ray, hence less numerical
// diffusion.
//
// Interpolation cannot resolve the shadow of a particle of a cell or two: there the optical
// depth varies over the stencil faster than any interpolant follows, and the error of each
// interpolation adds up along the ray. With `propagation.sweep_refine` (step.refine) every
// interpolation is error-controlled: the stencil's third differences across each axis (zero
// for the quadratic data Catmull-Rom reproduces; their size is the order of its error on data
// that is not smooth across a cell, where a sharper estimate with the interpolation weights
// missed errors of 3e-2) plus what the limiter clipped give the error of m at P; times the
// rest's length and the whole path's transmittance, that is the interpolation's error in the
// cell's transmittance. If it exceeds `step.tolerance`, X tries planes 2, 4, 8, … times as
// far (shorter rests; the segments already integrated are kept), and integrates the rest of
// its in-box path directly only once the next plane lies beyond the box: its value is then as
// exact as the `exact` scheme's, and the cells behind it interpolate from exact values. A
// rejected cell so integrates about as far as its first acceptable plane, not its whole path,
// whose length grows with the grid's extent (wide, flat grids have long paths). The worst error along a ray stays
// within a small multiple of the tolerance (tests/placements.rs). Whole in-box paths, and
// segments X–P whose bound on the error of splitting at axis a's planes only exceeds
// DETAIL_TOL, are split at every axis' cell-centre planes, which makes their integral exact
// for the trilinear medium. That bound is the largest detail of the bricks at the segment's
// ends and middle (occupancy.wgsl: how far σ_t departs from linear across a cell, in optical
// depth), times the square of the ray's lateral rate, times the transmittance of the rest: an
// error in a cell's optical depth reaches its own and the cells behind it only through that
// attenuation.
//
// Order: the cells P's interpolation reads lie at least stride − 2 Chebyshev shells (in cell
// units, around the light, or around a far light's anchor on the same line) closer to the
// light than X. Shells are processed in batches of stride − 3 (1 for stride 3, which
// interpolates bilinearly), one dispatch per batch covering all lights: each dispatch lists
// boxes (one per layer of each face of the batch's shells, spanning exactly that layer's part
// of the shell), and a thread solves its cell only if the cell's own batch and face are the
// box's, so each cell is solved exactly once per light (a layer next to a batch boundary can be
// listed in both batches).
//
// σ_t comes from `sigma_pair`, defined by sweep_sigma_filtered.wgsl (hardware trilinear
// filtering) or sweep_sigma_loads.wgsl (eight texel loads) depending on the adapter, and the
// segment integrals from integrate_exact.wgsl.

struct SweepStep {
    first_box: u32,
    box_count: u32,
    // Threads per row of workgroups (the dispatch is 2D when one row is not enough).
    row: u32,
    stride: u32,
    // Index of this dispatch's first thread among its batch's (box `first` counts from there).
    offset: u32,
    // 1: interpolations are error-controlled (see the top of this file).
    refine: u32,
    // Their largest accepted error in transmittance.
    tolerance: f32,
    _pad: u32,
}

struct SweepBox {
    lo: vec3i,
    light: u32,
    size: vec3u,
    // Index, within the batch, of this box's first thread.
    first: u32,
    // Where Chebyshev shells are measured from, in cell-centre coordinates.
    anchor: vec3f,
    level0: f32,
    width: f32,
    // 2·axis + (1 if on the negative side of the anchor).
    face: u32,
    batch: u32,
    _pad: u32,
}

@group(0) @binding(1) var ev: texture_3d<f32>;

fn ev_texel(c: vec3i) -> f32 {
    return textureLoad(ev, c, 0).r;
}
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> step: SweepStep;
// bindings 4, 5: `opv` and `mean_in`, declared with their helpers by src/gpu/opv_store.rs.
@group(0) @binding(6) var<storage, read> boxes: array<SweepBox>;
// Each brick's largest σ_t, then its detail (shaders/occupancy.wgsl).
@group(0) @binding(8) var<storage, read> brick_max: array<f32>;

fn load_mean(light: u32, c: vec3i) -> f32 {
    return mean_in_load(light, vec3u(c));
}

fn store(light: u32, c: vec3i, t: f32, mean: f32) {
    opv_store(light, vec3u(c), t);
    mean_in_store(light, vec3u(c), mean);
}

// The detail of the brick holding cell c (clamped to the grid).
fn detail_cell(cell: vec3i) -> f32 {
    let c = clamp(cell, vec3i(0), vec3i(grid.dims) - 1);
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    let b = vec3u(c) / BRICK;
    return brick_max[b.x + bdims.x * (b.y + bdims.y * b.z) + bdims.x * bdims.y * bdims.z];
}

struct Exit {
    // Distance from the start to where the ray leaves the box, at most the light's distance.
    t: f32,
    // The axis of the face it leaves through; 3 if it reaches the light first.
    axis: u32,
}

fn exit_box(x: vec3f, dir: vec3f, len: f32) -> Exit {
    return exit_from(x, dir, len, grid.min, grid.max);
}

// Where the ray from x (inside [lo, hi]) leaves the box [lo, hi].
fn exit_from(x: vec3f, dir: vec3f, len: f32, lo: vec3f, hi: vec3f) -> Exit {
    var e = Exit(len, 3u);
    for (var i = 0u; i < 3u; i++) {
        var t = len;
        if dir[i] > 0.0 {
            t = (hi[i] - x[i]) / dir[i];
        } else if dir[i] < 0.0 {
            t = (lo[i] - x[i]) / dir[i];
        }
        if t < e.t {
            e = Exit(t, i);
        }
    }
    e.t = max(e.t, 0.0);
    return e;
}

fn catmull_rom(t: f32) -> vec4f {
    let t2 = t * t;
    let t3 = t2 * t;
    return 0.5 * vec4f(-t3 + 2.0 * t2 - t, 3.0 * t3 - 5.0 * t2 + 2.0, -3.0 * t3 + 4.0 * t2 + t, t3 - t2);
}

// Mean in-box extinction at P (cell-centre coordinates u) in layer `layer` of axis a:
// Catmull-Rom over the 4×4 cells around P (less numerical diffusion than bilinear), limited to
// the range of the 2×2 nearest so that it cannot overshoot. A stencil position beyond the grid
// stands for the linear extrapolation of the two edge cells (its weight moves onto them), not
// for a copy of the edge cell: a copy flattens the slope in the last interval, an error of
// first order in the cell size that the many interpolations along a ray near a face
// accumulate. Within the outer half-cell P takes the edge cells' values. Returns that value
// and an estimate of its error: the largest third differences across each axis (the ghost
// positions holding their extrapolations) plus what the limiter clipped; for the bilinear
// stencil of stride 3, the 2×2 cells' spread.
fn layer_mean(light: u32, a: u32, layer: i32, u: vec3f) -> vec2f {
    let b = (a + 1u) % 3u;
    let d = (a + 2u) % 3u;
    let nb = i32(grid.dims[b]);
    let nd = i32(grid.dims[d]);
    let ub = clamp(u[b], 0.0, f32(nb - 1));
    let ud = clamp(u[d], 0.0, f32(nd - 1));
    let fb = i32(floor(ub));
    let fd = i32(floor(ud));
    // Stride 3 leaves no room for the wider stencil in the ordering: bilinear there, and the
    // outer cells (not yet solved) are not read.
    let cubic = step.stride >= 4u;
    var wb = vec4f(0.0, 1.0 - (ub - f32(fb)), ub - f32(fb), 0.0);
    var wd = vec4f(0.0, 1.0 - (ud - f32(fd)), ud - f32(fd), 0.0);
    if cubic {
        wb = fold_ghosts(catmull_rom(ub - f32(fb)), fb, nb);
        wd = fold_ghosts(catmull_rom(ud - f32(fd)), fd, nd);
    }
    // The stencil's four rows along b, written out so that every index is constant.
    let ea = unit(a);
    let eb = unit(b);
    let ed = unit(d);
    let cell = ea * layer;
    let m1 = stencil_row(light, cell, eb, ed, fb, fd, nb, nd, cubic);
    let m2 = stencil_row(light, cell, eb, ed, fb, fd + 1, nb, nd, cubic);
    let lo = min(min(m1.y, m1.z), min(m2.y, m2.z));
    let hi = max(max(m1.y, m1.z), max(m2.y, m2.z));
    if !cubic {
        let sum = wd.y * dot(wb, m1) + wd.z * dot(wb, m2);
        return vec2f(clamp(sum, lo, hi), hi - lo);
    }
    let m0 = stencil_row(light, cell, eb, ed, fb, fd - 1, nb, nd, cubic);
    let m3 = stencil_row(light, cell, eb, ed, fb, fd + 2, nb, nd, cubic);
    let sum = dot(wd, vec4f(dot(wb, m0), dot(wb, m1), dot(wb, m2), dot(wb, m3)));
    let limited = clamp(sum, lo, hi);
    if step.refine == 0u {
        return vec2f(limited, 0.0);
    }
    // Third differences along b of each row and along d of each column, from coefficients
    // that read no ghost position; the ghost rows and columns then hold the linear
    // extrapolation of the edge ones.
    let cb = third_difference(fb, nb);
    let cd = third_difference(fd, nd);
    let rows = extrapolate_ghosts(vec4f(dot(cb, m0), dot(cb, m1), dot(cb, m2), dot(cb, m3)), fd, nd);
    let cols = extrapolate_ghosts(cd.x * m0 + cd.y * m1 + cd.z * m2 + cd.w * m3, fb, nb);
    let e_b = max(max(abs(rows.x), abs(rows.y)), max(abs(rows.z), abs(rows.w)));
    let e_d = max(max(abs(cols.x), abs(cols.y)), max(abs(cols.z), abs(cols.w)));
    return vec2f(limited, e_b + e_d + abs(sum - limited));
}

// Mean in-box extinction of the stencil cells fb − 1 … fb + 2 along b (unit vector eb) in
// row `row` along d (unit vector ed), both clamped to the grid, of the layer holding `layer`;
// without `cubic` only the middle two.
fn stencil_row(light: u32, layer: vec3i, eb: vec3i, ed: vec3i, fb: i32, row: i32, nb: i32, nd: i32, cubic: bool) -> vec4f {
    let base = layer + ed * clamp(row, 0, nd - 1);
    var m = vec4f(0.0);
    m.y = load_mean(light, base + eb * clamp(fb, 0, nb - 1));
    m.z = load_mean(light, base + eb * clamp(fb + 1, 0, nb - 1));
    if cubic {
        m.x = load_mean(light, base + eb * clamp(fb - 1, 0, nb - 1));
        m.w = load_mean(light, base + eb * clamp(fb + 2, 0, nb - 1));
    }
    return m;
}

// The unit vector along axis i.
fn unit(i: u32) -> vec3i {
    return vec3i(vec3u(i) == vec3u(0u, 1u, 2u));
}

// Coefficients of the third difference v0 − 3v1 + 3v2 − v3 over the stencil cells f − 1 …
// f + 2 of an axis of n cells, with a position beyond the axis standing for the linear
// extrapolation of the two edge cells.
fn third_difference(f: i32, n: i32) -> vec4f {
    var c = vec4f(1.0, -3.0, 3.0, -1.0);
    if n >= 2 && f == 0 {
        c = vec4f(0.0, c.y + 2.0 * c.x, c.z - c.x, c.w);
    }
    if n >= 2 && f >= n - 2 {
        c = vec4f(c.x, c.y - c.w, c.z + 2.0 * c.w, 0.0);
    }
    return c;
}

// Values at the stencil positions f − 1 … f + 2 of an axis of n cells, those beyond the axis
// replaced by the linear extrapolation of the two edge cells.
fn extrapolate_ghosts(v: vec4f, f: i32, n: i32) -> vec4f {
    var w = v;
    if n >= 2 && f == 0 {
        w.x = 2.0 * w.y - w.z;
    }
    if n >= 2 && f >= n - 2 {
        w.w = 2.0 * w.z - w.y;
    }
    return w;
}

// Weights `w` of the stencil cells f − 1 … f + 2 along an axis of n cells, with the weight of
// a position beyond the axis moved onto the two edge cells it extrapolates linearly from.
fn fold_ghosts(w: vec4f, f: i32, n: i32) -> vec4f {
    var v = w;
    if n >= 2 && f == 0 {
        v = vec4f(0.0, v.y + 2.0 * v.x, v.z - v.x, v.w);
    }
    if n >= 2 && f == n - 2 {
        v = vec4f(v.x, v.y - v.w, v.z + 2.0 * v.w, 0.0);
    }
    return v;
}

// The bound (detail × lateral rate² × transmittance, see the top of this file) above which a
// segment X–P is integrated exactly with refine. On a ray along a cell's body diagonal, in
// clear air, it is the detail itself, where the plain integration of a segment measured errors beyond 1e-3 on the
// placements test's scenes.
const DETAIL_TOL: f32 = 2.5e-4;
// With refine, the planes tried, at 1, 2, 4, … times the stride: more than any path needs
// (each stays below the box's exit, and i32 holds the last plane's offset).
const PLANES: u32 = 24u;

struct FlatRest {
    // The rest's optical depth and its error, as `layer_mean(…) · length`.
    m: vec2f,
    // P' in cell units, where the layer is read.
    up: vec3f,
    // False where the construction does not hold (the rest then is not interpolated).
    ok: bool,
}

// The in-box optical depth from P = x + dir·at to the light S, for a grid one layer deep along
// f, which X's ray (in-box length `inside`) leaves through. σ_t is constant along f, so any
// segment's integral depends only on its projection across f. P' is P moved along f back to
// the cell-centre plane: the ray from P' to S (direction d', in-box length L') projects onto
// the same line from the same point as P's, and reaches further along it. Its optical depth,
// m(P')·L' from the layer of a (the cells around P' lie as many shells closer to the light as
// those around P), minus the part beyond the reach of P's projection (P' + d'·t for t from
// t* to L', where t* = |P's rest|·|dir⊥| / |d'⊥|), times |d'⊥| / |dir⊥|, is P's rest.
fn flat_rest(light: u32, x: vec3f, dir: vec3f, at: f32, inside: f32, f: u32, e: u32, plane: i32, s: vec3f) -> FlatRest {
    var keep = vec3f(1.0);
    keep[f] = 0.0;
    var q = x + dir * at;
    q[f] = x[f];
    let to = s - q;
    let lq = length(to);
    var out = FlatRest(vec2f(0.0), (q - grid.min) / grid.cell - 0.5, false);
    if lq <= 0.0 {
        return out;
    }
    let dq = to / lq;
    let eq = exit_box(q, dq, lq);
    let across = length(dir * keep);
    let across_q = length(dq * keep);
    if eq.axis != f || across <= 0.0 || across_q <= 0.0 {
        return out;
    }
    let t_star = (inside - at) * across / across_q;
    if t_star > eq.t {
        return out;
    }
    let beyond = integrate_pieces(q + dq * eq.t, q + dq * t_star, true);
    let mean = layer_mean(light, e, plane, out.up);
    let scale = across_q / across;
    out.m = vec2f(mean.x * eq.t - beyond, mean.y * eq.t) * scale;
    out.ok = true;
    return out;
}

fn solve(c: vec3i, light: u32) {
    let s = lights[light].position;
    let x = grid.min + (vec3f(c) + 0.5) * grid.cell;
    let v = s - x;
    let len = length(v);
    let h = min(grid.cell.x, min(grid.cell.y, grid.cell.z));
    if len < 1e-6 * h {
        store(light, c, 0.0, sigma_cell(c));
        return;
    }
    let dir = v / len;
    let exit = exit_box(x, dir, len);
    let inside = exit.t;
    let mag = abs(v / grid.cell);
    let a = largest_axis(mag);
    let stride = f32(step.stride);
    // The interpolation plane is a layer of axis e (see the top of this file), the first at
    // least `stride` layers closer along a. Were e the axis of the face of the box itself, a
    // ray grazing another face would be interpolated across it, from neighbours whose paths
    // leave the box at far different points.
    let half = 0.5 * grid.cell;
    let centres = exit_from(x, dir, len, grid.min + half, grid.max - half);
    var e = a;
    var layers = stride;
    // A grid one layer deep along the axis f the ray leaves through: σ_t does not vary along
    // f, so P takes its rest from the cell-centre plane (see `flat_rest`), on a layer of a.
    let f = centres.axis;
    let flat = f < 3u && f != a && grid.dims[min(f, 2u)] == 1u && exit.axis == f;
    if f < 3u && f != a && !flat {
        e = f;
        layers = max(ceil(stride * mag[e] / mag[a]), 1.0);
    }
    // Where the ray would reach the plane of another face's outermost cells less than two
    // cells (along that face's axis) after leaving through e's, the stencil around P holds
    // cells whose rays leave through that face instead: their in-box lengths and means meet
    // at a kink there, which interpolation smears. Such cells integrate directly.
    var kink = false;
    if centres.axis < 3u {
        for (var f = 0u; f < 3u; f++) {
            if f != centres.axis && dir[f] != 0.0 {
                let face = select(grid.min[f] + half[f], grid.max[f] - half[f], dir[f] > 0.0);
                let t_f = (face - x[f]) / dir[f];
                if t_f < len && (t_f - centres.t) * abs(dir[f]) < 2.0 * grid.cell[f] {
                    kink = true;
                }
            }
        }
    }
    // Each round integrates the path from where the last one ended either to the next plane
    // P, then adds the rest interpolated there if its error is within the tolerance, or to
    // the box's exit. One integration call in one loop, so that threads taking different
    // branches share it, and a rejected plane's segment is part of the next one's.
    let usable = mag[a] >= stride + 0.5 && !kink;
    let tries = select(1u, PLANES, step.refine != 0u);
    var near = 0.0;
    var near_cell = c;
    var t_in = 0.0;
    // Splitting a segment only at axis a's planes leaves kinks where it crosses the other
    // axes' planes: their count and their slope jumps each grow with the ray's lateral rate
    // (cells along b per cell along a), so the error grows with its square; 1 on a diagonal.
    let ma = mag[a] * mag[a];
    let lateral = 0.5 * (dot(mag, mag) - ma) / ma;
    for (var r = 0u; ; r++) {
        var far = inside;
        var m = vec2f(0.0);
        var up = vec3f(0.0);
        let n = layers * f32(1u << r);
        let at = len * n / mag[e];
        let plane = c[e] + i32(n) * i32(sign(v[e]));
        var interpolate = usable && r < tries && at < inside && plane >= 0 && plane < i32(grid.dims[e]);
        if interpolate && flat {
            let rest = flat_rest(light, x, dir, at, inside, f, e, plane, s);
            interpolate = rest.ok;
            if rest.ok {
                far = at;
                up = rest.up;
                m = rest.m;
            }
        } else if interpolate {
            far = at;
            up = (x + dir * at - grid.min) / grid.cell - 0.5;
            m = layer_mean(light, e, plane, up) * (inside - at);
        }
        var exact = !interpolate;
        if step.refine != 0u && interpolate {
            // The bricks at the segment's ends and middle. Its error in the cell's
            // transmittance is at most that in optical depth times exp(−rest).
            let far_cell = vec3i(floor(up + 0.5));
            let detail = max(max(detail_cell(near_cell), detail_cell(far_cell)), detail_cell((near_cell + far_cell) / 2));
            near_cell = far_cell;
            exact = detail * lateral * exp(-m.x) > DETAIL_TOL;
        }
        t_in += integrate_pieces(x + dir * far, x + dir * near, exact);
        near = far;
        if !interpolate {
            break;
        }
        // The interpolation's error in the cell's transmittance: in mean extinction, times
        // the rest's length, times the transmittance of the whole path.
        if step.refine == 0u || m.y * exp(-(m.x + t_in)) <= step.tolerance {
            t_in += m.x;
            break;
        }
    }
    store(light, c, t_in + base_fog_depth(x + dir * inside, dir, len - inside), select(sigma_cell(c), t_in / inside, inside > 1e-6 * h));
}

// Threads per workgroup: SWEEP_WORKGROUP (src/gpu/layout.rs). Each thread solves
// SWEEP_CELLS cells of its box (`const SWEEP_CELLS`, prepended by src/gpu/shaders.rs:
// several on a CPU adapter, which pays a fixed cost per invocation). Consecutive threads take
// consecutive cells, SWEEP_CHUNK threads at a time, so that neighbouring lanes follow nearby
// paths and branch alike.
const SWEEP_CHUNK: u32 = 32u;

@compute @workgroup_size(SWEEP_WORKGROUP, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let t = gid.x + gid.y * step.row + step.offset;
    // The last box starting at or before thread t.
    var lo = step.first_box;
    var hi = step.first_box + step.box_count;
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if boxes[mid].first <= t {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let bx = boxes[lo];
    let count = bx.size.x * bx.size.y * bx.size.z;
    let threads = (count + SWEEP_CELLS - 1u) / SWEEP_CELLS;
    if t < bx.first || t - bx.first >= threads {
        return;
    }
    let lt = t - bx.first;
    let chunk = lt / SWEEP_CHUNK;
    let lanes = min(SWEEP_CHUNK, threads - chunk * SWEEP_CHUNK);
    for (var k = 0u; k < SWEEP_CELLS; k++) {
        let local = chunk * SWEEP_CHUNK * SWEEP_CELLS + k * lanes + lt % SWEEP_CHUNK;
        if local >= count {
            return;
        }
        let c = bx.lo + vec3i(vec3u(local % bx.size.x, (local / bx.size.x) % bx.size.y, local / (bx.size.x * bx.size.y)));
        let r = vec3f(c) - bx.anchor;
        let ar = abs(r);
        let a = largest_axis(ar);
        let face = 2u * a + select(0u, 1u, r[a] < 0.0);
        let batch = max(i32(floor((ar[a] - bx.level0) / bx.width)), 0);
        if in_grid(c) && face == bx.face && batch == i32(bx.batch) {
            solve(c, bx.light);
        }
    }
}

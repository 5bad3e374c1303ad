// Extinction lookups shared by the propagation schemes. Expects `grid` and `ev` bindings.

fn in_grid(c: vec3i) -> bool {
    return all(c >= vec3i(0)) && all(c < vec3i(grid.dims));
}

// σ_t at a cell; outside the grid only the base fog exists.
fn sigma_cell(c: vec3i) -> f32 {
    if !in_grid(c) {
        return grid.base_extinction;
    }
    return textureLoad(ev, c, 0).r;
}

// Trilinear σ_t at a world position; base fog outside the grid box.
fn sigma_at_point(x: vec3f) -> f32 {
    if any(x < grid.min) || any(x > grid.max) {
        return grid.base_extinction;
    }
    let hi = vec3f(grid.dims - 1u);
    let u = clamp((x - grid.min) / grid.cell - 0.5, vec3f(0.0), hi);
    let i0 = vec3i(floor(u));
    let f = u - vec3f(i0);
    let i1 = min(i0 + 1, vec3i(grid.dims) - 1);
    let c000 = textureLoad(ev, i0, 0).r;
    let c100 = textureLoad(ev, vec3i(i1.x, i0.y, i0.z), 0).r;
    let c010 = textureLoad(ev, vec3i(i0.x, i1.y, i0.z), 0).r;
    let c110 = textureLoad(ev, vec3i(i1.x, i1.y, i0.z), 0).r;
    let c001 = textureLoad(ev, vec3i(i0.x, i0.y, i1.z), 0).r;
    let c101 = textureLoad(ev, vec3i(i1.x, i0.y, i1.z), 0).r;
    let c011 = textureLoad(ev, vec3i(i0.x, i1.y, i1.z), 0).r;
    let c111 = textureLoad(ev, i1, 0).r;
    return mix(
        mix(mix(c000, c100, f.x), mix(c010, c110, f.x), f.y),
        mix(mix(c001, c101, f.x), mix(c011, c111, f.x), f.y),
        f.z,
    );
}

// ∫σ_t over the segment [a, b] by composite Simpson with about `per_cell` intervals per cell
// edge travelled (an even count, at least two).
fn integrate_segment(a: vec3f, b: vec3f, per_cell: f32) -> f32 {
    let len = length(b - a);
    let h = min(grid.cell.x, min(grid.cell.y, grid.cell.z));
    let n = 2u * max(1u, u32(ceil(0.5 * per_cell * len / h)));
    let dt = len / f32(n);
    let dir = (b - a) / max(len, 1e-30);
    var acc = sigma_at_point(a) + sigma_at_point(b);
    for (var k = 1u; k < n; k++) {
        acc += select(2.0, 4.0, (k & 1u) == 1u) * sigma_at_point(a + dir * (f32(k) * dt));
    }
    return acc * dt / 3.0;
}

// σ_t at cell-centre coordinates p and q (cell (i, j, k) at (i, j, k)), both within the
// trilinear patch around m: one set of eight loads for the two values.
fn sigma_pair(m: vec3f, p: vec3f, q: vec3f) -> vec2f {
    let hi = vec3f(grid.dims - 1u);
    let i0 = vec3i(min(floor(clamp(m, vec3f(0.0), hi)), max(hi - 1.0, vec3f(0.0))));
    let i1 = min(i0 + 1, vec3i(grid.dims) - 1);
    let c000 = textureLoad(ev, i0, 0).r;
    let c100 = textureLoad(ev, vec3i(i1.x, i0.y, i0.z), 0).r;
    let c010 = textureLoad(ev, vec3i(i0.x, i1.y, i0.z), 0).r;
    let c110 = textureLoad(ev, vec3i(i1.x, i1.y, i0.z), 0).r;
    let c001 = textureLoad(ev, vec3i(i0.x, i0.y, i1.z), 0).r;
    let c101 = textureLoad(ev, vec3i(i1.x, i0.y, i1.z), 0).r;
    let c011 = textureLoad(ev, vec3i(i0.x, i1.y, i1.z), 0).r;
    let c111 = textureLoad(ev, i1, 0).r;
    let fp = clamp(clamp(p, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    let fq = clamp(clamp(q, vec3f(0.0), hi) - vec3f(i0), vec3f(0.0), vec3f(1.0));
    let sp = mix(
        mix(mix(c000, c100, fp.x), mix(c010, c110, fp.x), fp.y),
        mix(mix(c001, c101, fp.x), mix(c011, c111, fp.x), fp.y),
        fp.z,
    );
    let sq = mix(
        mix(mix(c000, c100, fq.x), mix(c010, c110, fq.x), fq.y),
        mix(mix(c001, c101, fq.x), mix(c011, c111, fq.x), fq.y),
        fq.z,
    );
    return vec2f(sp, sq);
}

// ∫σ_t over the segment [a, b], both in the grid box, exact for the trilinear medium up to
// rounding: σ_t is a cubic between the points where the segment crosses cell-centre planes,
// and 2-point Gauss–Legendre integrates each such piece exactly.
fn integrate_pieces(a: vec3f, b: vec3f) -> f32 {
    let len = length(b - a);
    let ua = (a - grid.min) / grid.cell - 0.5;
    let du = (b - a) / grid.cell;
    var next = vec3f(2.0);
    var step = vec3f(0.0);
    for (var i = 0u; i < 3u; i++) {
        if du[i] > 1e-6 {
            next[i] = (floor(ua[i]) + 1.0 - ua[i]) / du[i];
            step[i] = 1.0 / du[i];
        } else if du[i] < -1e-6 {
            next[i] = (ceil(ua[i]) - 1.0 - ua[i]) / du[i];
            step[i] = -1.0 / du[i];
        }
    }
    let g0 = 0.21132487;
    let g1 = 0.78867513;
    var acc = 0.0;
    var t0 = 0.0;
    let pieces = u32(abs(du.x) + abs(du.y) + abs(du.z)) + 4u;
    for (var n = 0u; n < pieces; n++) {
        let t1 = min(min(next.x, next.y), min(next.z, 1.0));
        let h = t1 - t0;
        if h > 0.0 {
            let s = sigma_pair(ua + du * (t0 + 0.5 * h), ua + du * (t0 + g0 * h), ua + du * (t0 + g1 * h));
            acc += 0.5 * h * (s.x + s.y);
        }
        if t1 >= 1.0 {
            break;
        }
        t0 = t1;
        next = select(next, next + step, next <= vec3f(t1));
    }
    return acc * len;
}

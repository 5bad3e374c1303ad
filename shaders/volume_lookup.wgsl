// Extinction lookups shared by the propagation schemes. Expects the `ev` binding and
// ev_trilinear.wgsl.

fn in_grid(c: vec3i) -> bool {
    return all(c >= vec3i(0)) && all(c < vec3i(grid.dims));
}

// σ_t at a cell; outside the grid only the base fog exists.
fn sigma_cell(c: vec3i) -> f32 {
    if !in_grid(c) {
        return grid.base_extinction;
    }
    return ev_texel(c);
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
    return lerp3(ev_corners(i0, i1), f);
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

// Occupancy: the largest σ_t each 8³ brick's samples can see. Trilinear lookups inside a brick
// touch one cell beyond it on every side, so the maximum is taken over the brick dilated by
// one cell; a ray may then skip a brick whose maximum is zero without changing the result.
//
// The second half of the buffer holds each brick's detail: the largest second difference of
// σ_t along x over the same cells, times the cell size. It is the optical depth by which the
// medium departs from linear across one cell, large only for features of a few cells (small
// particles, noise, an imported volume's fine structure): the refined sweep
// (propagate_sweep.wgsl) checks its interpolations only in the shadows of such bricks.

@group(0) @binding(0) var<uniform> grid: GridParams;
@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read_write> brick_max: array<f32>;


@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) b: vec3u) {
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    if any(b >= bdims) {
        return;
    }
    let lo = vec3i(b * BRICK) - 1;
    let hi = min(vec3i((b + 1u) * BRICK), vec3i(grid.dims) - 1);
    var m = 0.0;
    var detail = 0.0;
    for (var z = max(lo.z, 0); z <= hi.z; z++) {
        for (var y = max(lo.y, 0); y <= hi.y; y++) {
            var before = 0.0;
            var here = 0.0;
            for (var x = max(lo.x, 0); x <= hi.x; x++) {
                let v = textureLoad(ev, vec3i(x, y, z), 0).r;
                m = max(m, v);
                if x >= max(lo.x, 0) + 2 {
                    detail = max(detail, abs(here - 0.5 * (before + v)));
                }
                before = here;
                here = v;
            }
        }
    }
    let i = b.x + bdims.x * (b.y + bdims.y * b.z);
    brick_max[i] = m;
    brick_max[i + bdims.x * bdims.y * bdims.z] = detail * grid.cell.x;
}

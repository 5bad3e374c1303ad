// Occupancy: the largest σ_t each 8³ brick's samples can see. Trilinear lookups inside a brick
// touch one cell beyond it on every side, so the maximum is taken over the brick dilated by
// one cell; a ray may then skip a brick whose maximum is zero without changing the result.
//
// The second half of the buffer holds each brick's detail: the largest second difference of
// σ_t along any axis over the brick's cells, times the cell size along that axis (on
// anisotropic grids a particle can be resolved along one axis and not another). It is the
// optical depth by which the medium departs from linear across one cell, large only for
// features of a few cells (small particles, noise, an imported volume's fine structure): the
// refined sweep (propagate_sweep.wgsl) integrates exactly the segments that cross such bricks
// where its error bound asks for it.

@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read_write> brick_max: array<f32>;

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn main(@builtin(global_invocation_id) b: vec3u) {
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    if any(b >= bdims) {
        return;
    }
    let lo = vec3i(b * BRICK) - 1;
    let hi = min(vec3i((b + 1u) * BRICK), vec3i(grid.dims) - 1);
    var m = 0.0;
    for (var z = max(lo.z, 0); z <= hi.z; z++) {
        for (var y = max(lo.y, 0); y <= hi.y; y++) {
            for (var x = max(lo.x, 0); x <= hi.x; x++) {
                m = max(m, textureLoad(ev, vec3i(x, y, z), 0).r);
            }
        }
    }
    let top = vec3i(grid.dims) - 1;
    let end = min(vec3i((b + 1u) * BRICK), vec3i(grid.dims));
    var detail = 0.0;
    for (var z = i32(b.z * BRICK); z < end.z; z++) {
        for (var y = i32(b.y * BRICK); y < end.y; y++) {
            for (var x = i32(b.x * BRICK); x < end.x; x++) {
                let c = vec3i(x, y, z);
                let v = textureLoad(ev, c, 0).r;
                for (var a = 0u; a < 3u; a++) {
                    var e = vec3i(0);
                    e[a] = 1;
                    let below = textureLoad(ev, max(c - e, vec3i(0)), 0).r;
                    let above = textureLoad(ev, min(c + e, top), 0).r;
                    detail = max(detail, abs(v - 0.5 * (below + above)) * grid.cell[a]);
                }
            }
        }
    }
    let i = b.x + bdims.x * (b.y + bdims.y * b.z);
    brick_max[i] = m;
    brick_max[i + bdims.x * bdims.y * bdims.z] = detail;
}

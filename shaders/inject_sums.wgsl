// Injection from particle sums the host computed (src/gpu/host_sums.rs): the path taken on
// software adapters, where the host's own loops over each particle's cells are many times
// faster than this adapter's per-cell list walk. `sums` holds, per dispatched brick that a
// particle reaches, its BRICK_CELLS cells' plain particle sums, then their noisy ones, x fastest then
// y then z; `slots` gives each dispatched brick's place there (NONE: no particle, all zero).

const BRICK_CELLS: u32 = BRICK * BRICK * BRICK;

@group(0) @binding(1) var<storage, read> sums: array<f32>;
@group(0) @binding(2) var<storage, read> slots: array<u32>;

@compute @workgroup_size(BRICK, BRICK, 1)
fn main(@builtin(workgroup_id) wg: vec3u, @builtin(local_invocation_id) lid: vec3u) {
    let base = dirty_brick(wg.x) * BRICK + vec3u(lid.xy, 0u);
    if any(base.xy >= grid.dims.xy) {
        return;
    }
    let slot = slots[wg.x];
    var sum: array<vec2f, BRICK>;
    if slot != 0xffffffffu {
        let at = slot * 2u * BRICK_CELLS + lid.x + BRICK * lid.y;
        for (var k = 0u; k < BRICK; k++) {
            sum[k] = vec2f(sums[at + BRICK * BRICK * k], sums[at + BRICK_CELLS + BRICK * BRICK * k]);
        }
    }
    for (var k = 0u; k < BRICK; k++) {
        let id = base + vec3u(0u, 0u, k);
        if id.z >= grid.dims.z {
            break;
        }
        write_cell(id, sum[k]);
    }
}

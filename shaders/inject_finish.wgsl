// What both injection paths share: the bindings they write through and the last step of a
// cell, which adds the base fog, the imported layer and the particle sums (the noisy part
// modulated by the medium's noise) and stores the EV. The particle sums come from inject.wgsl
// (evaluated here from binned lists) or inject_sums.wgsl (computed by the host).

@group(0) @binding(4) var ev: texture_storage_3d<r32float, write>;
@group(0) @binding(5) var<storage, read> dirty_bricks: array<u32>;
// An imported density layer (e.g. from a VDB file) under the particles, when has_base_layer.
@group(0) @binding(6) var<storage, read> base_layer: array<f32>;

// Coordinates of the brick workgroup `wg` injects.
fn dirty_brick(wg: u32) -> vec3u {
    let brick = dirty_bricks[wg];
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    return vec3u(brick % bdims.x, (brick / bdims.x) % bdims.y, brick / (bdims.x * bdims.y));
}

// Stores cell `id` given its (plain, noisy) particle sum.
fn write_cell(id: vec3u, sum: vec2f) {
    let x = cell_center(id);
    var layer = 0.0;
    if grid.has_base_layer != 0u {
        layer = base_layer[linear_index(id)];
    }
    textureStore(ev, id, vec4f(base_fog_at(x.y) + layer + particle_sum(sum, x), 0.0, 0.0, 0.0));
}

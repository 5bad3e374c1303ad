// One axis-aligned slice of the EV or of one light's OPV, gathered into a small buffer so that
// a view reads back a plane instead of the whole volume. The plane's axes are the other two
// grid axes in increasing order, the first one fastest.

struct SliceParams {
    axis: u32,
    index: u32,
    light: u32,
    // 0: the EV; 1: the OPV of `light`.
    source: u32,
}

@group(0) @binding(1) var ev: texture_3d<f32>;
// binding 2: `opv`, declared with its helper opv_load by src/gpu/opv_store.rs.
@group(0) @binding(3) var<uniform> slice: SliceParams;
@group(0) @binding(4) var<storage, read_write> plane: array<f32>;

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn main(@builtin(global_invocation_id) id: vec3u) {
    var c: vec3u;
    var dims: vec2u;
    if slice.axis == 0u {
        c = vec3u(slice.index, id.x, id.y);
        dims = grid.dims.yz;
    } else if slice.axis == 1u {
        c = vec3u(id.x, slice.index, id.y);
        dims = grid.dims.xz;
    } else {
        c = vec3u(id.x, id.y, slice.index);
        dims = grid.dims.xy;
    }
    if any(id.xy >= dims) {
        return;
    }
    var v = 0.0;
    if slice.source == 0u {
        v = textureLoad(ev, vec3i(c), 0).r;
    } else {
        v = opv_load(slice.light, c);
    }
    plane[id.x + id.y * dims.x] = v;
}

// Opacity propagation by brute force: every cell marches straight to the light, up to where
// the path leaves the grid, through the trilinear EV with steps of a quarter of the smallest
// cell edge (Simpson's rule per pair of steps), then adds the base fog beyond. O(N) work per
// cell, O(N⁴) per light: a reference-quality scheme for measurement.
//
// A sun (directional light) is marched along its reversed direction of travel to where the
// path leaves the box, integrating the trilinear medium exactly between the crossings of
// cell-centre planes (integrate_pieces), and adds the base fog beyond in closed form: the
// same G + B the directional sweep stores.

struct ExactParams {
    light: u32,
    steps_per_cell: u32,
    z_offset: u32,
    _pad: u32,
}

// Read-only storage: on llvmpipe its loads cost less than a sampled texture's.
@group(0) @binding(1) var ev: texture_storage_3d<r32float, read>;

fn ev_texel(c: vec3i) -> f32 {
    return textureLoad(ev, c).r;
}
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> exact: ExactParams;
// binding 4: `opv`, declared with its helpers by src/gpu/opv_store.rs.

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let id = gid + vec3u(0u, 0u, exact.z_offset);
    if any(id >= grid.dims) {
        return;
    }
    let x = cell_center(id);
    let light = lights[exact.light];
    if light.kind == LIGHT_DIRECTIONAL {
        let towards = -light.direction;
        let beyond = sun_beyond(x, towards);
        if beyond >= OPAQUE {
            opv_store(exact.light, id, OPAQUE);
            return;
        }
        opv_store(exact.light, id, integrate_pieces(x, x + towards * box_exit(x, towards), true) + beyond);
        return;
    }
    let s = light.position;
    let len = length(s - x);
    let dir = (s - x) / max(len, 1e-30);
    // Beyond the grid only base fog remains: march to where the segment leaves the grid and
    // add the rest in closed form (height fog included), so the cost stays O(N) however far the light is.
    let ta = (grid.min - x) / dir;
    let tb = (grid.max - x) / dir;
    let inside = clamp(min(min(max(ta.x, tb.x), max(ta.y, tb.y)), max(ta.z, tb.z)), 0.0, len);
    let t = integrate_segment(x, x + dir * inside, f32(exact.steps_per_cell)) + base_fog_depth(x + dir * inside, dir, len - inside);
    opv_store(exact.light, id, t);
}

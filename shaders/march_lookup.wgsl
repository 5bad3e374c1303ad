// The march's per-light lookup volumes (src/gpu/march_lookup.rs): for every cell, the value
// the march interpolates trilinearly instead of the optical depth itself, computed once per
// change of the volumes rather than at eight corners of every sample of every ray.
//
// Point and spot lights: T/|c − S|, the mean extinction along the cell centre's path to the
// light (the EV's own value in a cell whose centre is the light). Suns: the mean in-box
// extinction (T − B)/(exit distance), B the base fog beyond the box. march.wgsl's opv_at and
// sun_opv_at multiply the interpolated mean by the sample's own path length.

@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
// binding 3: `opv` (read), binding 4: `lookup` (written), declared by src/gpu/opv_store.rs.
// Nonzero for the lights whose volume is rebuilt.
@group(0) @binding(5) var<storage, read> stale: array<u32>;

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn main(@builtin(global_invocation_id) p: vec3u) {
    if any(p >= grid.dims) {
        return;
    }
    let xc = grid.min + (vec3f(p) + 0.5) * grid.cell;
    for (var light = 0u; light < grid.light_count; light++) {
        if stale[light] == 0u {
            continue;
        }
        var v: f32;
        if lights[light].kind == LIGHT_DIRECTIONAL {
            v = sun_mean_extinction(opv_load(light, p), xc, -lights[light].direction);
        } else {
            let d = length(xc - lights[light].position);
            if d < 1e-6 * grid.cell.x {
                v = textureLoad(ev, p, 0).r;
            } else {
                v = opv_load(light, p) / d;
            }
        }
        lookup_store(light, p, v);
    }
}

// Opacity propagation, Giroud & Biri's 6-neighbour gather (physics.md §5), one Jacobi
// iteration over the whole grid per dispatch.
//
// A cell gathers optical depth from the neighbour one cell towards the light along each axis
// where it is not in the light's slab, weighted by how well that axis matches the light
// direction. Each neighbour's value is advanced to this cell by the trapezoid integral of σ_t
// over the difference of their distances to the light, so a homogeneous medium gives exactly
// β·distance everywhere. Neighbours outside the grid see only the base fog. Gathering only
// towards the light's slab makes the dependencies acyclic: the iteration is exact after
// (largest Manhattan distance to the light's slabs + 1) sweeps, which the host computes.

@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<storage, read> active_lights: array<u32>;
// bindings 4, 5: `src` and `dst`, declared with their helpers by src/gpu/opv_store.rs.

fn sigma_at(c: vec3i) -> f32 {
    if any(c < vec3i(0)) || any(c >= vec3i(grid.dims)) {
        return base_fog_at(grid.min.y + (f32(c.y) + 0.5) * grid.cell.y);
    }
    return textureLoad(ev, c, 0).r;
}

@compute @workgroup_size(WORKGROUP_3D, WORKGROUP_3D, WORKGROUP_3D)
fn main(@builtin(global_invocation_id) gid: vec3u, @builtin(workgroup_id) wg: vec3u) {
    let zgroups = (grid.dims.z + WORKGROUP_3D - 1u) / WORKGROUP_3D;
    let slot = wg.z / zgroups;
    let id = vec3u(gid.xy, gid.z - slot * zgroups * WORKGROUP_3D);
    if any(id >= grid.dims) || slot >= arrayLength(&active_lights) {
        return;
    }
    let light = active_lights[slot];
    let s = lights[light].position;
    let x = cell_center(id);
    let offs = x - s;
    let dist = length(offs);
    let sigma = sigma_at(vec3i(id));

    var sum = 0.0;
    var wsum = 0.0;
    for (var a = 0u; a < 3u; a++) {
        if abs(offs[a]) <= 0.5 * grid.cell[a] * 1.0001 {
            continue;
        }
        var toward = vec3i(0);
        toward[a] = select(1, -1, offs[a] > 0.0);
        let n = vec3i(id) + toward;
        let nx = grid.min + (vec3f(n) + 0.5) * grid.cell;
        let ndist = length(nx - s);
        var tn: f32;
        if any(n < vec3i(0)) || any(n >= vec3i(grid.dims)) {
            tn = base_fog_depth(nx, (s - nx) / max(ndist, 1e-30), ndist);
        } else {
            tn = src_load(light, vec3u(n));
        }
        let w = abs(offs[a]) / dist;
        sum += w * (tn + 0.5 * (sigma + sigma_at(n)) * (dist - ndist));
        wsum += w;
    }
    var t = sigma * dist;
    if wsum > 0.0 {
        t = sum / wsum;
    }
    dst_store(light, id, t);
}

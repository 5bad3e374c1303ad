// A sun's optical-depth volume (physics.md §9) by a sweep along its direction: one dispatch
// per plane of cells across the axis the light travels most along, upstream planes first.
//
// A cell's optical depth towards the sun is G + B: G the grid's medium from the cell centre to
// where the ray towards the sun leaves the box, B the base fog beyond in closed form
// (common.wgsl). G steps back along the ray to an upstream plane of cell centres (the
// propagation's stride of planes back, fewer interpolations meaning less numerical
// diffusion), where it
// interpolates the previous plane's mean in-box extinction G/(exit distance) bilinearly and
// multiplies it by the exit distance from there, then adds the exact integral of the trilinear
// medium over the short step (integrate_pieces). The mean extinction is constant in
// homogeneous fog, so the sweep is exact there, and it is smooth where G has kinks (at the
// shadows of the box's edges). A cell whose step back leaves the box integrates straight to
// the exit. The volume stores G + B, the full optical depth.

struct PlaneParams {
    light: u32,
    // The axis the planes are stacked along and this dispatch's plane.
    axis: u32,
    plane: u32,
    // The upstream plane read: plane ± stride; equal to plane for the first `stride` planes.
    previous: u32,
}

@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> plane: PlaneParams;
// binding 4: `opv`, declared with its helpers by src/gpu/opv_store.rs.

// Mean in-box extinction of cell c of the previous plane: (T − B)/exit.
fn mean_extinction(c: vec3u, towards: vec3f, light: u32) -> f32 {
    let x = cell_center(c);
    let e = box_exit(x, towards);
    let b = sun_beyond(x, towards);
    return max(opv_load(light, c) - b, 0.0) / max(e, 1e-30);
}

@compute @workgroup_size(WORKGROUP_2D, WORKGROUP_2D, 1)
fn main(@builtin(global_invocation_id) gid: vec3u) {
    let a = plane.axis;
    let a1 = (a + 1u) % 3u;
    let a2 = (a + 2u) % 3u;
    if gid.x >= grid.dims[a1] || gid.y >= grid.dims[a2] {
        return;
    }
    var id: vec3u;
    id[a] = plane.plane;
    id[a1] = gid.x;
    id[a2] = gid.y;
    let towards = -lights[plane.light].direction;
    let x = cell_center(id);
    let beyond = sun_beyond(x, towards);
    if beyond >= OPAQUE {
        opv_store(plane.light, id, OPAQUE);
        return;
    }
    let e = box_exit(x, towards);
    let planes = f32(max(plane.plane, plane.previous) - min(plane.plane, plane.previous));
    let s = planes * grid.cell[a] / abs(towards[a]);
    var g: f32;
    if plane.previous == plane.plane || s >= e {
        g = integrate_pieces(x, x + towards * e, true);
    } else {
        let u = x + towards * s;
        // Bilinear weights in the previous plane, clamped to its cell centres.
        let f = clamp((u - grid.min) / grid.cell - 0.5, vec3f(0.0), vec3f(grid.dims - 1u));
        let i1 = u32(floor(f[a1]));
        let i2 = u32(floor(f[a2]));
        let j1 = min(i1 + 1u, grid.dims[a1] - 1u);
        let j2 = min(i2 + 1u, grid.dims[a2] - 1u);
        let w1 = f[a1] - f32(i1);
        let w2 = f[a2] - f32(i2);
        var c: vec3u;
        c[a] = plane.previous;
        c[a1] = i1;
        c[a2] = i2;
        let m00 = mean_extinction(c, towards, plane.light);
        c[a1] = j1;
        let m10 = mean_extinction(c, towards, plane.light);
        c[a2] = j2;
        let m11 = mean_extinction(c, towards, plane.light);
        c[a1] = i1;
        let m01 = mean_extinction(c, towards, plane.light);
        let m = mix(mix(m00, m10, w1), mix(m01, m11, w1), w2);
        g = m * box_exit(u, towards) + integrate_pieces(x, u, true);
    }
    opv_store(plane.light, id, g + beyond);
}

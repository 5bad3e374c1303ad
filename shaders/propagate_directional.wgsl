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
//
// Interpolation cannot resolve the shadow of a particle of a cell or two, and its error adds
// up along the ray. With `propagation.sweep_refine` (plane.refine) every interpolation is
// error-controlled as in the point lights' sweep: the stencil's second differences across
// each interpolated axis (a 4 × 4 stencil around the bilinear one; their size is the order
// of linear interpolation's error whether or not the data are smooth across a cell), times
// the rest's length and the whole path's transmittance, estimate the interpolation's error
// in the cell's transmittance. Above `plane.tolerance`, or where the point stepped back to
// lies beyond the outermost cell centres (the stencil then extrapolates), the cell integrates
// its whole in-box path exactly instead, so the cells downstream interpolate from exact
// values.

struct PlaneParams {
    light: u32,
    // The axis the planes are stacked along and this dispatch's plane.
    axis: u32,
    plane: u32,
    // The upstream plane read: plane ± stride; equal to plane for the first `stride` planes.
    previous: u32,
    // 1: interpolations are error-controlled (see the top of this file).
    refine: u32,
    // Their largest accepted error in transmittance.
    tolerance: f32,
    _pad0: u32,
    _pad1: u32,
}

// Read-only storage: on llvmpipe its loads cost less than a sampled texture's.
@group(0) @binding(1) var ev: texture_storage_3d<r32float, read>;

fn ev_texel(c: vec3i) -> f32 {
    return textureLoad(ev, c).r;
}
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> plane: PlaneParams;
// binding 4: `opv`, declared with its helpers by src/gpu/opv_store.rs.

// Mean in-box extinction of cell c of the previous plane: (T − B)/exit.
fn mean_extinction(c: vec3u, towards: vec3f, light: u32) -> f32 {
    return sun_mean_extinction(opv_load(light, c), cell_center(c), towards);
}

// The largest |second difference| of the stencil values v (cells f − 1 … f + 2 of an axis of
// n cells) over the triples that lie in the grid and touch the interval [f, f + 1]: the
// order of linear interpolation's error there, whether the data are smooth or not.
fn curvature(v: vec4f, f: i32, n: i32) -> f32 {
    var e = 0.0;
    if f >= 1 && f + 1 < n {
        e = abs(v.x - 2.0 * v.y + v.z);
    }
    if f + 2 < n {
        e = max(e, abs(v.y - 2.0 * v.z + v.w));
    }
    return e;
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
        let raw = (u - grid.min) / grid.cell - 0.5;
        let f = clamp(raw, vec3f(0.0), vec3f(grid.dims - 1u));
        let i1 = i32(floor(f[a1]));
        let i2 = i32(floor(f[a2]));
        let w1 = f[a1] - f32(i1);
        let w2 = f[a2] - f32(i2);
        // The stencil's cells i − 1 … i + 2 along both axes (clamped to the grid), rows along
        // a2; without refine only the middle two of each.
        let refine = plane.refine != 0u;
        let n1 = i32(grid.dims[a1]);
        let n2 = i32(grid.dims[a2]);
        var rows: array<vec4f, 4>;
        var c: vec3u;
        c[a] = plane.previous;
        for (var r = 0; r < 4; r++) {
            if !refine && (r == 0 || r == 3) {
                continue;
            }
            c[a2] = u32(clamp(i2 - 1 + r, 0, n2 - 1));
            var v = vec4f(0.0);
            for (var q = 0; q < 4; q++) {
                if !refine && (q == 0 || q == 3) {
                    continue;
                }
                c[a1] = u32(clamp(i1 - 1 + q, 0, n1 - 1));
                v[q] = mean_extinction(c, towards, plane.light);
            }
            rows[r] = v;
        }
        let m = mix(mix(rows[1].y, rows[1].z, w1), mix(rows[2].y, rows[2].z, w1), w2);
        let rest = box_exit(u, towards);
        let near = integrate_pieces(x, u, true);
        g = m * rest + near;
        if refine {
            let cols = array<vec4f, 4>(
                vec4f(rows[0].x, rows[1].x, rows[2].x, rows[3].x),
                vec4f(rows[0].y, rows[1].y, rows[2].y, rows[3].y),
                vec4f(rows[0].z, rows[1].z, rows[2].z, rows[3].z),
                vec4f(rows[0].w, rows[1].w, rows[2].w, rows[3].w),
            );
            // Beyond the outermost cell centres the stencil's values are extrapolated as
            // constants, whose error nothing here estimates: such cells integrate directly.
            let outside = raw[a1] != f[a1] || raw[a2] != f[a2];
            var err = select(0.0, 3.4e38, outside);
            if w1 > 1e-4 {
                err += max(curvature(rows[1], i1, n1), curvature(rows[2], i1, n1));
            }
            if w2 > 1e-4 {
                err += max(curvature(cols[1], i2, n2), curvature(cols[2], i2, n2));
            }
            // The error in mean extinction, times the rest's length and the whole path's
            // transmittance: the interpolation's error in this cell's transmittance.
            if err * rest * exp(-(g + beyond)) > plane.tolerance {
                g = near + integrate_pieces(u, u + towards * rest, true);
            }
        }
    }
    opv_store(plane.light, id, g + beyond);
}

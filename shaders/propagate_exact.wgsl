// Opacity propagation by brute force: every cell marches straight to the light through the
// trilinear EV with steps of a quarter of the smallest cell edge (Simpson's rule per pair of
// steps). O(N) work per cell, O(N⁴) per light: a reference-quality scheme for measurement.

struct ExactParams {
    light: u32,
    steps_per_cell: u32,
    _pad: vec2u,
}

@group(0) @binding(0) var<uniform> grid: GridParams;
@group(0) @binding(1) var ev: texture_3d<f32>;
@group(0) @binding(2) var<storage, read> lights: array<LightGpu>;
@group(0) @binding(3) var<uniform> exact: ExactParams;
@group(0) @binding(4) var<storage, read_write> opv: array<f32>;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if any(id >= grid.dims) {
        return;
    }
    let x = cell_center(id);
    let t = integrate_segment(x, lights[exact.light].position, f32(exact.steps_per_cell));
    opv[exact.light * cell_count() + linear_index(id)] = t;
}

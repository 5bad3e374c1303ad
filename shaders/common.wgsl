// Shared declarations, prepended to every Fogsmith compute shader.

struct GridParams {
    min: vec3f,
    base_extinction: f32,
    max: vec3f,
    light_count: u32,
    cell: vec3f,
    has_base_layer: u32,
    dims: vec3u,
    // Edge, in cells, of the bins particles are listed in for injection.
    bin_size: u32,
}

// A point light: position and radiant intensity per RGB channel (W/sr). Hidden lights have zero rgb.
struct LightGpu {
    position: vec3f,
    _pad0: f32,
    rgb: vec3f,
    _pad1: f32,
}

fn cell_center(id: vec3u) -> vec3f {
    return grid.min + (vec3f(id) + 0.5) * grid.cell;
}

fn linear_index(id: vec3u) -> u32 {
    return id.x + grid.dims.x * (id.y + grid.dims.y * id.z);
}

fn cell_count() -> u32 {
    return grid.dims.x * grid.dims.y * grid.dims.z;
}

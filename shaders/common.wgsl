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

// A light (kind LIGHT_POINT, LIGHT_SPOT or LIGHT_DIRECTIONAL): position, intensity per RGB
// channel (W/sr; W/m² for a directional light), unit direction (the spot's axis or the
// direction a sun's light travels), the spot's half-angle (radians) and blend. Hidden and
// culled lights have zero rgb.
struct LightGpu {
    position: vec3f,
    kind: u32,
    rgb: vec3f,
    angle: f32,
    direction: vec3f,
    blend: f32,
}

const LIGHT_POINT: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_DIRECTIONAL: u32 = 2u;

// The spot's cone factor at offset v from its apex (physics.md §9), 1 for other kinds:
// t = clamp((A − θ)/(A·B), 0, 1), factor t²(3 − 2t); a hard edge when B = 0.
fn cone_factor(light: LightGpu, v: vec3f) -> f32 {
    if light.kind != LIGHT_SPOT {
        return 1.0;
    }
    let len = length(v);
    if len <= 0.0 {
        return 1.0;
    }
    let theta = acos(clamp(dot(light.direction, v) / len, -1.0, 1.0));
    if light.blend <= 0.0 {
        return select(0.0, 1.0, theta <= light.angle);
    }
    let t = clamp((light.angle - theta) / (light.angle * light.blend), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
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

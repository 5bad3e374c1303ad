// Injection: particles -> extinction volume (EV).
// Each cell sums the gaussians binned into its 8³ brick; a particle is binned only into the
// bricks its cut-off sphere reaches, so cost follows particle-cell overlaps.

struct ParticleGpu {
    center: vec3f,
    inv_r2: f32,
    density: f32,
    cutoff2: f32,
    _pad: vec2f,
}

@group(0) @binding(0) var<uniform> grid: GridParams;
@group(0) @binding(1) var<storage, read> particles: array<ParticleGpu>;
@group(0) @binding(2) var<storage, read> brick_offsets: array<u32>;
@group(0) @binding(3) var<storage, read> brick_items: array<u32>;
@group(0) @binding(4) var ev: texture_storage_3d<r32float, write>;

const BRICK: u32 = 8u;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) id: vec3u) {
    if any(id >= grid.dims) {
        return;
    }
    let x = cell_center(id);
    let bdims = (grid.dims + BRICK - 1u) / BRICK;
    let b = id / BRICK;
    let brick = b.x + bdims.x * (b.y + bdims.y * b.z);
    var sum = 0.0;
    for (var n = brick_offsets[brick]; n < brick_offsets[brick + 1u]; n++) {
        let p = particles[brick_items[n]];
        let d = x - p.center;
        let d2 = dot(d, d);
        if d2 < p.cutoff2 {
            sum += p.density * exp(-d2 * p.inv_r2);
        }
    }
    textureStore(ev, id, vec4f(grid.base_extinction + sum, 0.0, 0.0, 0.0));
}

// Injection: particles -> extinction volume (EV).
// A bin is b × b cells across and one brick (8 cells) along z; a particle is listed only in
// the bins its cut-off sphere reaches, so cost follows particle-cell overlaps. One workgroup
// per listed 8³ brick (a full bake lists every brick, an edit only the bricks it touched);
// each thread sums one column of 8 cells, so every particle it loads serves eight cells.

struct ParticleGpu {
    center: vec3f,
    inv_r2: f32,
    // Peak extinction as (plain, noisy): noisy particles are modulated by the medium's noise.
    density: vec2f,
    cutoff2: f32,
    _pad: f32,
}

// Bindings 4–6 and each cell's last step: inject_finish.wgsl (binding 0: common.wgsl).
@group(0) @binding(1) var<storage, read> particles: array<ParticleGpu>;
@group(0) @binding(2) var<storage, read> bin_offsets: array<u32>;
@group(0) @binding(3) var<storage, read> bin_items: array<u32>;

@compute @workgroup_size(BRICK, BRICK, 1)
fn main(@builtin(workgroup_id) wg: vec3u, @builtin(local_invocation_id) lid: vec3u) {
    let b = dirty_brick(wg.x);
    let base = b * BRICK + vec3u(lid.xy, 0u);
    if any(base.xy >= grid.dims.xy) {
        return;
    }
    let ndims = vec2u((grid.dims.xy + grid.bin_size - 1u) / grid.bin_size);
    let nb = base.xy / grid.bin_size;
    let bin = nb.x + ndims.x * (nb.y + ndims.y * b.z);
    let x0 = cell_center(base);
    var sum: array<vec2f, BRICK>;
    for (var n = bin_offsets[bin]; n < bin_offsets[bin + 1u]; n++) {
        let p = particles[bin_items[n]];
        let dxy = x0.xy - p.center.xy;
        let dxy2 = dot(dxy, dxy);
        if dxy2 >= p.cutoff2 {
            continue;
        }
        for (var k = 0u; k < BRICK; k++) {
            // cell_center's z, written out: a table of the column's eight z values is slower
            // on llvmpipe (dynamically indexed arrays live in memory there).
            let d = grid.min.z + (f32(base.z + k) + 0.5) * grid.cell.z - p.center.z;
            let d2 = dxy2 + d * d;
            if d2 < p.cutoff2 {
                sum[k] += p.density * exp(-d2 * p.inv_r2);
            }
        }
    }
    for (var k = 0u; k < BRICK; k++) {
        let id = base + vec3u(0u, 0u, k);
        if id.z >= grid.dims.z {
            break;
        }
        write_cell(id, sum[k]);
    }
}

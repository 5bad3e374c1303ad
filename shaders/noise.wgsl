// The medium's fractal value noise on the particles (the `Noise` doc in src/scene/mod.rs
// defines it; the CPU twin is src/reference/noise.rs). Reads the noise_* fields of `grid`.

fn noise_pcg(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// Bit for bit `noise_hash` of src/scene/mod.rs (u32 arithmetic wraps in WGSL as there).
fn noise_hash(i: i32, j: i32, k: i32, seed: u32) -> u32 {
    var h = (seed * 0x9E3779B9u) ^ (bitcast<u32>(i) * 0x85EBCA6Bu);
    h = noise_pcg(h) ^ (bitcast<u32>(j) * 0xC2B2AE35u);
    h = noise_pcg(h) ^ (bitcast<u32>(k) * 0x27D4EB2Fu);
    return noise_pcg(h);
}

// Lattice value in [−1, 1]: 2·(hash / 2³²) − 1.
fn noise_lattice(c: vec3i, seed: u32) -> f32 {
    return f32(noise_hash(c.x, c.y, c.z, seed)) * (1.0 / 2147483648.0) - 1.0;
}

// Value noise: trilinear interpolation of the lattice values with smoothstep weights.
fn value_noise(p: vec3f, seed: u32) -> f32 {
    let f = floor(p);
    let t = p - f;
    let w = t * t * (3.0 - 2.0 * t);
    // Clamped to what i32 holds (2147483520 is the largest f32 below 2³¹), as on the CPU.
    let c = vec3i(clamp(f, vec3f(-2147483648.0), vec3f(2147483520.0)));
    let d = vec3i(1, 1, 1) + c;
    let x00 = mix_exact(noise_lattice(c, seed), noise_lattice(vec3i(d.x, c.y, c.z), seed), w.x);
    let x10 = mix_exact(noise_lattice(vec3i(c.x, d.y, c.z), seed), noise_lattice(vec3i(d.x, d.y, c.z), seed), w.x);
    let x01 = mix_exact(noise_lattice(vec3i(c.x, c.y, d.z), seed), noise_lattice(vec3i(d.x, c.y, d.z), seed), w.x);
    let x11 = mix_exact(noise_lattice(vec3i(c.x, d.y, d.z), seed), noise_lattice(d, seed), w.x);
    return mix_exact(mix_exact(x00, x10, w.y), mix_exact(x01, x11, w.y), w.z);
}

// a + (b − a)·t: exactly a at t = 0, so lattice points give lattice values unrounded.
fn mix_exact(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}

// max(0, 1 + amplitude·n(x − offset)) over the kept octaves; 1 without noise. The drift
// is subtracted in f32 once, as the CPU reference does (src/reference/noise.rs).
fn noise_modulation(x_world: vec3f) -> f32 {
    if grid.noise_octaves == 0u {
        return 1.0;
    }
    let x = x_world - grid.noise_offset;
    var sum = 0.0;
    var norm = 0.0;
    var weight = 1.0;
    var frequency = grid.noise_frequency;
    for (var o = 0u; o < grid.noise_octaves; o++) {
        sum += weight * value_noise(x * frequency, grid.noise_seed + o);
        norm += weight;
        weight *= 0.5;
        frequency *= 2.0;
    }
    return max(0.0, 1.0 + grid.noise_amplitude * (sum / norm));
}

// A cell's particle extinction from its sums of (plain, noisy) particles at x.
fn particle_sum(sum: vec2f, x: vec3f) -> f32 {
    if sum.y == 0.0 {
        return sum.x;
    }
    return sum.x + sum.y * noise_modulation(x);
}

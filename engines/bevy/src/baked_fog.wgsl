// Draws a Fogsmith light bake as emission and absorption, with no lights: the fragment of
// each back face of the box marches the view ray through the box in uniform steps, reading
// the emission j (RGB) and the extinction σ (A) trilinearly from the 3D texture. Over a step
// of length Δ both are held constant and integrated exactly:
//   L += T · j · (1 − e^{−σΔ}) / σ,   T *= e^{−σΔ}.
// The result goes out premultiplied: (exposure · L, 1 − T).

#import bevy_pbr::forward_io::VertexOutput
#import bevy_pbr::mesh_view_bindings::view

struct BakedFog {
    box_min: vec3<f32>,
    emission_scale: f32,
    box_max: vec3<f32>,
    extinction_scale: f32,
    // Step length along the ray, in metres.
    step: f32,
}

@group(#{MATERIAL_BIND_GROUP}) @binding(0) var<uniform> fog: BakedFog;
@group(#{MATERIAL_BIND_GROUP}) @binding(1) var bake_texture: texture_3d<f32>;
@group(#{MATERIAL_BIND_GROUP}) @binding(2) var bake_sampler: sampler;

// Below this transmittance the rest of the ray adds at most that fraction of its radiance.
const CUTOFF: f32 = 1e-6;

@fragment
fn fragment(in: VertexOutput) -> @location(0) vec4<f32> {
    let origin = view.world_position;
    let dir = normalize(in.world_position.xyz - origin);
    // Slab test against the box; a zero direction component is replaced by a tiny one, whose
    // huge inverse the min/max below handle.
    let inv = 1.0 / select(dir, vec3<f32>(1e-30), abs(dir) < vec3<f32>(1e-30));
    let a = (fog.box_min - origin) * inv;
    let b = (fog.box_max - origin) * inv;
    let near = min(a, b);
    let far = max(a, b);
    let t0 = max(max(near.x, near.y), max(near.z, 0.0));
    let t1 = min(min(far.x, far.y), far.z);
    var radiance = vec3<f32>(0.0);
    var transmittance = 1.0;
    if t1 > t0 {
        let n = max(u32(ceil((t1 - t0) / fog.step)), 1u);
        let dt = (t1 - t0) / f32(n);
        let size = fog.box_max - fog.box_min;
        for (var k = 0u; k < n; k++) {
            let p = origin + dir * (t0 + (f32(k) + 0.5) * dt);
            let texel = textureSampleLevel(bake_texture, bake_sampler, (p - fog.box_min) / size, 0.0);
            let sigma = texel.a * fog.extinction_scale;
            let tau = sigma * dt;
            // ∫_0^Δ e^{−σs} ds, by its series where σΔ is too small for f32.
            let weight = select((1.0 - exp(-tau)) / sigma, dt * (1.0 - tau * (0.5 - tau / 6.0)), tau < 1e-3);
            radiance += transmittance * weight * texel.rgb * fog.emission_scale;
            transmittance *= exp(-tau);
            if transmittance < CUTOFF {
                break;
            }
        }
    }
    return vec4<f32>(radiance * view.exposure, 1.0 - transmittance);
}

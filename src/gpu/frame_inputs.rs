//! The project in GPU terms: [`FrameInputs`] is built once per call from the project, the
//! request and the pipeline's settings, and holds what the stages upload (grid, lights,
//! surfaces, march parameters) and every stage's key. The scheduler and the stages read it;
//! nothing translates the project a second time.

use super::gpu_types::{GridParams, LightGpu, MarchParams, SurfaceGpu};
use super::keys::{EvKey, ImageKey, OpvKey, ScatterKey};
use super::layout::{
    LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_SPOT, POLICY_ADAPTIVE, POLICY_FIXED, POLICY_TWO_LEVEL, SURFACE_BOX,
    SURFACE_GROUND,
};
use crate::scene::{Light, LightKind, MultipleScattering, Noise, Project, Scheme, StepPolicy};

/// What to render this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRequest {
    pub width: u32,
    pub height: u32,
    pub scheme: Scheme,
    /// Recompute every stage even if nothing changed.
    pub force: bool,
}

impl FrameRequest {
    /// The project's own render size and propagation scheme.
    pub fn for_project(project: &Project) -> Self {
        Self {
            width: project.render.width,
            height: project.render.height,
            scheme: project.propagation.scheme,
            force: false,
        }
    }
}

/// The pipeline's settings that enter the inputs (see `FogPipeline`'s setters).
pub(super) struct Settings {
    /// A base layer resampled for the project's grid is bound.
    pub layer_on_grid: bool,
    pub layer_generation: u64,
    pub brute_force: bool,
    /// Bin edge of the last injection's particle lists.
    pub bin_size: u32,
}

/// One call's project and request in GPU terms.
pub(super) struct FrameInputs {
    pub request: FrameRequest,
    pub grid: GridParams,
    /// Per light, culled and hidden ones dark.
    pub lights: Vec<LightGpu>,
    pub surfaces: Vec<SurfaceGpu>,
    pub march: MarchParams,
    pub ev: EvKey,
    /// Per light: the OPV key at EV generation 0, None when it gets no OPV.
    opvs: Vec<Option<OpvKey>>,
    /// Per light: negligible, or unable to reach the grid box.
    pub culled: Vec<bool>,
    pub positions: Vec<glam::Vec3>,
    /// Per light: a directional light's unit direction of travel.
    pub directions: Vec<Option<glam::Vec3>>,
    pub sweep_stride: u32,
    pub sweep_refine: Option<f32>,
    /// The multiple-scattering solve this frame needs (see [`multiple_scattering_of`]).
    pub multiple_scattering: Option<MultipleScattering>,
}

impl FrameInputs {
    pub fn new(project: &Project, request: &FrameRequest, settings: &Settings) -> Self {
        let (min, max) = (project.grid.min, project.grid.max);
        let mut lights = Vec::with_capacity(project.lights.len());
        let mut opvs = Vec::with_capacity(project.lights.len());
        let mut culled = Vec::with_capacity(project.lights.len());
        let surfaces = surfaces_gpu(project);
        for l in &project.lights {
            let negligible = light_is_negligible(project, l);
            let reaches = l.reaches_box(min, max);
            let mut gpu = light_gpu(l, negligible);
            gpu.occluders = occluders(&gpu, &surfaces, min, max);
            lights.push(gpu);
            opvs.push(has_opv(l, negligible, reaches).then(|| opv_key(project, l, request.scheme)));
            culled.push(negligible || !reaches);
        }
        let noise = noise_of(project);
        Self {
            request: *request,
            grid: grid_params(project, settings),
            lights,
            march: march_params(project, request.width, request.height, surfaces.len() as u32),
            surfaces,
            ev: EvKey {
                grid: project.grid,
                base_extinction: project.medium.base_extinction,
                height: [project.medium.height_falloff, project.medium.height_origin],
                layer_generation: settings.layer_generation,
                brute_force: settings.brute_force,
                noise,
            },
            opvs,
            culled,
            positions: project.lights.iter().map(|l| l.position).collect(),
            directions: project.lights.iter().map(sun_direction).collect(),
            sweep_stride: project.propagation.sweep_stride,
            sweep_refine: project.propagation.refine_tolerance(),
            multiple_scattering: multiple_scattering_of(project),
        }
    }

    pub fn light_count(&self) -> usize {
        self.lights.len()
    }

    /// The OPV inputs light `i` needs once the EV is at `ev_generation`, or None when it is
    /// not propagated at all (hidden, dark or culled).
    pub fn opv_key(&self, i: usize, ev_generation: u64) -> Option<OpvKey> {
        self.opvs[i].map(|k| OpvKey { ev_generation, ..k })
    }

    /// What a march now would read, given the EV generation and OPVs on the GPU.
    pub fn image_key(&self, ev_generation: u64, opvs: &[Option<OpvKey>]) -> ImageKey {
        ImageKey {
            params: self.march,
            grid: self.grid,
            lights: self.lights.clone(),
            surfaces: self.surfaces.clone(),
            ev_generation,
            opvs: opvs.to_vec(),
            scatter: 0,
        }
    }

    /// What the multiple-scattering solve reads, given the EV generation and OPVs on the GPU;
    /// None when the frame needs none.
    pub fn scatter_key(&self, ev_generation: u64, opvs: &[Option<OpvKey>]) -> Option<ScatterKey> {
        let settings = self.multiple_scattering?;
        Some(ScatterKey {
            settings,
            factor: self.march.scatter_factor,
            albedo: self.march.albedo,
            anisotropy: self.march.anisotropy,
            grid: self.grid,
            lights: self.lights.clone(),
            surfaces: self.surfaces.clone(),
            ev_generation,
            opvs: opvs.to_vec(),
        })
    }
}

/// The OPV key of a light that gets one, at EV generation 0.
fn opv_key(project: &Project, l: &Light, scheme: Scheme) -> OpvKey {
    // A sun's volume depends on its direction, not its position: `sweep` and `giroud` sweep it
    // plane by plane (with the sweep's error control, if on), `exact` and `analytic` integrate
    // it themselves.
    if let Some(direction) = sun_direction(l) {
        let (scheme, refine) = match scheme {
            Scheme::Sweep | Scheme::Giroud => (Scheme::Sweep, project.propagation.refine_tolerance()),
            other => (other, None),
        };
        return OpvKey { position: direction, ev_generation: 0, scheme, stride: 0, refine, sun: true };
    }
    let (stride, refine) = match scheme {
        Scheme::Sweep => (project.propagation.sweep_stride, project.propagation.refine_tolerance()),
        _ => (0, None),
    };
    OpvKey { position: l.position, ev_generation: 0, scheme, stride, refine, sun: false }
}

/// Whether light `l` gets an optical-depth volume: it is shown, has intensity, can reach
/// the grid box (a spot's cone, a point light's reach) and is not negligible. The others add
/// nothing to the image, so their volumes are never read (their contents are unspecified).
pub fn light_has_opv(project: &Project, l: &Light) -> bool {
    has_opv(l, light_is_negligible(project, l), l.reaches_box(project.grid.min, project.grid.max))
}

fn has_opv(l: &Light, negligible: bool, reaches_box: bool) -> bool {
    !(l.hidden || l.intensity <= 0.0 || negligible || !reaches_box)
}

/// Radiance below which a light's whole contribution is dropped: the tone-mapped display
/// changes by less than exposure × this, far below one 8-bit step.
pub const CULL_RADIANCE: f32 = 1e-6;

/// Whether light `l` provably adds less than [`CULL_RADIANCE`] / exposure to every pixel.
/// Only possible without base fog and surfaces: then light is scattered only inside the grid,
/// and a pixel receives at most I·albedo·max(phase) / d² (d: the light's distance to the grid
/// box), since ∫σ_t·exp(−τ) along a ray is below 1.
pub fn light_is_negligible(project: &Project, l: &Light) -> bool {
    if !l.reaches_box(project.grid.min, project.grid.max)
        && project.medium.base_extinction <= 0.0
        && project.surfaces.is_empty()
    {
        return true;
    }
    if matches!(l.kind, LightKind::Directional { .. })
        || project.medium.base_extinction > 0.0
        || !project.surfaces.is_empty()
        || project.base_volume.is_some()
    {
        return false;
    }
    let g = project.grid;
    let d2 = (l.position - l.position.clamp(g.min, g.max)).length_squared();
    let gm = project.medium.anisotropy.abs();
    let max_phase = (1.0 + gm) / (4.0 * std::f32::consts::PI * (1.0 - gm).powi(2));
    let bound = l.radiance_rgb().max_element() * project.medium.albedo * max_phase / d2;
    bound * project.render.exposure.max(1e-6) < CULL_RADIANCE
}

/// The medium's noise when it changes the EV (amplitude above 0), else None.
pub(super) fn noise_of(project: &Project) -> Option<Noise> {
    project.medium.noise.filter(|n| n.amplitude > 0.0)
}

/// The unit direction of travel of a directional light; None for other kinds.
fn sun_direction(l: &Light) -> Option<glam::Vec3> {
    match l.kind {
        LightKind::Directional { direction } => Some(direction.normalize_or_zero()),
        _ => None,
    }
}

fn grid_params(project: &Project, settings: &Settings) -> GridParams {
    let spec = project.grid;
    let noise = noise_of(project);
    GridParams {
        min: spec.min.to_array(),
        base_extinction: project.medium.base_extinction,
        max: spec.max.to_array(),
        light_count: project.lights.len() as u32,
        cell: spec.cell_size().to_array(),
        has_base_layer: settings.layer_on_grid as u32,
        dims: spec.resolution.to_array(),
        bin_size: settings.bin_size,
        height_falloff: project.medium.height_falloff,
        height_origin: project.medium.height_origin,
        _pad_h: [0; 2],
        noise_amplitude: noise.map_or(0.0, |n| n.amplitude),
        noise_frequency: noise.map_or(0.0, |n| n.frequency),
        noise_octaves: noise.map_or(0, |n| n.effective_octaves(&spec)),
        noise_seed: noise.map_or(0, |n| n.seed),
        noise_offset: noise.map_or([0.0; 3], |n| n.offset.to_array()),
        _pad_n: 0,
    }
}

fn light_gpu(l: &Light, culled: bool) -> LightGpu {
    let rgb = if l.hidden || culled { glam::Vec3::ZERO } else { l.radiance_rgb() };
    let (kind, direction, angle, blend) = match l.kind {
        LightKind::Point => (LIGHT_POINT, glam::Vec3::ZERO, 0.0, 0.0),
        LightKind::Spot { direction, angle_deg, blend } => {
            (LIGHT_SPOT, direction.normalize_or_zero(), angle_deg.to_radians(), blend)
        }
        LightKind::Directional { direction } => (LIGHT_DIRECTIONAL, direction.normalize_or_zero(), 0.0, 0.0),
    };
    LightGpu {
        position: l.position.to_array(),
        kind,
        rgb: rgb.to_array(),
        angle,
        direction: direction.to_array(),
        blend,
        occluders: 0,
        _pad: [0; 3],
    }
}

/// The light's `occluders` mask: bit i set unless surface i provably cannot block, by the
/// march's `blocks` test, the path from any point of the grid box [min, max] to the light. The
/// march then tests only these surfaces for its samples in the box (surfaces from the 33rd on
/// always). A culled surface's interior misses every such path: for a point or spot light the
/// paths lie in the bounding box of the grid box and the light, and a box whose interior misses
/// that can meet a path only on its boundary, which the test does not count as blocking (its
/// exit is behind the path's start, or its entry at the light, beyond the test's reach);
/// for a sun the paths are the grid box swept towards the sun, which a box misses when a face
/// plane separates them along the sweep, or when the sweep misses it by a margin far above f32
/// rounding. The ground blocks only paths that go down through it: towards a point or spot
/// below it, or a sun shining from below, from a part of the box above it. The one exception
/// is a path lying in the plane of a box's face that touches the bounding box, which both
/// tests decide by rounding.
pub(super) fn occluders(light: &LightGpu, surfaces: &[SurfaceGpu], min: glam::Vec3, max: glam::Vec3) -> u32 {
    let (g_min, g_max) = (min.as_dvec3(), max.as_dvec3());
    let sun = light.kind == LIGHT_DIRECTIONAL;
    let towards = -glam::Vec3::from(light.direction).as_dvec3();
    let s = glam::Vec3::from(light.position).as_dvec3();
    let mut mask = 0u32;
    for (i, surface) in surfaces.iter().enumerate().take(32) {
        let (b_min, b_max) = (glam::Vec3::from(surface.min).as_dvec3(), glam::Vec3::from(surface.max).as_dvec3());
        let may_block = if surface.kind == SURFACE_GROUND {
            let below = if sun { towards.y < 0.0 } else { s.y < b_min.y };
            below && g_max.y > b_min.y
        } else if sun {
            sweep_meets_box(g_min, g_max, towards, b_min, b_max)
        } else {
            let (a_min, a_max) = (g_min.min(s), g_max.max(s));
            b_min.cmplt(a_max).all() && b_max.cmpgt(a_min).all()
        };
        if may_block {
            mask |= 1 << i;
        }
    }
    mask
}

/// Whether the grid box [g_min, g_max] swept along `u` (t ≥ 0) may meet the interior of the box
/// [b_min, b_max]: x + t·u lies in the box for some x in the grid box exactly when t·u lies in
/// their difference [b_min − g_max, b_max − g_min], a ray–box test.
fn sweep_meets_box(
    g_min: glam::DVec3,
    g_max: glam::DVec3,
    u: glam::DVec3,
    b_min: glam::DVec3,
    b_max: glam::DVec3,
) -> bool {
    if u == glam::DVec3::ZERO {
        return true;
    }
    for a in 0..3 {
        if (b_min[a] >= g_max[a] && u[a] <= 0.0) || (b_max[a] <= g_min[a] && u[a] >= 0.0) {
            return false;
        }
    }
    let (lo, hi) = (b_min - g_max, b_max - g_min);
    let margin = 1e-4 * lo.abs().max(hi.abs()).max_element();
    let (lo, hi) = (lo - margin, hi + margin);
    let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
    for a in 0..3 {
        if u[a] == 0.0 {
            if lo[a] > 0.0 || hi[a] < 0.0 {
                return false;
            }
        } else {
            let (ta, tb) = (lo[a] / u[a], hi[a] / u[a]);
            t0 = t0.max(ta.min(tb));
            t1 = t1.min(ta.max(tb));
        }
    }
    t0 <= t1
}

/// The project's surfaces in the layout of `shaders/march.wgsl`.
fn surfaces_gpu(project: &Project) -> Vec<SurfaceGpu> {
    let mut out: Vec<SurfaceGpu> = project
        .surfaces
        .boxes
        .iter()
        .map(|b| SurfaceGpu {
            min: b.min.to_array(),
            kind: SURFACE_BOX,
            max: b.max.to_array(),
            specular: b.specular,
            albedo: b.albedo.to_array(),
            phong_exponent: b.phong_exponent,
        })
        .collect();
    if let Some(g) = &project.surfaces.ground {
        out.push(SurfaceGpu {
            min: [0.0, g.height, 0.0],
            kind: SURFACE_GROUND,
            max: [0.0; 3],
            specular: g.specular,
            albedo: g.albedo.to_array(),
            phong_exponent: g.phong_exponent,
        });
    }
    out
}
/// Camera basis scaled to the image plane, step policy and far distance for the march.
fn march_params(project: &Project, width: u32, height: u32, surface_count: u32) -> MarchParams {
    let cam = &project.camera;
    let r = &project.render;
    let (right, up, forward) = cam.basis();
    let tan_half = (cam.fov_y_deg.to_radians() * 0.5).tan();
    let aspect = width as f32 / height as f32;
    let step = r.step_factor * project.grid.cell_size().min_element();
    let base = project.medium.base_extinction;
    // Beyond the grid only base fog remains; follow it until its transmittance is 1e-8.
    // Height fog thins upwards, so no density bounds the distance: the cap alone applies.
    let far_distance = if base > 0.0 {
        let reach = if project.medium.height_falloff > 0.0 { f32::INFINITY } else { 18.42 / base };
        reach.min(20.0 * project.grid.size().length())
    } else {
        0.0
    };
    MarchParams {
        origin: cam.position.to_array(),
        step,
        right: (right * tan_half * aspect).to_array(),
        albedo: project.medium.albedo,
        up: (up * tan_half).to_array(),
        anisotropy: project.medium.anisotropy,
        forward: forward.to_array(),
        exposure: r.exposure,
        size: [width, height],
        tr_cutoff: r.transmittance_cutoff,
        far_distance,
        policy: match r.step_policy {
            StepPolicy::Fixed => POLICY_FIXED,
            StepPolicy::TwoLevel => POLICY_TWO_LEVEL,
            StepPolicy::Adaptive => POLICY_ADAPTIVE,
        },
        near_steps: r.near_steps,
        far_steps: r.far_steps,
        skip_empty: r.skip_empty as u32,
        tau_target: r.tau_target,
        near_fraction: r.near_fraction,
        min_step: 0.25 * step,
        max_step: 4.0 * step,
        surface_count,
        row_offset: 0,
        sun_count: project.lights.iter().filter(|l| matches!(l.kind, LightKind::Directional { .. })).count() as u32,
        col_offset: 0,
        list_offset: 0,
        list_end: 0,
        lattice_stride: 0,
        padded_width: 0,
        padded_height: 0,
        scatter_factor: scatter_factor(project),
        _pad: [0; 2],
    }
}

/// The multiple-scattering settings that add light: none without them, without albedo or at
/// strength 0, so that those render exactly as single scattering.
pub fn multiple_scattering_of(project: &Project) -> Option<MultipleScattering> {
    project.medium.multiple_scattering.filter(|m| m.strength > 0.0 && project.medium.albedo > 0.0)
}

/// Fine cells per coarse cell edge of the multiple-scattering grid
/// ([`MultipleScattering::factor`]); 0 without multiple scattering.
fn scatter_factor(project: &Project) -> u32 {
    multiple_scattering_of(project).map_or(0, |m| m.factor(&project.grid))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::shadowed;
    use crate::scene::{Ground, SurfaceBox, Surfaces};
    use glam::{DVec3, Vec3};

    use crate::rng::Lcg;

    /// The surfaces a light's mask leaves out never block a path from the grid box to it
    /// (the exact f64 test, [`shadowed`]): random boxes inside, across, outside and flush with
    /// the grid box, the ground below, across and above it, point lights inside and outside it
    /// and suns from random and axis-aligned directions, each checked from points inside the
    /// box, near its faces and at its corners. The masks must also leave some surfaces out.
    #[test]
    fn culled_surfaces_never_block_a_path_from_the_grid() {
        let mut rng = Lcg(0x0cc1_d0e5);
        let (g_min, g_max) = (Vec3::new(-1.0, 0.0, -1.5), Vec3::new(1.0, 2.0, 1.0));
        let (mut culled, mut kept) = (0, 0);
        for case in 0..300 {
            let mut boxes = Vec::new();
            for k in 0..6 {
                let (min, max) = match k {
                    // Flush with a face of the grid box, on its outer side.
                    0 => {
                        let a = case % 3;
                        let (mut lo, mut hi) = (g_min - 0.2, g_max + 0.2);
                        if case % 2 == 0 {
                            lo[a] = g_max[a];
                            hi[a] = g_max[a] + 0.1;
                        } else {
                            hi[a] = g_min[a];
                            lo[a] = g_min[a] - 0.1;
                        }
                        (lo, hi)
                    }
                    _ => {
                        let c = rng.vec3(-4.0, 4.0);
                        let h = rng.vec3(0.05, 1.0);
                        (c - h, c + h)
                    }
                };
                boxes.push(SurfaceBox { min, max, ..SurfaceBox::default() });
            }
            let ground = Ground { height: rng.range(-1.0, 2.5), ..Ground::default() };
            let surfaces = Surfaces { ground: Some(ground), boxes };
            let mut light = Light::new(rng.vec3(-4.0, 4.0), 1.0, Vec3::ONE);
            if case % 4 == 1 {
                light.position = rng.vec3(-0.9, 0.9) + Vec3::Y;
            } else if case % 4 >= 2 {
                let axis = [Vec3::X, -Vec3::Y, Vec3::Z, Vec3::Y][(case / 4) % 4];
                let direction = if case % 4 == 2 { axis } else { rng.vec3(-1.0, 1.0).normalize() };
                light.kind = LightKind::Directional { direction };
            }
            let project = Project {
                grid: crate::scene::GridSpec { min: g_min, max: g_max, resolution: glam::UVec3::splat(8) },
                lights: vec![light.clone()],
                surfaces,
                ..Project::default()
            };
            let gpu = surfaces_gpu(&project);
            let mask = occluders(&light_gpu(&light, false), &gpu, g_min, g_max);
            // Just inside the corners (on a face, a path along it may graze a flush box: the
            // exception `occluders` names), then inside and just inside a face.
            let mut points: Vec<DVec3> = (0..8)
                .map(|n| {
                    let f = DVec3::new((n & 1) as f64, (n >> 1 & 1) as f64, (n >> 2 & 1) as f64) * (1.0 - 2e-6) + 1e-6;
                    g_min.as_dvec3() + f * (g_max - g_min).as_dvec3()
                })
                .collect();
            for k in 0..400 {
                let mut x = rng.vec3(0.0, 1.0);
                if k % 2 == 0 {
                    x[k / 2 % 3] = if rng.f32() < 0.5 { 1e-6 } else { 1.0 - 1e-6 };
                }
                points.push((g_min + x * (g_max - g_min)).as_dvec3());
            }
            for i in 0..gpu.len() {
                if mask >> i & 1 == 1 {
                    kept += 1;
                    continue;
                }
                culled += 1;
                let mut only = project.clone();
                only.surfaces = match project.surfaces.boxes.get(i) {
                    Some(b) => Surfaces { ground: None, boxes: vec![*b] },
                    None => Surfaces { ground: project.surfaces.ground, boxes: vec![] },
                };
                for &x in &points {
                    let (u, reach) = match light.kind {
                        LightKind::Directional { direction } => (-direction.as_dvec3().normalize(), f64::INFINITY),
                        _ => {
                            let v = light.position.as_dvec3() - x;
                            (v.normalize(), v.length())
                        }
                    };
                    assert!(
                        !shadowed(&only, x, DVec3::ZERO, u, reach),
                        "case {case}: surface {i} {:?} is culled but blocks {x} from {:?}",
                        only.surfaces,
                        light.kind
                    );
                }
            }
        }
        println!("{culled} surfaces culled, {kept} kept");
        assert!(culled > 600 && kept > 300, "{culled} culled, {kept} kept");
    }

    /// The demos' masks: in the Cornell box both lights are inside the room, so the walls
    /// (flush with the grid box) are culled and only the block is tested; on the street the
    /// buildings and the road lie outside the grid box or below the lights.
    #[test]
    fn the_demos_test_only_surfaces_between_the_box_and_the_lights() {
        let mask = |name: &str| {
            let p = crate::demos::demo(name).unwrap();
            let surfaces = surfaces_gpu(&p);
            p.lights
                .iter()
                .map(|l| occluders(&light_gpu(l, false), &surfaces, p.grid.min, p.grid.max))
                .collect::<Vec<_>>()
        };
        assert_eq!(mask("cornell"), [1 << 5, 1 << 5]);
        assert_eq!(mask("street"), [0; 5]);
        assert_eq!(mask("room"), [1 << 4, 1 << 4]);
    }
}

//! What the benchmark suites share: the pipeline they time, the options they were run with,
//! loading the scenes they measure (the bundled demos at `--frame`, resized grids, the large
//! scene of small particles) and the propagation schemes `--scheme` names. Every suite
//! depends on this file and on none of the others for its setup.

use super::{BenchError, BenchOptions};
use crate::demos::demo;
use crate::gpu::{FogPipeline, FrameReport, FrameRequest, GpuContext};
use crate::rng::Lcg;
use crate::scene::{Light, Particle, Project, Scheme};
use glam::{UVec3, Vec3};

/// The scene name of 10⁵ small particles (`scale`'s scene on a 64³ grid, 2 lights), run
/// with the preview at ¼ of the viewport's pixels.
pub const LARGE_SCENE: &str = "large";

/// The pipeline and the options every suite runs with.
pub struct Context {
    pub(super) gpu: FogPipeline,
    pub(super) quick: bool,
    pub(super) resolutions: Vec<u32>,
    pub(super) scenes: Vec<String>,
    pub(super) schemes: Vec<String>,
    /// The frame of an animated demo the suites bake (`--frame`).
    frame: Option<i32>,
    /// What the suites' marches use (`--image-sampling`).
    pub(super) image_sampling: crate::gpu::ImageSampling,
}

impl Context {
    pub fn new(opts: &BenchOptions) -> Result<Self, BenchError> {
        let large = LARGE_SCENE;
        if let Some(bad) = opts.scenes.iter().find(|s| {
            *s != large
                && !crate::demos::DEMOS.iter().any(|(name, _)| name == s)
                && !super::shapes::NAMES.contains(&s.as_str())
        }) {
            let known: Vec<&str> = crate::demos::DEMOS.iter().map(|(name, _)| *name).chain([large]).collect();
            return Err(BenchError::Option(format!(
                "--scene {bad}: not a bundled demo, `{large}` (10⁵ particles, interaction only) or a case of the shapes suite; use one of {}, or of {}",
                known.join(", "),
                super::shapes::NAMES.join(", ")
            )));
        }
        if let Some(bad) = opts.schemes.iter().find(|s| !OPV_SCHEMES.iter().any(|&(_, label)| label == s.as_str())) {
            let known: Vec<&str> = OPV_SCHEMES.iter().map(|&(_, label)| label).collect();
            return Err(BenchError::Option(format!(
                "--scheme {bad}: not a scheme of the propagation suite; use one of {}",
                known.join(", ")
            )));
        }
        if let Some(f) = opts.frame {
            check_frame(f, &opts.scenes)?;
        }
        let mut gpu = FogPipeline::new(GpuContext::new_headless()?);
        gpu.set_image_sampling(opts.image_sampling);
        Ok(Self {
            gpu,
            image_sampling: opts.image_sampling,
            quick: opts.quick,
            resolutions: opts.resolutions.clone(),
            scenes: opts.scenes.clone(),
            schemes: opts.schemes.clone(),
            frame: opts.frame,
        })
    }

    /// The demo `name`; an animated one at `--frame`, or at its first frame.
    pub(super) fn demo(&self, name: &str) -> Result<Project, BenchError> {
        let p = demo(name)?;
        Ok(match p.animation {
            Some(a) => p.at_frame(self.frame.unwrap_or(a.start)),
            None => p,
        })
    }

    /// Bakes and renders `project` from scratch.
    pub(super) fn full(&mut self, project: &Project, width: u32, height: u32) -> Result<FrameReport, BenchError> {
        let request = FrameRequest { width, height, scheme: project.propagation.scheme, force: true };
        Ok(self.gpu.update(project, &request)?)
    }

    /// Brings the pipeline up to date with `project`, rerunning only what changed.
    pub(super) fn incremental(
        &mut self,
        project: &Project,
        width: u32,
        height: u32,
    ) -> Result<FrameReport, BenchError> {
        let request = FrameRequest { width, height, scheme: project.propagation.scheme, force: false };
        Ok(self.gpu.update(project, &request)?)
    }
}

/// `--frame f` needs `--scene` to name an animated demo, and f within each animated one's range.
fn check_frame(f: i32, scenes: &[String]) -> Result<(), BenchError> {
    let mut animated = Vec::new();
    for (name, _) in crate::demos::DEMOS {
        if let Some(a) = demo(name)?.animation {
            if scenes.iter().any(|s| s == name) && !a.frames().contains(&f) {
                return Err(BenchError::Option(format!(
                    "--frame {f}: outside the demo {name}'s animation range {}-{}",
                    a.start, a.end
                )));
            }
            animated.push(name);
        }
    }
    if !scenes.iter().any(|s| animated.contains(&s.as_str())) {
        return Err(BenchError::Option(format!(
            "--frame {f}: no animated demo among --scene {}; name one of {}",
            if scenes.is_empty() { "(none given)".to_string() } else { scenes.join(",") },
            animated.join(", ")
        )));
    }
    Ok(())
}

/// The project with its grid's longest axis at `longest` cells, the others in proportion.
pub(super) fn with_resolution(project: &Project, longest: u32) -> Project {
    let mut p = project.clone();
    let size = p.grid.size();
    let scale = longest as f32 / size.max_element();
    p.grid.resolution = (size * scale).round().as_uvec3().max(UVec3::ONE);
    p
}

pub(super) fn image_size(project: &Project, width: u32) -> (u32, u32) {
    let h = (width as f32 * project.render.height as f32 / project.render.width as f32).round() as u32;
    (width, h.max(1))
}

/// The propagation suite's schemes, (scheme, sweep stride, sweep_refine), by record label.
pub(super) const OPV_SCHEMES: [((Scheme, u32, bool), &str); 7] = [
    ((Scheme::Giroud, 4, false), "giroud"),
    ((Scheme::Sweep, 4, false), "sweep4"),
    ((Scheme::Sweep, 4, true), "sweep4r"),
    ((Scheme::Sweep, 8, false), "sweep8"),
    ((Scheme::Sweep, 8, true), "sweep8r"),
    ((Scheme::Exact, 4, false), "exact"),
    ((Scheme::Analytic, 4, false), "analytic"),
];

/// `count` small particles (radius 0.02–0.06 m, the dabs of detailed painting) spread
/// uniformly through a 4 m box, `lights` lights around it, on a `res`³ grid.
pub fn small_particle_scene(count: usize, lights: usize, res: u32) -> Project {
    let mut p = Project::default();
    p.grid.min = Vec3::splat(-2.0);
    p.grid.max = Vec3::splat(2.0);
    p.grid.resolution = UVec3::splat(res);
    p.medium.base_extinction = 0.01;
    let mut rng = Lcg(0x9E37_79B9_7F4A_7C15);
    let mut rnd = || rng.f32();
    p.particles = (0..count)
        .map(|_| {
            let c = Vec3::new(rnd(), rnd(), rnd()) * 4.0 - 2.0;
            Particle::new(c, 0.02 + 0.04 * rnd(), 0.5 + 3.0 * rnd())
        })
        .collect();
    p.lights = (0..lights)
        .map(|l| {
            let a = l as f32 / lights.max(1) as f32 * std::f32::consts::TAU;
            Light::new(Vec3::new(1.6 * a.cos(), 1.7, 1.6 * a.sin()), 4.0, Vec3::ONE)
        })
        .collect();
    p.camera.position = Vec3::new(0.8, 1.2, 7.0);
    p.camera.target = Vec3::ZERO;
    p
}

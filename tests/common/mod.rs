//! Helpers shared by the integration tests.
#![allow(dead_code)]

use fogsmith::gpu::{FogPipeline, GpuContext};
use fogsmith::scene::{Camera, GridSpec, Light, Medium, Particle, Project};
use glam::{UVec3, Vec3};

/// The real pipeline on whatever adapter wgpu finds (lavapipe on CI). A missing adapter
/// fails the test loudly: GPU tests are never skipped.
pub fn pipeline() -> FogPipeline {
    fogsmith::cli::ensure_runtime_dir();
    match GpuContext::new_headless() {
        Ok(ctx) => FogPipeline::new(ctx),
        Err(e) => panic!("GPU tests need an adapter and none is available: {e}"),
    }
}

/// A small cloud of gaussians in a unit-ish box with one or more lights.
pub fn small_scene(res: u32, lights: &[Vec3]) -> Project {
    let mut p = Project {
        grid: GridSpec {
            min: Vec3::new(-1.0, -1.0, -1.0),
            max: Vec3::new(1.0, 1.0, 1.0),
            resolution: UVec3::splat(res),
        },
        medium: Medium { base_extinction: 0.05, albedo: 0.8, anisotropy: 0.0, ..Medium::default() },
        particles: vec![
            Particle::new(Vec3::new(0.0, 0.0, 0.0), 0.35, 4.0),
            Particle::new(Vec3::new(0.4, -0.2, 0.1), 0.25, 6.0),
            Particle::new(Vec3::new(-0.45, 0.3, -0.2), 0.3, 3.0),
            Particle::new(Vec3::new(0.1, 0.5, 0.4), 0.2, 8.0),
        ],
        lights: lights.iter().map(|&pos| Light::new(pos, 5.0, Vec3::new(1.0, 0.9, 0.8))).collect(),
        ..Project::default()
    };
    p.camera = Camera { position: Vec3::new(0.3, 0.4, 3.5), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 };
    p.render.width = 48;
    p.render.height = 36;
    p
}

/// A grid filled with base fog only.
pub fn homogeneous_scene(res: u32, beta: f32, light: Vec3) -> Project {
    let mut p = small_scene(res, &[light]);
    p.particles.clear();
    p.medium.base_extinction = beta;
    p
}

/// A small deterministic generator (xorshift) for randomized scenes.
pub struct Rng(pub u64);

impl Rng {
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.f()
    }
    /// Each component in [a, b).
    pub fn v(&mut self, a: f32, b: f32) -> Vec3 {
        Vec3::new(self.range(a, b), self.range(a, b), self.range(a, b))
    }
    /// A random unit direction.
    pub fn dir(&mut self) -> Vec3 {
        loop {
            let v = self.v(-1.0, 1.0);
            if v.length() > 0.2 && v.length() < 1.0 {
                return v.normalize();
            }
        }
    }
}

/// The project's root folder.
pub fn root() -> &'static std::path::Path {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The test venv's Python (./setup.sh), which must import `module`: a missing venv or
/// module fails the test loudly, naming what is missing and the fix.
pub fn venv_python(module: &str) -> std::path::PathBuf {
    let py = root().join(".venv/bin/python");
    let ok = std::process::Command::new(&py)
        .args(["-c", &format!("import {module}")])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(
        ok,
        "this test needs `{module}` in the project's test venv ({}), which is missing: run ./setup.sh",
        py.display()
    );
    py
}

/// Runs `cmd` and returns its stdout; a failure panics with `what` and its output.
pub fn run_ok(cmd: &mut std::process::Command, what: &str) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{what}: {e}"));
    assert!(
        out.status.success(),
        "{what} failed: {}\n{}",
        String::from_utf8_lossy(&out.stderr),
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// Linear RGB of a `width`×`height` EXR render (R, G and B channels), rows top to bottom.
pub fn read_exr_rgb(path: &std::path::Path, width: usize, height: usize) -> Vec<[f32; 3]> {
    use exr::prelude::read_all_flat_layers_from_file;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (width, height), "{}", path.display());
    let ch = |name: &str| -> Vec<f32> {
        let c = layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.to_string() == name)
            .unwrap_or_else(|| panic!("{}: no channel {name}", path.display()));
        c.sample_data.values_as_f32().collect()
    };
    let (r, g, b) = (ch("R"), ch("G"), ch("B"));
    (0..width * height).map(|n| [r[n], g[n], b[n]]).collect()
}

/// RGB from a raw little-endian f32 file of `width`×`height` pixels (the Blender scripts' output).
pub fn read_f32_rgb(path: &std::path::Path, width: usize, height: usize) -> Vec<[f32; 3]> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(bytes.len(), width * height * 12, "{}", path.display());
    bytes
        .chunks_exact(12)
        .map(|c| [0, 1, 2].map(|i| f32::from_le_bytes(c[4 * i..4 * i + 4].try_into().unwrap())))
        .collect()
}

//! The scene model: what an artist authors, independent of GPUs and of the editor.
//!
//! A [`Project`] holds the medium (a base fog, homogeneous or exponential in height, plus
//! gaussian particles), point, spot and directional lights, the grid the medium is baked on,
//! the camera and render settings.
//! Units follow `physics.md`: metres, extinction in 1/m, radiant intensity in W/sr.
//! Every optional field has a default documented on its type, so a project file only
//! needs what differs from the defaults. [`io`] loads and saves projects as RON.

pub mod animation;
mod fit;
mod ids;
pub mod io;
mod light_edit;
pub mod recovery;
pub mod sidecar;
mod validate;
mod volume;

pub use animation::{Animation, Channel, Interp, Key, KeyError, KeyValue, Object, Prop, Track, ValueKind};
pub use fit::{FitKeep, SUPPORT_FRACTION};
pub use ids::NextIds;
pub use io::{load_project, load_project_with, parse_project, save_project, ProjectError};
pub use light_edit::{LightKindChoice, DEFAULT_SPOT_ANGLE_DEG, DEFAULT_SPOT_BLEND};
pub use validate::{
    validations_on_this_thread, ValidationError, MAX_COORDINATE, MAX_EXTINCTION, MAX_HEIGHT_FALLOFF, MAX_INTENSITY,
    MAX_NOISE_AMPLITUDE, MAX_RESOLUTION_DEFAULT,
};
pub use volume::{Volume, Volume3};

use glam::{UVec3, Vec3};
use serde::{Deserialize, Serialize};

/// The project format version this build writes. Older versions are migrated on load
/// (version 1 had no ids: its particles and lights get their list positions; version 2 had
/// no animation and loads as a still).
pub const PROJECT_VERSION: u32 = 3;

/// A whole fog scene, as saved in a `.ron` project file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Project {
    /// File format version; see [`PROJECT_VERSION`]. A file without one is read as version 1
    /// (hand-written files need no ids: they get their list positions).
    #[serde(default = "io::unversioned")]
    pub version: u32,
    pub grid: GridSpec,
    pub medium: Medium,
    pub particles: Vec<Particle>,
    pub lights: Vec<Light>,
    pub camera: Camera,
    pub render: RenderSettings,
    pub propagation: PropagationSettings,
    pub surfaces: Surfaces,
    /// A density grid imported from a VDB file, resampled into the grid under the
    /// particles. Default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_volume: Option<BaseVolume>,
    /// The ids the next new particle and light get (see [`NextIds`]).
    pub next_id: NextIds,
    /// The frame range and rate; None (the default): the project is a still. See
    /// [`animation`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub animation: Option<Animation>,
    /// Keyframe tracks, one per animated value (see [`animation`]). Default none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tracks: Vec<Track>,
    /// Where a file's particles are when they are not in its RON (see [`sidecar`]): written
    /// by saving, consumed by loading, so always None in a loaded project.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particle_file: Option<sidecar::ParticleFile>,
}

/// A VDB density grid used as a base layer of the extinction volume.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BaseVolume {
    /// The .vdb file; a relative path is relative to the project file's directory.
    pub path: std::path::PathBuf,
    /// Name of the float grid to read. Default "density".
    #[serde(default = "density_name")]
    pub grid: String,
    /// Multiplier turning the grid's values into extinction (1/m). Default 1.
    #[serde(default = "one")]
    pub scale: f32,
}

fn density_name() -> String {
    "density".into()
}

fn one() -> f32 {
    1.0
}

impl BaseVolume {
    /// The file to read, resolving a relative path against `project_dir`.
    pub fn resolved_path(&self, project_dir: Option<&std::path::Path>) -> std::path::PathBuf {
        match project_dir {
            Some(dir) if self.path.is_relative() => dir.join(&self.path),
            _ => self.path.clone(),
        }
    }
}

impl Project {
    /// A copy of everything but the particles, without touching them: what saving writes
    /// into the RON when the particles go to a sidecar, and what undo keeps per step.
    pub fn without_particles(&self) -> Project {
        let Project {
            version,
            grid,
            medium,
            particles: _,
            lights,
            camera,
            render,
            propagation,
            surfaces,
            base_volume,
            next_id,
            animation,
            tracks,
            particle_file,
        } = self;
        Project {
            version: *version,
            grid: *grid,
            medium: *medium,
            particles: Vec::new(),
            lights: lights.clone(),
            camera: *camera,
            render: *render,
            propagation: *propagation,
            surfaces: surfaces.clone(),
            base_volume: base_volume.clone(),
            next_id: *next_id,
            animation: *animation,
            tracks: tracks.clone(),
            particle_file: particle_file.clone(),
        }
    }
}

impl Project {
    /// A new, empty project as the editor's File > New makes it: the defaults, with multiple
    /// scattering on.
    pub fn new_empty() -> Self {
        let mut project = Self::default();
        project.medium.multiple_scattering = Some(MultipleScattering::default());
        project
    }
}

impl Default for Project {
    fn default() -> Self {
        Self {
            version: PROJECT_VERSION,
            grid: GridSpec::default(),
            medium: Medium::default(),
            particles: Vec::new(),
            lights: Vec::new(),
            camera: Camera::default(),
            render: RenderSettings::default(),
            propagation: PropagationSettings::default(),
            surfaces: Surfaces::default(),
            base_volume: None,
            next_id: NextIds::default(),
            animation: None,
            tracks: Vec::new(),
            particle_file: None,
        }
    }
}

/// The axis-aligned box the medium is baked on. Cell `(i, j, k)` is centred at
/// `min + (index + 0.5) * cell_size()`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridSpec {
    pub min: Vec3,
    pub max: Vec3,
    /// Cells along x, y, z. Default 64³.
    pub resolution: UVec3,
}

impl Default for GridSpec {
    fn default() -> Self {
        Self { min: Vec3::new(-2.0, 0.0, -2.0), max: Vec3::new(2.0, 4.0, 2.0), resolution: UVec3::splat(64) }
    }
}

impl GridSpec {
    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }
    pub fn cell_size(&self) -> Vec3 {
        self.size() / self.resolution.as_vec3()
    }
    pub fn cell_count(&self) -> u64 {
        self.resolution.x as u64 * self.resolution.y as u64 * self.resolution.z as u64
    }
    pub fn cell_center(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.min + (UVec3::new(i, j, k).as_vec3() + 0.5) * self.cell_size()
    }
    /// Cell (i, j, k) of a linear index: the inverse of [`index`](Self::index).
    pub fn cell_of(&self, index: usize) -> [u32; 3] {
        let (nx, ny) = (self.resolution.x as usize, self.resolution.y as usize);
        [(index % nx) as u32, ((index / nx) % ny) as u32, (index / (nx * ny)) as u32]
    }

    /// Linear index of cell (i, j, k), x fastest.
    pub fn index(&self, i: u32, j: u32, k: u32) -> usize {
        let r = self.resolution;
        (i as usize) + r.x as usize * ((j as usize) + r.y as usize * k as usize)
    }
}

/// The participating medium's optical properties.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Medium {
    /// Homogeneous fog filling all space, in 1/m. Default 0.
    pub base_extinction: f32,
    /// Single-scattering albedo σ_s/σ_t in [0, 1]. Default 1.
    pub albedo: f32,
    /// Henyey–Greenstein asymmetry g in (−1, 1); 0 is isotropic. Default 0.
    pub anisotropy: f32,
    /// Exponential height fog: the base fog is β(y) = base_extinction · exp(−k·(y − y₀))
    /// with k = `height_falloff` (1/m, ≥ 0) and y₀ = `height_origin` (m). Default 0 and 0:
    /// homogeneous base fog.
    #[serde(skip_serializing_if = "is_zero")]
    pub height_falloff: f32,
    #[serde(skip_serializing_if = "is_zero")]
    pub height_origin: f32,
    /// Fractal noise modulating the particles' density (see [`Noise`]). Default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise: Option<Noise>,
    /// Light scattered more than once inside the grid (see [`MultipleScattering`]). Default
    /// none: single scattering only, as every file written before the field existed.
    /// [`Project::new`] turns it on for new projects.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub multiple_scattering: Option<MultipleScattering>,
}

/// Multiple scattering: the light scattered two or more times, solved on a coarse copy of the
/// grid by discrete ordinates (src/gpu/scattering.rs) and added to single scattering in the
/// preview, `render` and the light bake. Fog outside the grid (base fog) scatters once only.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MultipleScattering {
    /// Scattering orders solved one by one (2nd to `orders`+1-th); the rest is added as the
    /// geometric tail of the last two. 1..=64, default 8.
    pub orders: u32,
    /// Factor on the multiply scattered light: 1 is physical; artists may dim or boost it.
    /// 0..=10, default 1.
    pub strength: f32,
    /// Coarse cells per axis of a cube of the solver's cell count: its grid, coarser than the
    /// project's by one factor on every axis, holds at most `resolution`³ cells. More is
    /// slower and resolves sharper light. 4..=128, default 24.
    pub resolution: u32,
}

impl MultipleScattering {
    /// Fine cells per coarse cell edge of the solver's grid on `grid`: the smallest factor,
    /// the same on every axis, that leaves at most `resolution`³ coarse cells (so a thin grid
    /// keeps as many coarse cells as a cube, not as few as its longest axis would give).
    pub fn factor(&self, grid: &GridSpec) -> u32 {
        let budget = (self.resolution.max(1) as u64).pow(3);
        let cells = |f: u32| grid.resolution.map(|n| n.div_ceil(f)).as_u64vec3().element_product();
        let mut f = ((grid.cell_count() as f64 / budget as f64).cbrt().ceil() as u32).max(1);
        while f > 1 && cells(f - 1) <= budget {
            f -= 1;
        }
        while cells(f) > budget {
            f += 1;
        }
        f
    }
}

impl Default for MultipleScattering {
    fn default() -> Self {
        Self { orders: 8, strength: 1.0, resolution: 24 }
    }
}

impl Default for Medium {
    fn default() -> Self {
        Self {
            base_extinction: 0.0,
            albedo: 1.0,
            anisotropy: 0.0,
            height_falloff: 0.0,
            height_origin: 0.0,
            noise: None,
            multiple_scattering: None,
        }
    }
}

impl Medium {
    /// Base-fog extinction at height `y`: β₀·exp(−k·(y − y₀)), the exponent clamped so that
    /// it cannot overflow far below y₀.
    pub fn base_at(&self, y: f64) -> f64 {
        self.base_extinction as f64
            * (-(self.height_falloff as f64) * (y - self.height_origin as f64)).min(MAX_HEIGHT_EXPONENT).exp()
    }
}

/// Largest exponent −k·(y − y₀) of the height fog: far below y₀ the fog stops growing (at
/// e⁴⁰ times the base extinction, opaque within far less than a cell), so its extinction
/// stays finite in single precision.
pub const MAX_HEIGHT_EXPONENT: f64 = 40.0;

fn is_zero(v: &f32) -> bool {
    *v == 0.0
}

/// Deterministic fractal noise that modulates the particles' extinction:
/// σ_particles · max(0, 1 + amplitude · n(x − offset)). Written in a project as
/// `(amplitude, frequency, octaves, seed)`, or with wind as
/// `(amplitude, frequency, octaves, seed, (vx, vy, vz))`; a still of an animation also
/// carries its drift: `(amplitude, frequency, octaves, seed, (vx, vy, vz), (ox, oy, oz))`.
///
/// n(x) = Σ_{o < octaves} 0.5^o · v(2^o · frequency · x, seed + o) / Σ_{o < octaves} 0.5^o,
/// where v is 3D value noise on the integer lattice: v(p, s) is the trilinear interpolation,
/// with smoothstep weights 3t² − 2t³, of lattice values h(i, j, k, s) in [−1, 1],
/// h = 2·(hash(i, j, k, s) / 2³²) − 1 with hash the PCG-style integer hash of
/// [`noise_hash`]. So n lies in [−1, 1], and its smallest feature at octave o has the size
/// 1 / (2^o · frequency) metres. Octaves whose lattice is finer than two grid cells (above
/// the grid's Nyquist limit) are dropped: see [`Noise::effective_octaves`].
/// Only particles whose `noise` flag is set (the default) are modulated; the base fog and an
/// imported base volume never are. The hash works on wrapping 32-bit integers (lattice
/// indices are clamped to [−2³¹, 2³¹ − 128]), so huge seeds and coordinates stay finite.
///
/// Wind: the noise pattern drifts with `velocity` (m/s), so at time t it is evaluated at
/// x − velocity·t. The pipeline renders still projects, so [`Project::at_frame`] stores the
/// drift of its frame as `offset` = velocity·t (computed in f32); the GPU and the CPU
/// reference both evaluate n at the f32 difference x − offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Noise {
    /// Strength of the modulation; 0 leaves the particles unchanged.
    pub amplitude: f32,
    /// Lattice frequency of the first octave, in 1/m.
    pub frequency: f32,
    /// Number of octaves, 1..=16.
    pub octaves: u32,
    pub seed: u32,
    /// Wind: how fast the pattern drifts, in m/s. Default zero.
    pub velocity: Vec3,
    /// The drift of this still, in metres: n is evaluated at x − offset. Default zero; set
    /// by [`Project::at_frame`] to velocity·t.
    pub offset: Vec3,
}

impl Noise {
    /// Noise without wind or drift.
    pub fn new(amplitude: f32, frequency: f32, octaves: u32, seed: u32) -> Self {
        Self { amplitude, frequency, octaves, seed, velocity: Vec3::ZERO, offset: Vec3::ZERO }
    }
}

impl Serialize for Noise {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeTuple;
        let len = if self.offset != Vec3::ZERO {
            6
        } else if self.velocity != Vec3::ZERO {
            5
        } else {
            4
        };
        let mut t = s.serialize_tuple(len)?;
        t.serialize_element(&self.amplitude)?;
        t.serialize_element(&self.frequency)?;
        t.serialize_element(&self.octaves)?;
        t.serialize_element(&self.seed)?;
        if len >= 5 {
            t.serialize_element(&self.velocity)?;
        }
        if len == 6 {
            t.serialize_element(&self.offset)?;
        }
        t.end()
    }
}

impl<'de> Deserialize<'de> for Noise {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Noise;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("(amplitude, frequency, octaves, seed) with an optional (vx, vy, vz) wind velocity")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut seq: A) -> Result<Noise, A::Error> {
                use serde::de::Error;
                let missing = |i: usize| A::Error::invalid_length(i, &"4 to 6 elements");
                let amplitude = seq.next_element()?.ok_or_else(|| missing(0))?;
                let frequency = seq.next_element()?.ok_or_else(|| missing(1))?;
                let octaves = seq.next_element()?.ok_or_else(|| missing(2))?;
                let seed = seq.next_element()?.ok_or_else(|| missing(3))?;
                let velocity = seq.next_element()?.unwrap_or(Vec3::ZERO);
                let offset = seq.next_element()?.unwrap_or(Vec3::ZERO);
                Ok(Noise { amplitude, frequency, octaves, seed, velocity, offset })
            }
        }
        d.deserialize_tuple(6, V)
    }
}

/// Largest number of noise octaves a project may ask for.
pub const MAX_NOISE_OCTAVES: u32 = 16;

impl Noise {
    /// The octaves kept on `grid`: octave o has lattice spacing 1 / (2^o · frequency), and
    /// is kept only while that spacing is at least two cells (the smallest cell edge), so no
    /// feature is smaller than the grid can represent. At least the first octave is kept.
    pub fn effective_octaves(&self, grid: &GridSpec) -> u32 {
        let cell = grid.cell_size().min_element() as f64;
        let mut kept = 1;
        while kept < self.octaves && 1.0 / (2f64.powi(kept as i32) * self.frequency as f64) >= 2.0 * cell {
            kept += 1;
        }
        kept
    }

    /// What the grid's Nyquist limit does to this noise, in words, or None when every octave
    /// is kept and the first one is no finer than two cells: the note `render`, `export` and
    /// the editor show.
    pub fn nyquist_note(&self, grid: &GridSpec) -> Option<String> {
        let kept = self.effective_octaves(grid);
        let cell = grid.cell_size().min_element() as f64;
        let first_too_fine = 1.0 / (self.frequency as f64) < 2.0 * cell;
        let mut notes = Vec::new();
        if kept < self.octaves {
            let dropped = self.octaves - kept;
            notes.push(format!(
                "{dropped} of {} octaves above the grid's Nyquist limit are dropped; raise the resolution to keep them",
                self.octaves
            ));
        }
        if first_too_fine {
            notes.push(format!(
                "the first octave (frequency {} /m) is finer than two cells ({:.4} m) and aliases; lower the frequency or raise the resolution",
                self.frequency,
                2.0 * cell
            ));
        }
        (!notes.is_empty()).then(|| notes.join("; "))
    }
}

/// The integer hash behind [`Noise`]: a PCG output permutation applied in turn to the seed
/// and the lattice point's coordinates, so any implementation can reproduce it bit for bit.
pub fn noise_hash(i: i32, j: i32, k: i32, seed: u32) -> u32 {
    let mut h = seed.wrapping_mul(0x9E37_79B9) ^ (i as u32).wrapping_mul(0x85EB_CA6B);
    h = pcg(h) ^ (j as u32).wrapping_mul(0xC2B2_AE35);
    h = pcg(h) ^ (k as u32).wrapping_mul(0x27D4_EB2F);
    pcg(h)
}

fn pcg(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28).wrapping_add(4))) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// A gaussian blob of fog: σ_t(x) = density · exp(−|x − center|² / radius²).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Particle {
    /// Stable identifier, unique among the project's particles: the editor names the
    /// particle "Particle #id" whatever its place in the list. Default 0.
    #[serde(default)]
    pub id: u32,
    pub center: Vec3,
    /// r in exp(−d²/r²), metres; must be > 0.
    pub radius: f32,
    /// Peak extinction c, 1/m; must be ≥ 0.
    pub density: f32,
    /// Optional label shown in the editor. Default none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Hidden particles are kept in the file but contribute nothing. Default false.
    #[serde(default, skip_serializing_if = "is_false")]
    pub hidden: bool,
    /// Whether the medium's noise (see [`Noise`]) modulates this particle. Default true.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub noise: bool,
}

fn yes() -> bool {
    true
}

fn is_true(b: &bool) -> bool {
    *b
}

impl Particle {
    pub fn new(center: Vec3, radius: f32, density: f32) -> Self {
        Self { id: 0, center, radius, density, name: None, hidden: false, noise: true }
    }

    /// Distance beyond which this particle's extinction is below `epsilon` (physics.md §2):
    /// r·sqrt(ln(c/ε)), or 0 when the peak itself is below ε.
    pub fn cutoff_radius(&self, epsilon: f32) -> f32 {
        if self.density <= epsilon {
            0.0
        } else {
            self.radius * (self.density / epsilon).ln().sqrt()
        }
    }
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// What kind of light a [`Light`] is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub enum LightKind {
    /// Isotropic point light at `position`, radiant intensity `intensity` W/sr.
    #[default]
    Point,
    /// A point light whose intensity is multiplied by a cone factor (physics.md §9): full
    /// within `angle_deg`·(1 − `blend`) of `direction`, zero beyond `angle_deg` (the cone's
    /// half-angle, in (0, 90]), a smoothstep in angle between.
    Spot { direction: Vec3, angle_deg: f32, blend: f32 },
    /// A sun: parallel light travelling along `direction` (need not be normalised);
    /// `intensity` is the irradiance in W/m² on a plane facing it, before any fog, and
    /// `position` is ignored.
    Directional { direction: Vec3 },
}

impl LightKind {
    pub fn is_point(&self) -> bool {
        matches!(self, LightKind::Point)
    }
}

/// A light: a point light by default (see [`LightKind`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Light {
    /// Stable identifier, unique among the project's lights ("Light #id"). Default 0.
    #[serde(default)]
    pub id: u32,
    pub position: Vec3,
    /// Radiant intensity I in W/sr (irradiance in W/m² for a directional light); must be ≥ 0.
    pub intensity: f32,
    /// Default `Point`.
    #[serde(default, skip_serializing_if = "LightKind::is_point")]
    pub kind: LightKind,
    /// Per-channel scale of the intensity (linear RGB). Default white (1, 1, 1).
    #[serde(default = "white")]
    pub color: Vec3,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Hidden lights are kept in the file but cast no light. Default false.
    #[serde(default, skip_serializing_if = "is_false")]
    pub hidden: bool,
}

impl Light {
    pub fn new(position: Vec3, intensity: f32, color: Vec3) -> Self {
        Self { id: 0, position, intensity, color, kind: LightKind::Point, name: None, hidden: false }
    }
    /// Radiant intensity per RGB channel.
    pub fn radiance_rgb(&self) -> Vec3 {
        self.color * self.intensity
    }

    /// The spot's cone factor towards `x` (1 for other kinds): with θ the angle between the
    /// axis and x − position, t = clamp((A − θ)/(A·B), 0, 1) and factor t²(3 − 2t) (physics.md §9).
    pub fn cone_factor(&self, x: glam::DVec3) -> f64 {
        match self.kind {
            LightKind::Spot { direction, angle_deg, blend } => {
                cone_factor(direction.as_dvec3(), angle_deg as f64, blend as f64, x - self.position.as_dvec3())
            }
            _ => 1.0,
        }
    }
}

impl Light {
    /// Whether any of this light can fall inside the box [min, max]: false only for a spot
    /// whose cone provably misses it (its cone factor is 0 on the whole box), so the box's
    /// optical depths towards it are never needed. Conservative: the cone is tested against
    /// the box's bounding sphere and against the half-space behind the apex, with a margin.
    pub fn reaches_box(&self, min: Vec3, max: Vec3) -> bool {
        let LightKind::Spot { direction, angle_deg, .. } = self.kind else { return true };
        let (min, max, s) = (min.as_dvec3(), max.as_dvec3(), self.position.as_dvec3());
        let axis = direction.as_dvec3().normalize_or_zero();
        if axis == glam::DVec3::ZERO {
            return true;
        }
        let center = 0.5 * (min + max);
        let radius = 0.5 * (max - min).length();
        let v = center - s;
        let dist = v.length();
        if dist <= radius * (1.0 + 1e-6) {
            return true;
        }
        let margin = 1e-3;
        let phi = (axis.dot(v) / dist).clamp(-1.0, 1.0).acos();
        if phi - (radius / dist).asin() > (angle_deg as f64).to_radians() + margin {
            return false;
        }
        // The cone (half-angle ≤ 90°) lies in front of the plane through the apex.
        let behind = (0..8).all(|n| {
            let corner = glam::DVec3::new(
                if n & 1 == 0 { min.x } else { max.x },
                if n & 2 == 0 { min.y } else { max.y },
                if n & 4 == 0 { min.z } else { max.z },
            );
            axis.dot(corner - s) < -margin * radius
        });
        !behind
    }
}

/// Cone factor of a spot with axis `axis`, half-angle `angle_deg` and blend `blend` at offset
/// `v` from its apex (physics.md §9). A hard edge (blend 0) is 1 inside the cone, 0 outside.
pub fn cone_factor(axis: glam::DVec3, angle_deg: f64, blend: f64, v: glam::DVec3) -> f64 {
    let (la, lv) = (axis.length(), v.length());
    if la == 0.0 || lv == 0.0 {
        return 1.0;
    }
    let cos = (axis.dot(v) / (la * lv)).clamp(-1.0, 1.0);
    let theta = cos.acos();
    let a = angle_deg.to_radians();
    if blend <= 0.0 {
        return if theta <= a { 1.0 } else { 0.0 };
    }
    let t = ((a - theta) / (a * blend)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

fn white() -> Vec3 {
    Vec3::ONE
}

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Camera {
    pub position: Vec3,
    pub target: Vec3,
    /// Default +y.
    pub up: Vec3,
    /// Vertical field of view in degrees, in (0, 180). Default 40.
    pub fov_y_deg: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Self { position: Vec3::new(0.0, 2.0, 7.0), target: Vec3::new(0.0, 1.5, 0.0), up: Vec3::Y, fov_y_deg: 40.0 }
    }
}

impl Camera {
    /// Orthonormal basis (right, up, forward) of the view.
    pub fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let forward = (self.target - self.position).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        (right, up, forward)
    }

    /// Unit direction of the ray through the centre of pixel (px, py) of a
    /// `width`×`height` image, row 0 at the top.
    pub fn ray_dir(&self, px: u32, py: u32, width: u32, height: u32) -> Vec3 {
        let (right, up, forward) = self.basis();
        let tan_half = (self.fov_y_deg.to_radians() * 0.5).tan();
        let aspect = width as f32 / height as f32;
        let sx = ((px as f32 + 0.5) / width as f32 * 2.0 - 1.0) * tan_half * aspect;
        let sy = (1.0 - (py as f32 + 0.5) / height as f32 * 2.0) * tan_half;
        (forward + right * sx + up * sy).normalize()
    }
}

/// How samples are placed along camera rays inside the grid.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum StepPolicy {
    /// Uniform steps of `step_factor` cells.
    Fixed,
    /// Tan et al.: `near_steps` uniform steps over the first `near_fraction` of the ray's path
    /// through the grid, then `far_steps` linearly growing steps.
    TwoLevel,
    /// Steps of `tau_target` / (largest σ_t in the 8³ brick × √transmittance so far) and at
    /// most a tenth of the distance to the nearest light, between ¼ and 4× `step_factor`
    /// cells, so each step's contribution to the pixel's error and the change of incoming
    /// light across it stay bounded.
    #[default]
    Adaptive,
}

/// How the preview image is rendered.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RenderSettings {
    /// Output size in pixels. Default 640×360.
    pub width: u32,
    pub height: u32,
    /// Ray-march step as a fraction of the smallest cell edge. Default 0.5.
    pub step_factor: f32,
    /// Multiplier on linear radiance before tone mapping (PNG and display). Default 1.
    pub exposure: f32,
    /// Default `adaptive`.
    pub step_policy: StepPolicy,
    /// Optical thickness per step of the adaptive policy where the ray's transmittance is 1
    /// (it grows as 1/√transmittance). Default 0.05.
    pub tau_target: f32,
    /// Two-level policy: uniform near steps (default 48), growing far steps (default 24) and
    /// the fraction of the path covered by the near level (default 0.35).
    pub near_steps: u32,
    pub far_steps: u32,
    pub near_fraction: f32,
    /// Jump over bricks with no extinction at all (exact). Default true.
    pub skip_empty: bool,
    /// A ray stops once its transmittance is below this: the radiance still to come is at
    /// most this fraction of what the rest of the ray would add unattenuated. Default 1e-4.
    pub transmittance_cutoff: f32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 360,
            step_factor: 0.5,
            exposure: 1.0,
            step_policy: StepPolicy::default(),
            tau_target: 0.05,
            near_steps: 48,
            far_steps: 24,
            near_fraction: 0.35,
            skip_empty: true,
            transmittance_cutoff: 1e-4,
        }
    }
}

/// Opaque surfaces (diffuse, optionally with a Phong-specular part) that stop camera rays and
/// receive light through the fog.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct Surfaces {
    /// An infinite ground plane. Default none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ground: Option<Ground>,
    /// Axis-aligned boxes (walls, blocks). Default none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub boxes: Vec<SurfaceBox>,
}

/// Where a ray first meets a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    pub t: f64,
    pub normal: glam::DVec3,
    pub albedo: glam::DVec3,
    /// Phong specular reflectance and exponent.
    pub specular: f64,
    pub phong_exponent: f64,
}

impl Surfaces {
    pub fn is_empty(&self) -> bool {
        self.ground.is_none() && self.boxes.is_empty()
    }

    /// The first surface along `origin + t·dir` (t > 0), by the rules the GPU march uses:
    /// boxes are hit only from outside, the ground only from above.
    pub fn first_hit(&self, origin: glam::DVec3, dir: glam::DVec3) -> Option<SurfaceHit> {
        use glam::DVec3;
        let mut best: Option<SurfaceHit> = None;
        let mut consider = |hit: SurfaceHit| {
            if best.is_none_or(|b| hit.t < b.t) {
                best = Some(hit);
            }
        };
        if let Some(g) = &self.ground {
            let h = g.height as f64;
            if dir.y < 0.0 && origin.y > h {
                consider(SurfaceHit {
                    t: (h - origin.y) / dir.y,
                    normal: DVec3::Y,
                    albedo: g.albedo.as_dvec3(),
                    specular: g.specular as f64,
                    phong_exponent: g.phong_exponent as f64,
                });
            }
        }
        for b in &self.boxes {
            let inv = dir.recip();
            let ta = (b.min.as_dvec3() - origin) * inv;
            let tb = (b.max.as_dvec3() - origin) * inv;
            let (tn, tf) = (ta.min(tb), ta.max(tb));
            let t_in = tn.max_element();
            let t_out = tf.min_element();
            if t_in > 0.0 && t_in <= t_out {
                let axis = if t_in == tn.x {
                    0
                } else if t_in == tn.y {
                    1
                } else {
                    2
                };
                let mut normal = DVec3::ZERO;
                normal[axis] = -dir[axis].signum();
                consider(SurfaceHit {
                    t: t_in,
                    normal,
                    albedo: b.albedo.as_dvec3(),
                    specular: b.specular as f64,
                    phong_exponent: b.phong_exponent as f64,
                });
            }
        }
        best
    }
}

/// The plane y = `height`, lit from above.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Ground {
    pub height: f32,
    /// Diffuse albedo per channel in [0, 1]. Default 0.5 grey.
    #[serde(default = "grey")]
    pub albedo: Vec3,
    /// Phong specular reflectance k_s in [0, 1], added to the diffuse part: the surface
    /// reflects k_s·(n + 1)/(2π)·cos^n α times the incoming radiance per steradian, α the angle
    /// between the incoming direction and the mirror direction of the view, both for the
    /// lights' direct light and for the fog's glow (Sun et al.'s surface term). Default 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub specular: f32,
    /// Phong exponent n in [0, 1000]: larger is a sharper highlight. Default 32.
    #[serde(default = "default_phong_exponent", skip_serializing_if = "is_default_phong_exponent")]
    pub phong_exponent: f32,
}

impl Default for Ground {
    fn default() -> Self {
        Self { height: 0.0, albedo: grey(), specular: 0.0, phong_exponent: default_phong_exponent() }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SurfaceBox {
    pub min: Vec3,
    pub max: Vec3,
    /// Diffuse albedo per channel in [0, 1]. Default 0.5 grey.
    #[serde(default = "grey")]
    pub albedo: Vec3,
    /// Phong specular reflectance in [0, 1], as [`Ground::specular`]. Default 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub specular: f32,
    /// Phong exponent in [0, 1000], as [`Ground::phong_exponent`]. Default 32.
    #[serde(default = "default_phong_exponent", skip_serializing_if = "is_default_phong_exponent")]
    pub phong_exponent: f32,
}

impl Default for SurfaceBox {
    fn default() -> Self {
        Self {
            min: Vec3::ZERO,
            max: Vec3::ONE,
            albedo: grey(),
            specular: 0.0,
            phong_exponent: default_phong_exponent(),
        }
    }
}

fn grey() -> Vec3 {
    Vec3::splat(0.5)
}

fn default_phong_exponent() -> f32 {
    32.0
}

fn is_default_phong_exponent(v: &f32) -> bool {
    *v == default_phong_exponent()
}

/// How optical depth towards each light is propagated through the grid.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Scheme {
    /// Giroud & Biri's 6-neighbour gather, iterated over the whole grid until converged:
    /// O(N⁴) per light.
    Giroud,
    /// Upwind short-characteristics sweep in wavefronts from the light: each cell computed
    /// once, O(N³) per light, little numerical diffusion.
    #[default]
    Sweep,
    /// Every cell marches straight to the light: reference quality, O(N⁴) per light.
    Exact,
    /// Every cell integrates the particles along its path to the light in closed form (erf),
    /// brick by brick over the particles each 8³ brick lists, and the base and height fog in
    /// closed form: exact at cell centres whatever the resolution, where the other schemes
    /// integrate the grid's medium. Cost grows with the particles listed along each path, so
    /// it suits sparse scenes; not for medium noise or an imported base volume, which only
    /// the grid holds.
    Analytic,
}

impl std::fmt::Display for Scheme {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Scheme::Giroud => "giroud",
            Scheme::Sweep => "sweep",
            Scheme::Exact => "exact",
            Scheme::Analytic => "analytic",
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PropagationSettings {
    /// Default `sweep`.
    pub scheme: Scheme,
    /// Layers the `sweep` scheme steps back per interpolation, 3..=16: larger is less
    /// diffusive and costs more per cell. Default 8 (`fogsmith bench --suite opv` compares 4
    /// and 8).
    pub sweep_stride: u32,
    /// Whether the `sweep` scheme controls the error of its interpolations: each one whose
    /// estimated error in transmittance exceeds `sweep_tolerance` is taken from a farther
    /// plane or replaced by the direct integral of the cell's path. Default true. Off, the
    /// sweep is faster (`fogsmith bench --suite opv` measures both) but up to a few 1e-2 off
    /// in the shadows of particles a cell or two wide.
    pub sweep_refine: bool,
    /// The largest estimated transmittance error `sweep_refine` accepts per interpolation,
    /// within 1e-6..=0.1. Default 5e-4; the worst error along a ray is a small multiple of it
    /// (tests/placements.rs measures the classes of light placement): lower it for final
    /// bakes of finely painted fog, raise it for speed.
    pub sweep_tolerance: f32,
}

/// `PropagationSettings::sweep_tolerance`'s default.
pub const DEFAULT_SWEEP_TOLERANCE: f32 = 5e-4;

/// The values `PropagationSettings::sweep_tolerance` may take.
pub const SWEEP_TOLERANCE_RANGE: std::ops::RangeInclusive<f32> = 1e-6..=0.1;

impl PropagationSettings {
    /// The tolerance of the sweep's error control, if `sweep_refine` turns it on.
    pub fn refine_tolerance(&self) -> Option<f32> {
        self.sweep_refine.then_some(self.sweep_tolerance)
    }
}

impl Default for PropagationSettings {
    fn default() -> Self {
        Self {
            scheme: Scheme::default(),
            sweep_stride: 8,
            sweep_refine: true,
            sweep_tolerance: DEFAULT_SWEEP_TOLERANCE,
        }
    }
}

impl Project {
    pub fn visible_particles(&self) -> impl Iterator<Item = &Particle> {
        self.particles.iter().filter(|p| !p.hidden)
    }
    pub fn visible_lights(&self) -> impl Iterator<Item = &Light> {
        self.lights.iter().filter(|l| !l.hidden)
    }
}

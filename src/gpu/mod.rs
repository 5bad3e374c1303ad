//! The GPU pipeline: the only module that talks to wgpu.
//!
//! Three compute stages turn a [`Project`](crate::scene::Project) into an image:
//! 1. **Injection** (`shaders/inject.wgsl`): particles, binned on the CPU into 8³ bricks by
//!    their cut-off spheres, are summed with the base fog into the extinction volume (EV), an
//!    r32float 3D texture of σ_t at cell centres. On software adapters the host sums the
//!    particles itself (`host_sums`, `shaders/inject_sums.wgsl`).
//! 2. **Opacity propagation** (`shaders/propagate_*.wgsl`): for each light, an optical
//!    depth volume (OPV) of T(cell, light), in slabs of r32float 3D textures, by
//!    Giroud & Biri's iterated gather, an upwind wavefront sweep, or a brute-force march.
//! 3. **Ray march** (`shaders/march.wgsl`): single scattering along camera rays with
//!    exact per-step integration, writing linear HDR radiance and a tone-mapped copy. By
//!    default it marches a refined lattice of rays and interpolates the rest
//!    (`image_sampling`, `shaders/image_refine.wgsl`).
//!
//! On request, the bake (`baking`, `shaders/bake.wgsl`) turns the EV and OPVs into each cell's
//! emitted radiance through the march's own lookups, for engines without self-shadowing, and
//! renders that bake as an engine would, with no lights (`shaders/as_baked.wgsl`).
//!
//! Each pipeline's WGSL is assembled in `shaders` from the files in `shaders/`, after the
//! constants Rust and WGSL share (`layout::shared_constants`).
//!
//! The module is layered, each file importing only those below it:
//! - [`FogPipeline`] (`pipeline`) is the scheduler: it decides what runs within a budget and
//!   in what order, tracks which inputs each stage last consumed (`keys`) and reruns only what
//!   a change invalidates. It translates the project once per call (`frame_inputs`), checks
//!   it against the adapter (`limits`), sizes work items by `budget` and reads its
//!   measurement switches from [`Tuning`] (`tuning`).
//! - `stages` holds what it runs work on: one long-lived object per stage (`inject`,
//!   `propagate`, `march` with `march_lookup`, `slice`, `baking`), each owning its pipelines,
//!   layouts and WGSL, and the scene's GPU resources (`resources`), rebuilt when the OPV
//!   layout changes, with the readbacks (`outputs`).
//! - The stages depend on the shared context and helpers (`context`, `layout`, `buffers`,
//!   `readback`, `report`, `opv_store`), never on the scheduler; `binning` and `gpu_types`,
//!   at the bottom, read only the scene.

mod baking;
mod binning;
mod budget;
mod buffers;
mod context;
mod error;
mod frame_inputs;
mod gpu_types;
mod host_sums;
mod image_sampling;
mod inject;
mod inject_options;
mod keys;
mod layout;
mod limits;
mod march;
mod march_lookup;
mod opv_store;
mod outputs;
mod pipeline;
mod propagate;
mod readback;
mod report;
mod resources;
mod scattering;
mod shaders;
mod slice;
mod stages;
mod timer;
mod tuning;

pub use baking::{BakePhase, AS_BAKED_STEPS_PER_CELL};
pub use binning::{cutoff_epsilon, cutoff_radius};
pub use context::{adapter_rank, GpuContext, OPTIONAL_FEATURES};
pub use error::GpuError;
pub use frame_inputs::{light_has_opv, light_is_negligible, FrameRequest, CULL_RADIANCE};
pub use gpu_types::{SweepBox, SweepStep};
pub use image_sampling::{ImageSampling, DEFAULT_TOLERANCE as DEFAULT_SAMPLING_TOLERANCE, LATTICE as SAMPLING_LATTICE};
pub use inject_options::HOST_MIN_ENTRIES_PER_BRICK;
pub use layout::shared_constants;
pub use limits::{analytic_unsupported, human_bytes};
pub use opv_store::OpvLayout;
pub use outputs::Image;
pub use pipeline::FogPipeline;
pub use propagate::{giroud_iterations, sweep_steps, ShellFrame, SweepPlan, EXACT_STEPS_PER_CELL};
pub use report::{Counters, FrameReport, Progress, Stage, StageTimings};
pub use slice::{Plane, SliceSource};
pub use tuning::{InjectPath, Tuning};

//! Fogsmith: an editor and baking pipeline for volumetric fog made of gaussian particles.
//!
//! - [`scene`]: the project model and its RON files (no GPU, no UI).
//! - [`gpu`]: the one module that talks to wgpu: injection, opacity propagation, ray march,
//!   readback, timings.
//! - [`reference`]: exact f64 formulas used only to measure the pipeline's error.
//! - [`editor`]: the interactive editor window (eframe + egui_dock).
//! - [`export`]: interchange: OpenVDB export and import, OpenEXR render / slices / atlas, and
//!   rendered images (tone-mapped PNG, linear EXR).
//! - [`farm`]: render-farm jobs (Open Job Description, Slurm) that split a sequence into tasks.
//! - [`stress`]: the numerical stress matrix behind `fogsmith stress`.
//! - [`sun_table`]: Sun et al.'s F function and the table the GPU reads.
//! - [`surface_table`]: Sun et al.'s surface term (fog glow on diffuse surfaces) and its table.
//! - [`quad`]: adaptive quadrature (the Sun table's construction and the reference).
//! - [`rng`]: the seeded generators behind every reproducible random draw.

pub mod bench;
pub mod cli;
pub mod demos;
pub mod editor;
pub mod export;
pub mod farm;
pub mod gpu;
pub mod measure;
pub mod quad;
pub mod reference;
pub mod rng;
pub mod scene;
pub mod stress;
pub mod sun_table;
pub mod surface_table;

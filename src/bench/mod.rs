//! `fogsmith bench`: run time against error for every speed/quality knob of the pipeline,
//! measured on the bundled demo scenes against the exact reference.
//!
//! Suites (each writes records into one list, saved as `bench.json` and `bench.csv`, with
//! PNG plots beside them):
//! - `opv`: propagation schemes × grid resolution, GPU time vs transmittance error.
//! - `march`: step policies × their knob, samples per pixel and time vs image relative RMSE.
//! - `sun`: Sun et al.'s F table, resolution × layout × interpolation vs error.
//! - `scaling`: update time vs resolution × lights and vs particle count, for a dynamic
//!   scene (everything recomputed) and a static one (camera only), with the stage split;
//!   plus binned vs brute-force injection and empty-space skipping on / off.
//! - `kinds`: light kinds (point, spot, sun) and medium features (height fog, noise,
//!   surfaces) on one small scene, bake-and-render time against OPV and image error.
//! - `scale`: time and peak memory (GPU resources, process RSS) against particles (10³ to
//!   10⁶, small ones), grid resolution (32³ to 384³) and lights (1 to 16), with fitted
//!   growth exponents; run on request only.
//! - `interaction`: the editor under scripted input (see `interaction`): frame times, input
//!   to preview latency and time to convergence; run on request only.
//! - `animation`: frame sequences of the cloud demo, one kind of motion each, baked in one
//!   pipeline against cold bakes of every frame (see `animation`); run on request only.
//! - `shapes`: propagation time per cell of wide, thin grids against a cube of the same cell
//!   count, with three light placements and the transmittance error; run on request only.
//! - `bake`: the light bake on each demo, its time, the error of its emission–absorption
//!   render against the lit render per phase mode, output sizes and texture quantisation
//!   (see `bake`); run on request only.

mod animation;
mod bake;
mod context;
mod interaction;
mod plot;
mod sampling;
mod scale;
mod scattering;
mod shapes;
mod suites;

use serde_json::Value;
use std::path::{Path, PathBuf};

pub use suites::Suite;

#[derive(Clone, Debug)]
pub struct BenchOptions {
    pub quick: bool,
    pub out: PathBuf,
    pub suites: Vec<Suite>,
    /// Resolutions of the propagation suite; empty for its default list.
    pub resolutions: Vec<u32>,
    /// Demo scenes of the propagation suite; empty for its default list.
    pub scenes: Vec<String>,
    /// Scheme labels of the propagation suite (`sweep8r`, `exact`, …); empty for all.
    pub schemes: Vec<String>,
    /// The frame at which animated demos are baked (`--frame`); their first without it.
    pub frame: Option<i32>,
    /// The image sampling of the suites' marches (`--image-sampling`).
    pub image_sampling: crate::gpu::ImageSampling,
}

/// Why a benchmark could not run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error(transparent)]
    Project(#[from] crate::scene::ProjectError),
    #[error("{0}")]
    Option(String),
    #[error("the interaction benchmark: {0}")]
    Editor(String),
    #[error("{path}: could not write benchmark output: {message}")]
    Write { path: PathBuf, message: String },
}

/// Runs the selected suites, writes bench.json, bench.csv and the plots into `opts.out`,
/// and returns the records. `log` receives one line per measurement.
pub fn run(opts: &BenchOptions, log: &mut dyn FnMut(&str)) -> Result<Vec<Value>, BenchError> {
    std::fs::create_dir_all(&opts.out).map_err(|e| write_err(&opts.out, e))?;
    let mut records = Vec::new();
    let mut ctx = context::Context::new(opts)?;
    for suite in &opts.suites {
        let start = records.len();
        run_suite(*suite, &mut ctx, &mut records, log)?;
        plot::plot_suite(*suite, &records[start..], &opts.out)
            .map_err(|message| BenchError::Write { path: opts.out.clone(), message })?;
    }
    write_json(&opts.out.join("bench.json"), &records)?;
    write_csv(&opts.out.join("bench.csv"), &records)?;
    Ok(records)
}

fn write_err(path: &Path, e: impl std::fmt::Display) -> BenchError {
    BenchError::Write { path: path.to_owned(), message: e.to_string() }
}

fn write_json(path: &Path, records: &[Value]) -> Result<(), BenchError> {
    let text = serde_json::to_string_pretty(records).map_err(|e| write_err(path, e))?;
    crate::scene::io::write_atomic(path, text.as_bytes(), false).map_err(|e| write_err(path, e))
}

/// One row per record; columns are the union of the records' scalar fields (nested objects
/// are flattened as `parent.child`).
fn write_csv(path: &Path, records: &[Value]) -> Result<(), BenchError> {
    let rows: Vec<Vec<(String, String)>> = records.iter().map(|r| flatten("", r)).collect();
    let mut columns: Vec<String> = Vec::new();
    for row in &rows {
        for (k, _) in row {
            if !columns.contains(k) {
                columns.push(k.clone());
            }
        }
    }
    let mut text = columns.join(",");
    text.push('\n');
    for row in &rows {
        let line: Vec<String> = columns
            .iter()
            .map(|c| row.iter().find(|(k, _)| k == c).map(|(_, v)| v.clone()).unwrap_or_default())
            .collect();
        text.push_str(&line.join(","));
        text.push('\n');
    }
    crate::scene::io::write_atomic(path, text.as_bytes(), false).map_err(|e| write_err(path, e))
}

fn flatten(prefix: &str, v: &Value) -> Vec<(String, String)> {
    match v {
        Value::Object(map) => map
            .iter()
            .flat_map(|(k, v)| flatten(&if prefix.is_empty() { k.clone() } else { format!("{prefix}.{k}") }, v))
            .collect(),
        Value::String(s) => vec![(prefix.to_string(), s.replace(',', ";"))],
        Value::Null => vec![(prefix.to_string(), String::new())],
        other => vec![(prefix.to_string(), other.to_string().replace(',', ";"))],
    }
}

/// One suite: `scale` and `interaction` live beside the others, so the dispatch is here.
fn run_suite(
    suite: Suite,
    ctx: &mut context::Context,
    out: &mut Vec<Value>,
    log: &mut dyn FnMut(&str),
) -> Result<(), BenchError> {
    match suite {
        Suite::Opv => suites::opv(ctx, out, log),
        Suite::March => {
            sampling::run(ctx, out, log)?;
            sampling::stability(ctx, out, log)?;
            suites::march(ctx, out, log)
        }
        Suite::Sampling => {
            sampling::run(ctx, out, log)?;
            sampling::stability(ctx, out, log)
        }
        Suite::Sun => {
            suites::sun(ctx.quick, out, log);
            Ok(())
        }
        Suite::Scaling => suites::scaling(ctx, out, log),
        Suite::Kinds => suites::kinds(ctx, out, log),
        Suite::Animation => animation::run(ctx, out, log),
        Suite::Bake => bake::run(ctx, out, log),
        Suite::Scattering => scattering::run(ctx, out, log),
        Suite::Scale => scale::run(ctx, out, log),
        Suite::Shapes => shapes::run(ctx, out, log),
        Suite::Interaction => {
            use crate::editor::app::Quality;
            // Blocking (every frame renders to convergence) is the editor before the frame budget.
            let modes = if ctx.quick { vec![Quality::Balanced] } else { vec![Quality::Balanced, Quality::Full] };
            let scenes: Vec<String> = if ctx.scenes.is_empty() {
                crate::demos::DEMOS
                    .iter()
                    .map(|(name, _)| name.to_string())
                    .chain([context::LARGE_SCENE.into()])
                    .collect()
            } else {
                ctx.scenes.clone()
            };
            for scene in &scenes {
                // The large scene in the budgeted preview only: blocking frames there take seconds.
                let large = scene == context::LARGE_SCENE;
                for &quality in modes.iter().filter(|&&q| !large || q == Quality::Balanced) {
                    out.extend(interaction::run(scene, quality, ctx.image_sampling, log)?);
                }
            }
            Ok(())
        }
    }
}

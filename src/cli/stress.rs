//! `fogsmith stress`: the numerical stress matrix of [`crate::stress`] on this machine's adapter.

use crate::gpu::{FogPipeline, GpuContext};
use crate::stress::{matrix, random_case, run_matrix, StressResult};

pub fn run(quick: bool, json: bool, quiet: bool) -> Result<(), Box<dyn std::error::Error>> {
    let ctx = GpuContext::new_headless()?;
    let adapter = ctx.adapter_summary();
    let max_3d = ctx.limits.max_texture_dimension_3d;
    let max_binding = ctx.max_binding_bytes();
    let opv_capacity = crate::gpu::OpvLayout::for_limits(&ctx.limits).capacity_lights(glam::UVec3::splat(64));
    let mut gpu = FogPipeline::new(ctx);
    let mut cases = matrix(quick, max_3d, max_binding, opv_capacity);
    cases.extend((0..if quick { 40 } else { 400 }).map(random_case));
    if !json {
        println!("stress matrix ({} cases{}) on {adapter}", cases.len(), if quick { ", quick" } else { "" });
        println!(
            "{:<48} {:<7} {:>10} {:>8} {:>6} {:>10}  result",
            "case", "scheme", "max error", "bound", "NaN", "time ms"
        );
    }
    let mut bar = super::progress::Bar::new(quiet);
    let mut done = 0;
    let results = run_matrix(&mut gpu, &cases, |r| {
        done += 1;
        bar.stage("stress cases", done as f64 / cases.len().max(1) as f64);
        if !json {
            bar.suspend(|| println!("{}", row(r)));
        }
    });
    bar.finish();
    let failed: Vec<&StressResult> = results.iter().filter(|r| !r.passed).collect();
    if json {
        println!("{}", serde_json::to_string_pretty(&results)?);
    } else {
        println!("{} of {} cases passed", results.len() - failed.len(), results.len());
    }
    if failed.is_empty() {
        Ok(())
    } else {
        let names: Vec<String> = failed.iter().map(|r| format!("{} ({}): {}", r.case, r.scheme, r.detail)).collect();
        Err(format!("{} stress case(s) failed:\n  {}", failed.len(), names.join("\n  ")).into())
    }
}

fn row(r: &StressResult) -> String {
    let opt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2e}"));
    let result = if r.passed && r.detail.is_empty() {
        "ok".to_string()
    } else if r.passed {
        "ok (refused as expected)".to_string()
    } else {
        format!("FAIL: {}", r.detail)
    };
    format!(
        "{:<48} {:<7} {:>10} {:>8} {:>6} {:>10.1}  {result}",
        r.case,
        r.scheme,
        opt(r.max_error),
        opt(r.bound),
        if r.nan_or_inf { "yes" } else { "no" },
        r.time_ms
    )
}

//! PNG plots of benchmark records (plotters, log–log axes).

use super::Suite;
use plotters::prelude::*;
use serde_json::Value;
use std::path::Path;
use std::sync::OnceLock;

const FONT_PATHS: [&str; 2] =
    ["/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf", "/usr/share/fonts/dejavu/DejaVuSans.ttf"];

/// Registers a system font with plotters once; the plots need text.
fn ensure_font() -> Result<(), String> {
    static FONT: OnceLock<Result<(), String>> = OnceLock::new();
    FONT.get_or_init(|| {
        let bytes = FONT_PATHS.iter().find_map(|p| std::fs::read(p).ok()).ok_or_else(|| {
            format!("no font for the plots at {}; run ./setup.sh (it installs fonts-dejavu-core)", FONT_PATHS[0])
        })?;
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
            .map_err(|_| "the plot font could not be parsed".to_string())
    })
    .clone()
}

type Series = Vec<(String, Vec<(f64, f64)>)>;

fn num(v: &Value, key: &str) -> f64 {
    v.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN)
}

fn text(v: &Value, key: &str) -> String {
    v.get(key).and_then(Value::as_str).unwrap_or("").to_string()
}

/// Groups (x, y) points by a label, keeping the order labels first appear in.
fn group(records: &[Value], label: impl Fn(&Value) -> Option<String>, xy: impl Fn(&Value) -> (f64, f64)) -> Series {
    let mut out: Series = Vec::new();
    for r in records {
        let Some(l) = label(r) else { continue };
        let p = xy(r);
        if !(p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite()) {
            continue;
        }
        match out.iter_mut().find(|(n, _)| *n == l) {
            Some((_, pts)) => pts.push(p),
            None => out.push((l, vec![p])),
        }
    }
    for (_, pts) in &mut out {
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    }
    out
}

fn loglog(path: &Path, title: &str, xlabel: &str, ylabel: &str, series: &Series) -> Result<(), String> {
    if series.is_empty() {
        return Ok(());
    }
    ensure_font()?;
    let all: Vec<(f64, f64)> = series.iter().flat_map(|(_, p)| p.iter().copied()).collect();
    let (x0, x1) = all.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.0), a.1.max(p.0)));
    let (y0, y1) = all.iter().fold((f64::MAX, f64::MIN), |a, p| (a.0.min(p.1), a.1.max(p.1)));
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    let e = |e: DrawingAreaErrorKind<_>| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0 / 1.3..x1 * 1.3).log_scale(), (y0 / 1.5..y1 * 1.5).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc(xlabel)
        .y_desc(ylabel)
        .label_style(("sans-serif", 16))
        .y_label_formatter(&|v| format!("{v:.0e}"))
        .draw()
        .map_err(e)?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
            .map_err(e)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3)));
        chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, color.filled()))).map_err(e)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

pub fn plot_suite(suite: Suite, records: &[Value], dir: &Path) -> Result<(), String> {
    match suite {
        Suite::Interaction => frame_times(&dir.join("interaction_frames.png"), records),
        // A table of four rows: the text output says it all.
        Suite::Animation | Suite::Scattering => Ok(()),
        // A few rows per light placement: the text output says it all.
        Suite::Shapes => Ok(()),
        // Two rows per demo: the text output says it all.
        Suite::Sampling => Ok(()),
        Suite::Opv => {
            let by_scheme = |r: &Value| Some(format!("{} / {}", text(r, "scene"), text(r, "scheme_or_policy")));
            // The grid's medium is not the scene's: against the gaussians themselves every
            // scheme but `analytic` also carries the grid's resolution error.
            let plots = [
                (
                    "opv_pareto.png",
                    "max scheme error (transmittance, vs the grid medium)",
                    "max |exp(-T) - exp(-T_exact)|",
                    "error_max",
                ),
                (
                    "opv_pareto_gaussians.png",
                    "max error against the gaussians clipped to the box",
                    "max |exp(-T) - exp(-T_analytic)|",
                    "error_vs_analytic_max",
                ),
            ];
            for (file, what, ylabel, key) in plots {
                let series = group(records, by_scheme, |r| (num(r, "time_ms"), num(r, key)));
                loglog(
                    &dir.join(file),
                    &format!("Opacity propagation: GPU time vs {what}"),
                    "propagation time (ms, all lights)",
                    ylabel,
                    &series,
                )?;
            }
            Ok(())
        }
        Suite::Bake => loglog(
            &dir.join("bake_pareto.png"),
            "Light bake: GPU time vs the error of its render against the lit render",
            "bake (ms)",
            "relative RMSE vs the lit render",
            &group(
                records,
                |r| Some(format!("{} / {}", text(r, "scene"), text(r, "phase"))),
                |r| (num(r, "time_ms"), num(r, "error_mean")),
            ),
        ),
        Suite::Kinds => loglog(
            &dir.join("kinds_pareto.png"),
            "Light kinds and medium features: bake and render time vs image error",
            "inject + propagate + march (ms)",
            "relative RMSE vs reference",
            &group(records, |r| Some(text(r, "scene")), |r| (num(r, "time_ms"), num(r, "error_mean"))),
        ),
        Suite::March => loglog(
            &dir.join("march_pareto.png"),
            "Ray march: samples per pixel vs image error",
            "samples per pixel",
            "relative RMSE vs reference",
            &group(
                records,
                |r| {
                    (text(r, "suite") == "march")
                        .then(|| format!("{} / {}", text(r, "scene"), text(r, "scheme_or_policy")))
                },
                |r| (num(r, "samples"), num(r, "error_mean")),
            ),
        ),
        Suite::Sun => {
            loglog(
                &dir.join("sun_table.png"),
                "Sun's F table: L_a relative error (max over the sweep)",
                "table resolution (entries per axis)",
                "max relative error of L_a",
                &group(records, |r| Some(text(r, "scheme_or_policy")), |r| (num(r, "resolution"), num(r, "error_max"))),
            )?;
            loglog(
                &dir.join("sun_f_error.png"),
                "Sun's F table: F(u, v) relative error on u in [0, 10] (paper's Fig. 6)",
                "table resolution (entries per axis)",
                "max relative error of F",
                &group(
                    records,
                    |r| Some(text(r, "scheme_or_policy")),
                    |r| (num(r, "resolution"), num(r, "f_error_max")),
                ),
            )
        }
        Suite::Scale => {
            let is = |r: &Value, case: &str| text(r, "suite") == "scale" && text(r, "case") == case;
            let stage = |r: &Value, s: &str| r["stage_ms"][s].as_f64().unwrap_or(f64::NAN);
            loglog(
                &dir.join("scale_particles.png"),
                "Injection time vs small particles (radius 0.02-0.06 m in a 4 m box)",
                "particles",
                "injection time (ms)",
                &group(
                    records,
                    |r| is(r, "particles").then(|| format!("{}³", num(r, "resolution"))),
                    |r| (num(r, "particles"), stage(r, "inject")),
                ),
            )?;
            loglog(
                &dir.join("scale_grid.png"),
                "Bake time (inject + propagate) vs grid cells, 2 lights",
                "cells",
                "bake time (ms)",
                &group(
                    records,
                    |r| is(r, "grid").then(|| "bake".to_string()),
                    |r| (num(r, "cells"), stage(r, "inject") + stage(r, "propagate")),
                ),
            )?;
            loglog(
                &dir.join("scale_lights.png"),
                "Propagation time vs lights",
                "lights",
                "propagation time (ms)",
                &group(
                    records,
                    |r| is(r, "lights").then(|| format!("{}³", num(r, "resolution"))),
                    |r| (num(r, "lights"), stage(r, "propagate")),
                ),
            )?;
            let mut files: Series = Vec::new();
            for (key, label) in [
                ("write_s", "write"),
                ("load_s", "load"),
                ("render_s", "render as the CLI does"),
                ("stage_s", "stage times of that render"),
                ("save_s", "save"),
                ("ron_write_s", "all in RON: write"),
                ("ron_parse_s", "all in RON: parse"),
            ] {
                files.extend(group(
                    records,
                    |r| is(r, "files").then(|| label.to_string()),
                    |r| (num(r, "particles"), num(r, key)),
                ));
            }
            loglog(&dir.join("scale_files.png"), "Through files: 128³ grid, 2 lights", "particles", "seconds", &files)?;
            let mut mem = group(
                records,
                |r| is(r, "grid").then(|| "GPU resources, peak".to_string()),
                |r| (num(r, "cells"), num(r, "gpu_peak_bytes") / 1048576.0),
            );
            mem.extend(group(
                records,
                |r| is(r, "grid").then(|| "process RSS, peak".to_string()),
                |r| (num(r, "cells"), num(r, "rss_peak_bytes") / 1048576.0),
            ));
            loglog(&dir.join("scale_memory.png"), "Peak memory vs grid cells, 2 lights", "cells", "MiB", &mem)
        }
        Suite::Scaling => {
            let res_records: Vec<Value> = records
                .iter()
                .filter(|r| text(r, "suite") == "scaling" && num(r, "particles") == 1000.0)
                .cloned()
                .collect();
            loglog(
                &dir.join("scaling_resolution.png"),
                "Update time vs grid size (1000 particles)",
                "cells",
                "update time (ms)",
                &group(
                    &res_records,
                    |r| Some(format!("{} / {} lights", text(r, "case"), num(r, "lights"))),
                    |r| (num(r, "resolution").powi(3), num(r, "time_ms")),
                ),
            )?;
            let sweep_res = particle_sweep_resolution(records);
            let mut part: Series = group(
                records,
                |r| {
                    let sweep =
                        text(r, "suite") == "scaling" && num(r, "lights") == 2.0 && num(r, "resolution") == sweep_res;
                    sweep.then(|| text(r, "case"))
                },
                |r| (num(r, "particles"), num(r, "time_ms")),
            );
            part.extend(group(
                records,
                |r| (text(r, "suite") == "injection").then(|| format!("inject, {}", text(r, "scheme_or_policy"))),
                |r| (num(r, "particles"), num(r, "time_ms")),
            ));
            loglog(&dir.join("scaling_particles.png"), "Update time vs particle count", "particles", "time (ms)", &part)
        }
    }
}

/// The resolution of the particle-count sweep: the one used by "injection" records.
fn particle_sweep_resolution(records: &[Value]) -> f64 {
    records.iter().filter(|r| text(r, "suite") == "injection").map(|r| num(r, "resolution")).fold(f64::NAN, f64::max)
}

/// Every frame's wall time of each interaction, frame by frame, with the 100 ms line.
fn frame_times(path: &Path, records: &[Value]) -> Result<(), String> {
    let series: Series = records
        .iter()
        // Playback records its rate, not each frame's time.
        .filter(|r| text(r, "suite") == "interaction" && r.get("frame_times_ms").is_some())
        .map(|r| {
            let times = r.get("frame_times_ms").and_then(Value::as_array).cloned().unwrap_or_default();
            let pts = times.iter().enumerate().map(|(i, v)| (i as f64, v.as_f64().unwrap_or(f64::NAN))).collect();
            (format!("{} / {}", text(r, "case"), text(r, "quality")), pts)
        })
        .collect();
    if series.is_empty() {
        return Ok(());
    }
    ensure_font()?;
    let frames = series.iter().map(|(_, p)| p.len()).max().unwrap_or(1) as f64;
    let top = series.iter().flat_map(|(_, p)| p.iter().map(|q| q.1)).filter(|v| v.is_finite()).fold(100.0, f64::max);
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    let e = |e: DrawingAreaErrorKind<_>| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(&root)
        .caption("Editor frame times during scripted interactions", ("sans-serif", 26))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(0.0..frames, (1.0..top * 1.5).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("frame of the interaction")
        .y_desc("frame wall time (ms)")
        .label_style(("sans-serif", 16))
        .draw()
        .map_err(e)?;
    chart.draw_series(LineSeries::new([(0.0, 100.0), (frames, 100.0)], BLACK.mix(0.5).stroke_width(1))).map_err(e)?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), color.stroke_width(2)))
            .map_err(e)?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(3)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(e)?;
    root.present().map_err(e)
}

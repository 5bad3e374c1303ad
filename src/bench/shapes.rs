//! The `shapes` suite: propagation cost per cell by grid shape. Wide, thin grids (ground fog,
//! street mist) hold the same number of cells as a cube but put most of them far from the
//! light along the flat axes; the sweep must not pay for that distance per cell. Each shape
//! has about the same cell count as the cube it is compared with and the same fog (gaussians
//! filling the box), with cubic cells (a box shaped like the grid) or with the 4 m box of a
//! new project (a user who lowers one axis' resolution gets long, flat cells), and one point
//! light in three places: inside the slab, above it and beside it. Each record has the propagation time, its ratio per cell to the cube's
//! with the same light placement, and the transmittance error (and the optical depth's
//! relative error, which still tells where the fog is too thick to let light through)
//! against the exact line integral through the grid's own medium.

use super::context::{Context, OPV_SCHEMES};
use super::BenchError;
use crate::measure::{opv_error_against, sample_cells};
use crate::reference::{grid_light_depth_cells, GridMedium64};
use crate::rng::Lcg;
use crate::scene::{Light, Particle, Project, Scheme};
use glam::{UVec3, Vec3};
use serde_json::{json, Value};

/// A scheme of the propagation suite: scheme, sweep stride, sweep refinement.
type SchemeChoice = (Scheme, u32, bool);

/// Edge of every grid cell, in metres.
const CELL: f32 = 1.0 / 64.0;

/// The shapes, as (label, resolution); the first is the cube the others are compared with.
fn shapes(quick: bool) -> Vec<(&'static str, UVec3)> {
    if quick {
        vec![
            ("cube", UVec3::splat(64)),
            ("slab", UVec3::new(256, 256, 4)),
            ("sheet", UVec3::new(512, 512, 1)),
            ("ground", UVec3::new(256, 4, 256)),
        ]
    } else {
        vec![
            ("cube", UVec3::splat(128)),
            ("slab", UVec3::new(512, 512, 8)),
            ("sheet", UVec3::new(2048, 2048, 1)),
            ("ground", UVec3::new(512, 8, 512)),
        ]
    }
}

/// One light placement, as a point of the box in units of its size (0 to 1 per axis, beyond
/// for outside), with the thin axis' coordinate taken from the second value.
const PLACEMENTS: [(&str, [f32; 3]); 3] =
    [("inside", [0.37, 0.41, 0.5]), ("above", [0.37, 0.41, 3.0]), ("beside", [-0.2, 0.41, 0.5])];

/// A grid of `res` cells centred on the origin, cubic or spanning a 4 m cube, filled with
/// overlapping gaussians, lit by one point light at `at` (see [`PLACEMENTS`]). The thin axis
/// is the one with fewest cells.
fn scene(res: UVec3, at: [f32; 3], cubic: bool) -> Project {
    let mut p = Project::default();
    let size = if cubic { res.as_vec3() * CELL } else { Vec3::splat(4.0) };
    p.grid.min = -size * 0.5;
    p.grid.max = size * 0.5;
    p.grid.resolution = res;
    p.medium.base_extinction = 0.02;
    let thin = (0..3).min_by_key(|&i| res[i]).unwrap_or(2);
    let mut rng = Lcg(0x5EED_F1A7);
    // The same gaussians in cells for every shape of a kind: 6 cells of the cube (cubic cells)
    // or of a 64³ grid over the 4 m box, so that only the shape differs.
    let radius = if cubic { 6.0 * CELL } else { 6.0 * 4.0 / 64.0 };
    let count = (res.as_dvec3().element_product() / 64f64.powi(3) * 400.0).round() as usize;
    for _ in 0..count {
        let c = p.grid.min + Vec3::new(rng.f32(), rng.f32(), rng.f32()) * size;
        p.particles.push(Particle::new(c, radius * (0.6 + 0.8 * rng.f32()), 0.5 / radius));
    }
    let mut u = Vec3::from(at);
    // The placements name the flat axes x and y and the thin one z; permute for a thin y.
    if thin == 1 {
        u = Vec3::new(u.x, u.z, u.y);
    }
    let light = p.grid.min + u * size;
    // Above: as far above the slab as the slab is wide, as a lamp over ground fog is.
    let light = if at[2] > 1.0 {
        let mut l = p.grid.min + u * size;
        l[thin] = p.grid.max[thin] + 0.3 * size.max_element();
        l
    } else {
        light
    };
    p.lights = vec![Light::new(light, 4.0, Vec3::ONE)];
    p.camera.position = Vec3::new(0.0, 0.5 * size.max_element(), 1.5 * size.max_element());
    p.camera.target = Vec3::ZERO;
    p
}

/// The names `--scene` takes in this suite: light placements and cell kinds.
pub(super) const NAMES: [&str; 5] = ["inside", "above", "beside", "cubic", "4m_box"];

pub(super) fn run(ctx: &mut Context, out: &mut Vec<Value>, log: &mut dyn FnMut(&str)) -> Result<(), BenchError> {
    let max_cells = if ctx.quick { 5_000 } else { 20_000 };
    // `--scene` picks placements and cell kinds by name (`inside`, `cubic`, …): all of each without one.
    let scenes = ctx.scenes.clone();
    let picked = |names: &[&str], name: &str| {
        !scenes.iter().any(|s| names.contains(&s.as_str())) || scenes.iter().any(|s| s == name)
    };
    // `--scheme` compares schemes (labels of the propagation suite); the default scheme without.
    let schemes: Vec<(Option<SchemeChoice>, &str)> = if ctx.schemes.is_empty() {
        vec![(None, "default")]
    } else {
        OPV_SCHEMES.iter().filter(|(_, l)| ctx.schemes.iter().any(|s| s == l)).map(|&(s, l)| (Some(s), l)).collect()
    };
    for (placement, at) in PLACEMENTS.into_iter().filter(|(n, _)| picked(&NAMES[..3], n)) {
        for &(scheme, scheme_label) in &schemes {
            for cubic in [true, false] {
                let cells_kind = if cubic { "cubic" } else { "4m_box" };
                if !picked(&NAMES[3..], cells_kind) {
                    continue;
                }
                let mut cube_ns = None;
                for (label, res) in shapes(ctx.quick) {
                    let mut project = scene(res, at, cubic);
                    if let Some((scheme, stride, refine)) = scheme {
                        project.propagation.scheme = scheme;
                        project.propagation.sweep_stride = stride;
                        project.propagation.sweep_refine = refine;
                    }
                    if let Err(e) = ctx.gpu.check_limits(&project, 8, 8) {
                        log(&format!("shapes {label} {res} skipped: {e}"));
                        continue;
                    }
                    let mut times = Vec::new();
                    let mut report = ctx.full(&project, 8, 8)?;
                    times.push(report.timings_ms.propagate);
                    while times.len() < 3 && times.iter().sum::<f64>() < 3000.0 {
                        report = ctx.full(&project, 8, 8)?;
                        times.push(report.timings_ms.propagate);
                    }
                    times.sort_by(f64::total_cmp);
                    let ms = times[times.len() / 2];
                    let cells = res.as_dvec3().element_product();
                    let ns_per_cell = ms * 1e6 / cells;
                    let cube = *cube_ns.get_or_insert(ns_per_cell);
                    let sample = sample_cells(&project.grid, max_cells);
                    let medium = GridMedium64::for_project(&project, &ctx.gpu.read_ev()?);
                    let exact = grid_light_depth_cells(&project, &medium, 0, &sample);
                    let e = opv_error_against(0, &ctx.gpu.read_opv(0)?, &sample, &exact);
                    log(&format!(
                "shapes {placement:6} {scheme_label:8} {cells_kind:6} {label:6} {:>4}×{:>4}×{:>4} {ms:9.1} ms  {ns_per_cell:7.1} ns/cell  {:5.2}× the cube's  transmittance error max {:.2e} mean {:.2e}  optical depth rel error max {:.2e}",
                res.x,
                res.y,
                res.z,
                ns_per_cell / cube,
                e.transmittance_max_abs_error,
                e.transmittance_mean_abs_error,
                e.depth_max_rel_error,
            ));
                    out.push(json!({
                "suite": "shapes", "case": placement, "cells_kind": cells_kind, "shape": label, "scheme_or_policy": scheme_label, "grid": res.to_array(),
                "cells": cells, "time_ms": ms, "runs": times.len(), "ns_per_cell": ns_per_cell,
                "per_cell_vs_cube": ns_per_cell / cube,
                "error_max": e.transmittance_max_abs_error, "error_mean": e.transmittance_mean_abs_error,
                "depth_rel_error_max": e.depth_max_rel_error,
                "cells_compared": sample.len(),
            }));
                }
            }
        }
    }
    Ok(())
}

//! The shader registry: one function per compute pipeline that assembles its WGSL, used by
//! the stages that build the pipelines and by the test that checks every GPU struct against
//! its WGSL twin, so that a pipeline's list of sources is written once.
//!
//! A pipeline's WGSL is the generated shared constants ([`shared_constants`]),
//! `shaders/common.wgsl`, then its own sources in order: WGSL has no imports, so a source
//! relies on what earlier ones declare. Sources that depend on the device or the OPV layout
//! (the OPV bindings of `opv_store`, the sweep's cells per thread and σ_t lookup) are
//! parameters.
//!
//! Plain concatenation rather than a module system such as naga_oil: the sources form one
//! shallow layer of shared helpers, the per-device parts (OPV bindings, cells per thread) are
//! generated text either way, and a composer would mangle item names, which the struct-size
//! test and shader debugging look up. `every_pipeline_validates` keeps naga's check of every
//! assembled variant.

use super::layout::shared_constants;
use super::opv_store::{OpvLayout, EXTRA_BINDING, EXTRA_BINDING_2};

const COMMON: &str = include_str!("../../shaders/common.wgsl");
const NOISE: &str = include_str!("../../shaders/noise.wgsl");
const INJECT_FINISH: &str = include_str!("../../shaders/inject_finish.wgsl");
const EV_TRILINEAR: &str = include_str!("../../shaders/ev_trilinear.wgsl");
const VOLUME_LOOKUP: &str = include_str!("../../shaders/volume_lookup.wgsl");
const INTEGRATE_EXACT: &str = include_str!("../../shaders/integrate_exact.wgsl");
const SWEEP_SIGMA_LOADS: &str = include_str!("../../shaders/sweep_sigma_loads.wgsl");
const SWEEP_SIGMA_FILTERED: &str = include_str!("../../shaders/sweep_sigma_filtered.wgsl");

/// The WGSL of a pipeline: the shared constants, `shaders/common.wgsl`, then `sources`.
fn assemble(sources: &[&str]) -> String {
    let mut code = shared_constants();
    code.push_str(COMMON);
    for s in sources {
        code.push('\n');
        code.push_str(s);
    }
    code
}

/// Particle injection from binned lists into the EV.
pub fn inject() -> String {
    assemble(&[NOISE, INJECT_FINISH, include_str!("../../shaders/inject.wgsl")])
}

/// Injection from the host's particle sums (`host_sums`).
pub fn inject_sums() -> String {
    assemble(&[NOISE, INJECT_FINISH, include_str!("../../shaders/inject_sums.wgsl")])
}

/// Each brick's largest σ_t and detail.
pub fn occupancy() -> String {
    assemble(&[include_str!("../../shaders/occupancy.wgsl")])
}

/// Giroud & Biri's gather: reads OPV `src` (binding 4), writes `dst` (binding 5).
pub fn propagate_giroud(opv: &OpvLayout) -> String {
    let src_dst = opv.wgsl("src", 4, EXTRA_BINDING, false) + &opv.wgsl("dst", 5, EXTRA_BINDING_2, true);
    assemble(&[&src_dst, include_str!("../../shaders/propagate_giroud.wgsl")])
}

/// The upwind wavefront sweep, `cells_per_thread` cells per thread, its σ_t pairs from
/// hardware trilinear filtering when `filtered`.
pub fn propagate_sweep(opv: &OpvLayout, cells_per_thread: u32, filtered: bool) -> String {
    let cells = format!("const SWEEP_CELLS: u32 = {cells_per_thread}u;\n");
    let opv_mean = opv.wgsl("opv", 4, EXTRA_BINDING, true) + &opv.wgsl("mean_in", 5, EXTRA_BINDING_2, true);
    let sigma = if filtered { SWEEP_SIGMA_FILTERED } else { SWEEP_SIGMA_LOADS };
    assemble(&[
        &cells,
        &opv_mean,
        EV_TRILINEAR,
        VOLUME_LOOKUP,
        sigma,
        INTEGRATE_EXACT,
        include_str!("../../shaders/propagate_sweep.wgsl"),
    ])
}

/// The brute-force march of the `exact` scheme (suns' paths integrated piecewise exactly).
pub fn propagate_exact(opv: &OpvLayout) -> String {
    assemble(&[
        &opv.wgsl("opv", 4, EXTRA_BINDING, true),
        EV_TRILINEAR,
        VOLUME_LOOKUP,
        SWEEP_SIGMA_LOADS,
        INTEGRATE_EXACT,
        include_str!("../../shaders/propagate_exact.wgsl"),
    ])
}

/// The closed-form particle integrals of the `analytic` scheme.
pub fn propagate_analytic(opv: &OpvLayout) -> String {
    assemble(&[&opv.wgsl("opv", 4, EXTRA_BINDING, true), include_str!("../../shaders/propagate_analytic.wgsl")])
}

/// A sun's plane-by-plane sweep.
pub fn propagate_directional(opv: &OpvLayout) -> String {
    assemble(&[
        &opv.wgsl("opv", 4, EXTRA_BINDING, true),
        EV_TRILINEAR,
        VOLUME_LOOKUP,
        SWEEP_SIGMA_LOADS,
        INTEGRATE_EXACT,
        include_str!("../../shaders/propagate_directional.wgsl"),
    ])
}

/// The camera ray march, with Sun et al.'s airlight and surface tables.
pub fn march(opv: &OpvLayout) -> String {
    assemble(&[
        &opv.wgsl("lookup", 4, EXTRA_BINDING, false),
        include_str!("../../shaders/sun.wgsl"),
        include_str!("../../shaders/surface_glow.wgsl"),
        include_str!("../../shaders/march.wgsl"),
    ])
}

/// One refinement level of adaptive image-space sampling (`image_sampling`).
pub fn image_refine() -> String {
    assemble(&[include_str!("../../shaders/image_refine.wgsl")])
}

/// The march's per-light lookup volumes from the OPVs: reads `opv` (binding 3), writes
/// `lookup` (binding 4).
pub fn march_lookup(opv: &OpvLayout) -> String {
    let opv_lookup = opv.wgsl("opv", 3, EXTRA_BINDING, false) + &opv.wgsl("lookup", 4, EXTRA_BINDING_2, true);
    assemble(&[&opv_lookup, include_str!("../../shaders/march_lookup.wgsl")])
}

/// The bake of each cell's emission: the march's sources and lookups, entry point `bake`.
pub fn bake(opv: &OpvLayout) -> String {
    march(opv) + "\n" + include_str!("../../shaders/bake.wgsl")
}

/// The emission–absorption render of a bake: the march's sources, entry point `as_baked`.
pub fn as_baked(opv: &OpvLayout) -> String {
    march(opv) + "\n" + include_str!("../../shaders/as_baked.wgsl")
}

/// Multiple scattering's first-scattering source: the bake's sources, entry point
/// `scatter_source`.
pub fn scatter_source(opv: &OpvLayout) -> String {
    bake(opv) + "\n" + include_str!("../../shaders/scatter_source.wgsl")
}

/// Multiple scattering's sweeps and reductions on the coarse grid.
pub fn scatter_sweep() -> String {
    assemble(&[include_str!("../../shaders/scatter_sweep.wgsl")])
}

/// One plane of the EV or of a light's OPV.
pub fn slice(opv: &OpvLayout) -> String {
    assemble(&[&opv.wgsl("opv", 2, EXTRA_BINDING, false), include_str!("../../shaders/slice.wgsl")])
}

#[cfg(test)]
mod tests {
    use super::*;
    use wgpu::naga;

    /// Every pipeline's WGSL, in each variant the device or the OPV layout can select, parses
    /// and validates.
    #[test]
    fn every_pipeline_validates() {
        let opv = OpvLayout { textures: 2, max_depth: 2048, lights_per_texture: u32::MAX, rows: true };
        let mut all = vec![
            ("inject", inject()),
            ("inject_sums", inject_sums()),
            ("occupancy", occupancy()),
            ("propagate_giroud", propagate_giroud(&opv)),
            ("propagate_exact", propagate_exact(&opv)),
            ("propagate_analytic", propagate_analytic(&opv)),
            ("propagate_directional", propagate_directional(&opv)),
            ("march", march(&opv)),
            ("march_lookup", march_lookup(&opv)),
            ("bake", bake(&opv)),
            ("as_baked", as_baked(&opv)),
            ("slice", slice(&opv)),
            ("image_refine", image_refine()),
            ("scatter_source", scatter_source(&opv)),
            ("scatter_sweep", scatter_sweep()),
        ];
        for (cells, filtered) in [(1, false), (8, true)] {
            all.push(("propagate_sweep", propagate_sweep(&opv, cells, filtered)));
        }
        for (name, code) in all {
            let module =
                naga::front::wgsl::parse_str(&code).unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(&code)));
            naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::all())
                .validate(&module)
                .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        }
    }
}

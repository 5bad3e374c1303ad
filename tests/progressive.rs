//! The frame-budgeted pipeline: work spread over many small `advance` calls converges to
//! exactly the image and volumes of a from-scratch bake, every call makes progress, and an
//! edit is on show after one call, with stale optical depths where propagation lags.

mod common;

use common::{pipeline, small_scene};
use fogsmith::gpu::{FogPipeline, FrameRequest, Progress, Stage};
use fogsmith::scene::{Light, LightKind, Particle, Project, Scheme};
use glam::Vec3;
use proptest::prelude::*;
use std::time::Duration;

/// Advances with `budget` until converged; returns every call's progress.
fn converge(gpu: &mut FogPipeline, p: &Project, request: &FrameRequest, budget: Duration) -> Vec<Progress> {
    let mut all = Vec::new();
    for _ in 0..100_000 {
        let progress = gpu.advance(p, request, Some(budget)).expect("advance");
        all.push(progress);
        if progress.converged() {
            return all;
        }
    }
    panic!("no convergence after 100000 calls: {:?}", all.last());
}

/// The small scene with a light inside the grid and one outside, rendered at `width`×`height`.
fn two_lights(width: u32, height: u32) -> Project {
    let mut p = small_scene(24, &[Vec3::new(0.9, 0.9, 0.9), Vec3::new(-2.0, 0.3, 0.1)]);
    p.render.width = width;
    p.render.height = height;
    p
}

/// Asserts that `gpu` holds exactly what a fresh pipeline bakes for `p`, bit for bit.
fn assert_same_as_fresh(gpu: &FogPipeline, p: &Project, request: &FrameRequest) {
    let mut fresh = pipeline();
    fresh.set_image_sampling(gpu.image_sampling());
    fresh.update(p, request).unwrap();
    assert_eq!(gpu.read_ev().unwrap().data, fresh.read_ev().unwrap().data, "EV differs from a fresh bake");
    for l in 0..p.lights.len() {
        let (a, b) = (gpu.read_opv(l).unwrap().data, fresh.read_opv(l).unwrap().data);
        assert!(
            a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()),
            "OPV of light {l} differs from a fresh bake"
        );
    }
    let (a, b) = (gpu.read_image().unwrap(), fresh.read_image().unwrap());
    assert_eq!((a.width, a.height), (b.width, b.height), "the converged image is full size");
    assert!(
        a.rgba.iter().flatten().zip(b.rgba.iter().flatten()).all(|(x, y)| x.to_bits() == y.to_bits()),
        "the converged image differs from a fresh bake"
    );
}

#[test]
fn tiny_budgets_converge_to_the_fresh_bake_for_every_scheme() {
    for scheme in [Scheme::Sweep, Scheme::Exact, Scheme::Giroud] {
        let mut gpu = pipeline();
        let p = two_lights(64, 48);
        let request = FrameRequest { scheme, ..FrameRequest::for_project(&p) };
        let calls = converge(&mut gpu, &p, &request, Duration::ZERO);
        assert!(calls.len() > 3, "{scheme:?}: a zero budget still spreads the bake over calls ({} calls)", calls.len());
        assert!(
            calls.iter().all(|c| c.report.counters.dispatches > 0),
            "{scheme:?}: every call runs at least one item"
        );
        assert_same_as_fresh(&gpu, &p, &request);
    }
}

#[test]
fn an_edit_is_on_show_after_one_call_and_shadows_catch_up() {
    let mut gpu = pipeline();
    let mut p = small_scene(32, &[Vec3::new(0.9, 0.9, 0.9)]);
    p.render.width = 160;
    p.render.height = 120;
    let request = FrameRequest::for_project(&p);
    gpu.update(&p, &request).unwrap();
    let before = gpu.read_image().unwrap();

    p.lights[0].position = Vec3::new(-0.9, 0.8, 0.9);
    let first = gpu.advance(&p, &request, Some(Duration::ZERO)).unwrap();
    assert!(first.new_image, "the moved light is on show after one call");
    assert!(first.shadows_stale, "its optical depths still lag: {first:?}");
    assert!(matches!(first.stage, Stage::Propagate { .. }), "propagation is what is left: {first:?}");
    let quick = gpu.read_image().unwrap();
    assert!(quick.width < request.width, "a zero budget shows a reduced-resolution preview first");
    assert!(quick.rgba.iter().flatten().all(|v| v.is_finite()));
    // The glow moved: the brightest column of the preview follows the light from right to left.
    let brightest_column = |img: &fogsmith::gpu::Image| {
        (0..img.width)
            .max_by(|&a, &b| {
                let sum = |x: u32| (0..img.height).map(|y| img.rgba[(y * img.width + x) as usize][0]).sum::<f32>();
                sum(a).total_cmp(&sum(b))
            })
            .unwrap() as f32
            / img.width as f32
    };
    assert!(brightest_column(&before) > 0.5 && brightest_column(&quick) < 0.5, "the glow follows the light");

    let rest = converge(&mut gpu, &p, &request, Duration::from_millis(5));
    let last = rest.last().unwrap();
    assert!(!last.shadows_stale && last.shown_size == [request.width, request.height], "{last:?}");
    assert_same_as_fresh(&gpu, &p, &request);
}

/// Progressive resolution: after an edit, under budgets that change from call to call (input
/// frames and idle ones), the image on show never steps down until the full image replaces
/// it. (How far it steps up depends on the machine's speed: `bench --suite interaction`.)
#[test]
fn the_preview_resolution_never_steps_down_under_changing_budgets() {
    let mut gpu = pipeline();
    let mut p = small_scene(32, &[Vec3::new(0.9, 0.9, 0.9), Vec3::new(-0.9, 0.6, -0.3)]);
    p.render.width = 320;
    p.render.height = 240;
    let request = FrameRequest::for_project(&p);
    gpu.update(&p, &request).unwrap();
    p.lights[0].position = Vec3::new(-0.9, 0.8, 0.9);
    p.particles.push(Particle::new(Vec3::new(0.2, 0.1, 0.0), 0.3, 3.0));
    let budgets_ms = [0u64, 30, 2, 120, 0, 60, 5, 120];
    let mut sizes = Vec::new();
    for k in 0..100_000 {
        let progress =
            gpu.advance(&p, &request, Some(Duration::from_millis(budgets_ms[k % budgets_ms.len()]))).unwrap();
        // From the first image of the edited scene on.
        if progress.new_image || !sizes.is_empty() {
            sizes.push(progress.shown_size);
        }
        if progress.converged() {
            break;
        }
    }
    assert_eq!(sizes.last(), Some(&[request.width, request.height]), "it converges to the full image");
    // The first call has no time: what it shows must be a quick image, or nothing below is tested.
    assert!(
        sizes[0][0] < request.width && sizes[0][1] < request.height,
        "the first image of the edit is a quick one, smaller than the full image: {sizes:?}"
    );
    for pair in sizes.windows(2) {
        assert!(
            pair[1][0] >= pair[0][0] && pair[1][1] >= pair[0][1],
            "the preview stepped down from {:?} to {:?}: {sizes:?}",
            pair[0],
            pair[1]
        );
    }
    assert_same_as_fresh(&gpu, &p, &request);
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 6, ..ProptestConfig::default() })]

    /// Randomized edits (particles added, moved and removed, lights moved in and out of the
    /// box), each followed by a few budgeted calls and sometimes interrupted by the next edit,
    /// end in exactly the fresh bake of the last scene.
    #[test]
    fn interrupted_edits_end_in_the_fresh_bake(
        edits in proptest::collection::vec((0u8..4, -1.5f32..1.5, -1.5f32..1.5, -1.5f32..1.5, 0usize..4), 1..6),
    ) {
        let mut gpu = pipeline();
        let mut p = small_scene(20, &[Vec3::new(0.5, 0.9, 0.2), Vec3::new(1.6, -0.4, 0.3)]);
        let request = FrameRequest::for_project(&p);
        gpu.update(&p, &request).unwrap();
        for (kind, x, y, z, calls) in edits {
            let at = Vec3::new(x, y, z);
            match kind {
                0 => p.particles.push(Particle::new(at * 0.6, 0.15 + 0.1 * x.abs(), 5.0)),
                1 => p.particles[0].center = at * 0.5,
                2 => { p.particles.pop(); }
                _ => p.lights[1].position = at * 1.4,
            }
            for _ in 0..calls {
                gpu.advance(&p, &request, Some(Duration::from_millis(2))).unwrap();
            }
        }
        converge(&mut gpu, &p, &request, Duration::from_millis(2));
        assert_same_as_fresh(&gpu, &p, &request);
    }
}

/// A local edit far from a light re-propagates only the shells it can reach, and the result
/// is still bit for bit the fresh bake; so after a light is added (its buffers reallocated).
/// With `sweep_refine` the edit reaches further: how a cell integrates its segment also depends
/// on the detail of the bricks its path crosses, which the edit changes up to one cell beyond
/// its bricks.
#[test]
fn a_local_edit_repropagates_only_the_shells_it_reaches() {
    for (refine, kept_at_least) in [(false, 0.1), (true, 0.05)] {
        local_edit_repropagates_only_the_shells_it_reaches(refine, kept_at_least);
    }
}

fn local_edit_repropagates_only_the_shells_it_reaches(refine: bool, kept_at_least: f64) {
    let mut gpu = pipeline();
    let mut p = small_scene(40, &[Vec3::new(-0.8, -0.8, -0.8), Vec3::new(-3.0, 0.2, 0.1)]);
    p.propagation.sweep_refine = refine;
    let request = FrameRequest::for_project(&p);
    let full = gpu.update(&p, &FrameRequest { force: true, ..request }).unwrap();
    p.particles.push(Particle::new(Vec3::new(0.75, 0.75, 0.75), 0.08, 6.0));
    let local = gpu.update(&p, &request).unwrap();
    assert_eq!(local.counters.lights_propagated, 2);
    // The shells nearer each light than the edit are kept: for these placements about a fifth
    // of the work without refine, 7 % with it.
    let (local_cells, full_cells) = (local.counters.cells_propagated, full.counters.cells_propagated);
    assert!(
        (local_cells as f64) < (1.0 - kept_at_least) * full_cells as f64,
        "refine {refine}: a corner edit recomputes fewer cells: {local_cells} of {full_cells}"
    );
    assert_same_as_fresh(&gpu, &p, &request);

    p.lights.push(fogsmith::scene::Light::new(Vec3::new(0.9, -0.9, 0.9), 3.0, Vec3::ONE));
    gpu.update(&p, &request).unwrap();
    p.particles[0].center = Vec3::new(0.05, 0.0, -0.05);
    gpu.update(&p, &request).unwrap();
    assert_same_as_fresh(&gpu, &p, &request);
}

/// What `update_with` reports: stages in pipeline order, each stage's fraction rising within
/// [0, 1], then the converged result; returning false stops it with `Cancelled`.
#[test]
fn update_progress_is_monotone_and_cancellable() {
    let mut gpu = pipeline();
    let p = small_scene(32, &[Vec3::new(0.9, 0.9, 0.9), Vec3::new(-2.0, 0.3, 0.1)]);
    let request = FrameRequest::for_project(&p);
    let rank = |s: Stage| match s {
        Stage::Inject => 0,
        Stage::Propagate { .. } => 1,
        Stage::Scatter => 2,
        Stage::March => 3,
        Stage::Done => 4,
    };
    let mut seen: Vec<(u32, f64)> = Vec::new();
    let report = gpu
        .update_with(&p, &FrameRequest { force: true, ..request }, Duration::ZERO, &mut |progress| {
            seen.push((rank(progress.stage), progress.stage_fraction));
            true
        })
        .unwrap();
    assert!(seen.len() > 2, "a zero slice reports between items: {seen:?}");
    for w in seen.windows(2) {
        assert!(w[0].0 <= w[1].0, "stages go forward: {seen:?}");
        if w[0].0 == w[1].0 {
            assert!(w[0].1 <= w[1].1, "fractions rise within a stage: {seen:?}");
        }
    }
    assert!(seen.iter().all(|&(_, f)| (0.0..=1.0).contains(&f)));
    assert_eq!(report.counters.lights_propagated, 2);
    assert_same_as_fresh(&gpu, &p, &request);

    let mut calls = 0;
    let err = gpu
        .update_with(&p, &FrameRequest { force: true, ..request }, Duration::ZERO, &mut |_| {
            calls += 1;
            calls < 3
        })
        .unwrap_err();
    assert!(matches!(err, fogsmith::gpu::GpuError::Cancelled), "{err}");
}

/// Multiple scattering is a stage of its own, one step (the first scattering, an order, the
/// moments) per item: under a zero budget it reports between its steps, after propagation and
/// before the march, and ends with the image of an unbudgeted update. A moved camera reuses
/// the solve (it reads no camera); a moved light solves again.
#[test]
fn multiple_scattering_steps_under_a_budget() {
    let mut gpu = pipeline();
    let mut p = small_scene(32, &[Vec3::new(0.9, 0.9, 0.9)]);
    p.medium.multiple_scattering = Some(fogsmith::scene::MultipleScattering { orders: 4, ..Default::default() });
    let request = FrameRequest::for_project(&p);
    let mut stages = Vec::new();
    let report = gpu
        .update_with(&p, &FrameRequest { force: true, ..request }, Duration::ZERO, &mut |progress| {
            stages.push(progress.stage);
            true
        })
        .unwrap();
    let steps = stages.iter().filter(|s| **s == Stage::Scatter).count();
    assert!(steps >= 5, "6 steps report 5 times between them, got {steps}: {stages:?}");
    let first = stages.iter().position(|s| *s == Stage::Scatter).unwrap();
    let last = stages.iter().rposition(|s| *s == Stage::Scatter).unwrap();
    assert!(stages[..first].iter().all(|s| !matches!(s, Stage::March)), "march before the solve: {stages:?}");
    assert!(stages[last..].iter().all(|s| !matches!(s, Stage::Propagate { .. })), "{stages:?}");
    assert!(report.timings_ms.scatter > 0.0);
    assert_same_as_fresh(&gpu, &p, &request);
    let mut moved = p.clone();
    moved.camera.position += Vec3::new(0.2, 0.0, 0.0);
    assert_eq!(gpu.update(&moved, &request).unwrap().timings_ms.scatter, 0.0, "a camera move solved again");
    moved.lights[0].position += Vec3::new(0.0, 0.1, 0.0);
    assert!(gpu.update(&moved, &request).unwrap().timings_ms.scatter > 0.0, "a moved light did not solve again");
    assert_same_as_fresh(&gpu, &moved, &request);
}

/// The march reads per-light lookup volumes built from the OPVs, rebuilt only for the lights
/// an edit touches. After each kind of edit, converged under small budgets, the image equals a
/// fresh bake bit for bit: a light moved, dimmed, turned into a spot or a sun and back, added
/// and removed; particles painted near one light only; the base fog changed; and a light at a
/// cell centre exactly (whose lookup takes the EV's value there) with the fog around it edited.
#[test]
fn every_edit_keeps_the_march_lookups_in_step() {
    let mut gpu = pipeline();
    let mut p = two_lights(40, 30);
    let request = FrameRequest::for_project(&p);
    let settle = |gpu: &mut FogPipeline, p: &Project, what: &str| {
        converge(gpu, p, &request, Duration::from_millis(2));
        eprintln!("checking after: {what}");
        assert_same_as_fresh(gpu, p, &request);
    };
    settle(&mut gpu, &p, "the first bake");
    p.lights[0].position = Vec3::new(-0.5, 0.7, 0.2);
    settle(&mut gpu, &p, "a light moved");
    p.lights[1].intensity = 2.0;
    settle(&mut gpu, &p, "a light dimmed");
    p.lights[1].kind = LightKind::Spot { direction: Vec3::new(1.0, -0.1, 0.0), angle_deg: 30.0, blend: 0.2 };
    settle(&mut gpu, &p, "a light turned into a spot");
    p.lights[0].kind = LightKind::Directional { direction: Vec3::new(0.3, -1.0, 0.2) };
    settle(&mut gpu, &p, "a light turned into a sun");
    p.lights[0].kind = LightKind::Directional { direction: Vec3::new(-0.6, -1.0, 0.1) };
    settle(&mut gpu, &p, "the sun turned");
    p.lights.push(Light::new(Vec3::new(0.2, -0.8, 0.6), 4.0, Vec3::new(0.5, 0.7, 1.0)));
    settle(&mut gpu, &p, "a light added");
    p.particles.push(Particle::new(Vec3::new(0.3, -0.6, 0.55), 0.1, 7.0));
    settle(&mut gpu, &p, "particles painted by the new light");
    p.medium.base_extinction = 0.2;
    settle(&mut gpu, &p, "the base fog thickened");
    // Cell 12 of 24 on [-1, 1] has its centre at 12.5 / 12 - 1 on every axis.
    let centre = 12.5 / 12.0 - 1.0;
    p.lights[2].position = Vec3::splat(centre);
    settle(&mut gpu, &p, "a light put at a cell centre");
    p.particles.push(Particle::new(Vec3::splat(centre + 0.05), 0.15, 9.0));
    settle(&mut gpu, &p, "fog painted around the light at a cell centre");
    p.lights.remove(0);
    settle(&mut gpu, &p, "a light removed");
    p.lights[0].kind = LightKind::Point;
    settle(&mut gpu, &p, "the spot turned back into a point light");
}

/// With per-pixel sampling, a call with no time left marches one workgroup of the full image,
/// not a whole row of workgroups (which on a software adapter can cost more than a frame), and
/// bands of every width add up to exactly the fresh bake.
#[test]
fn a_call_without_time_marches_part_of_a_row_and_converges_to_the_fresh_bake() {
    let mut gpu = pipeline();
    gpu.set_image_sampling(fogsmith::gpu::ImageSampling::PerPixel);
    let p = two_lights(200, 40);
    let request = FrameRequest::for_project(&p);
    let calls = converge(&mut gpu, &p, &request, Duration::ZERO);
    let marching: Vec<f64> = calls.iter().filter(|c| c.stage == Stage::March).map(|c| c.stage_fraction).collect();
    let steps: Vec<f64> = marching.windows(2).map(|w| w[1] - w[0]).collect();
    let row = 8.0 / 40.0;
    let largest = steps.iter().copied().fold(0.0, f64::max);
    assert!(steps.len() > 10, "the march took {} calls", steps.len() + 1);
    assert!(largest < 0.5 * row, "a call without time marched {largest} of the image, a row of workgroups is {row}");
    assert!(steps.iter().all(|&s| s >= 0.0), "the march's progress never goes back");
    assert_same_as_fresh(&gpu, &p, &request);
}

/// With adaptive sampling, calls with no time left march the lattice and each refinement
/// level's list in many small bands, the progress never goes back, and the result is the
/// fresh bake's bit for bit.
#[test]
fn adaptive_sampling_marches_in_small_bands_and_converges_to_the_fresh_bake() {
    let mut gpu = pipeline();
    let p = two_lights(200, 40);
    let request = FrameRequest::for_project(&p);
    let calls = converge(&mut gpu, &p, &request, Duration::ZERO);
    let marching: Vec<f64> = calls.iter().filter(|c| c.stage == Stage::March).map(|c| c.stage_fraction).collect();
    assert!(marching.len() > 10, "the march took {} calls", marching.len());
    assert!(marching.windows(2).all(|w| w[1] >= w[0]), "the march's progress never goes back: {marching:?}");
    assert_same_as_fresh(&gpu, &p, &request);
}

/// An update in slices (the command line's progress bar) may overrun a slice, so its
/// per-pixel march keeps to whole rows of workgroups, the most efficient bands: with zero
/// slices every report during the march stands at a whole number of rows of workgroups, and
/// the result is the fresh bake.
#[test]
fn an_update_in_slices_marches_whole_rows_of_workgroups() {
    let mut gpu = pipeline();
    gpu.set_image_sampling(fogsmith::gpu::ImageSampling::PerPixel);
    let p = two_lights(200, 40);
    let request = FrameRequest::for_project(&p);
    let mut fractions = Vec::new();
    gpu.update_with(&p, &request, Duration::ZERO, &mut |progress| {
        if progress.stage == Stage::March {
            fractions.push(progress.stage_fraction);
        }
        true
    })
    .unwrap();
    let rows = 40.0 / 8.0;
    assert!(fractions.len() >= 2, "the march was reported {} times", fractions.len());
    assert!(
        fractions.iter().all(|f| (f * rows - (f * rows).round()).abs() < 1e-9),
        "reports between whole rows of workgroups: {fractions:?}"
    );
    assert_same_as_fresh(&gpu, &p, &request);
}

//! Picking and box selection through the particle bins (`editor::pick_index`) against the
//! full scan, on random scenes, cameras, clicks and boxes: the answers must be identical.

mod common;

use common::Rng;
use egui::{Pos2, Rect};
use fogsmith::editor::pick_index::ParticleIndex;
use fogsmith::editor::tools::{box_select, box_select_with, pick, pick_with, Hit};
use fogsmith::editor::view::ViewProjection;
use fogsmith::scene::{Camera, Particle, Project};
use glam::Vec3;

/// Clusters of particles of very different sizes, some hidden, some sharing a centre (ties
/// in depth), some far out and some behind any camera in the middle of the scene.
fn random_particles(rng: &mut Rng, n: usize) -> Vec<Particle> {
    let clusters: Vec<(Vec3, f32)> = (0..8).map(|_| (rng.vec3(-3.0, 3.0), rng.range(0.05, 1.5))).collect();
    let mut out = Vec::with_capacity(n);
    while out.len() < n {
        let (c, spread) = clusters[(rng.f32() * clusters.len() as f32) as usize % clusters.len()];
        let radius = if rng.f32() < 0.05 { rng.range(0.2, 1.0) } else { rng.range(0.001, 0.08) };
        let mut p = Particle::new(c + rng.vec3(-spread, spread), radius, 1.0);
        p.hidden = rng.f32() < 0.05;
        if rng.f32() < 0.02 {
            p.center = rng.vec3(-40.0, 40.0);
        }
        out.push(p);
        if rng.f32() < 0.02 {
            let mut twin = out[out.len() - 1].clone();
            twin.radius = rng.range(0.001, 0.1);
            out.push(twin);
        }
    }
    out
}

fn random_view(rng: &mut Rng) -> ViewProjection {
    let target = rng.vec3(-2.0, 2.0);
    // Mostly outside the scene, sometimes inside it (particles behind the camera).
    let distance = if rng.f32() < 0.25 { rng.range(0.1, 2.0) } else { rng.range(3.0, 15.0) };
    let camera = Camera {
        position: target + rng.direction() * distance,
        target,
        up: Vec3::Y,
        fov_y_deg: rng.range(10.0, 100.0),
    };
    let size = egui::vec2(rng.range(50.0, 1600.0), rng.range(50.0, 1000.0));
    let rect = Rect::from_min_size(Pos2::new(rng.range(0.0, 300.0), rng.range(0.0, 200.0)), size);
    ViewProjection::new(&camera, rect)
}

fn project_with(particles: Vec<Particle>) -> Project {
    Project { particles, lights: Vec::new(), ..Default::default() }
}

#[test]
fn binned_picks_equal_the_scan() {
    let (mut hits, mut clicks, mut tested, mut scanned) = (0, 0, 0, 0);
    for seed in 1..=12u64 {
        let mut rng = Rng(seed * 0x9E37_79B9_7F4A_7C15);
        let n = [5_000, 20_000, 60_000][seed as usize % 3];
        let project = project_with(random_particles(&mut rng, n));
        let index = ParticleIndex::build(&project.particles);
        for _ in 0..6 {
            let view = random_view(&mut rng);
            for k in 0..60 {
                // Half the clicks aim at a particle's centre (or just beside it), so most hit.
                let pos = if k % 2 == 0 {
                    let p = &project.particles[(rng.f32() * n as f32) as usize % n];
                    match view.project(p.center) {
                        Some((s, _)) => s + egui::vec2(rng.range(-6.0, 6.0), rng.range(-6.0, 6.0)),
                        None => view.rect.center(),
                    }
                } else {
                    Pos2::new(
                        rng.range(view.rect.min.x - 20.0, view.rect.max.x + 20.0),
                        rng.range(view.rect.min.y - 20.0, view.rect.max.y + 20.0),
                    )
                };
                let scan = pick(&project, &view, pos);
                let binned = pick_with(&project, Some(&index), &view, pos);
                assert_eq!(binned, scan, "seed {seed}, click {k} at {pos:?}");
                tested += index.pick_counted(&project.particles, &view, pos).1;
                scanned += n;
                clicks += 1;
                hits += matches!(scan, Some(Hit::Particle(_))) as usize;
            }
        }
    }
    println!("{hits} of {clicks} clicks hit a particle; the bins left {tested} of {scanned} particle tests");
    // Without pruning the equality above would hold trivially. Cameras inside the clusters
    // with wide fields of view and the 4-point minimum footprint keep some cones wide.
    assert!(tested * 4 < scanned, "the bins prune too little: {tested} of {scanned} tests");
    assert!(hits > clicks / 3 && hits < clicks, "the clicks test too little: {hits} of {clicks} hit");
}

#[test]
fn binned_box_selections_equal_the_scan() {
    let (mut selected, mut boxes) = (0, 0);
    for seed in 1..=12u64 {
        let mut rng = Rng(seed * 0xD1B5_4A32_D192_ED03);
        let n = [5_000, 20_000, 60_000][seed as usize % 3];
        let project = project_with(random_particles(&mut rng, n));
        let index = ParticleIndex::build(&project.particles);
        for _ in 0..6 {
            let view = random_view(&mut rng);
            for k in 0..30 {
                let a = Pos2::new(
                    rng.range(view.rect.min.x - 50.0, view.rect.max.x + 50.0),
                    rng.range(view.rect.min.y - 50.0, view.rect.max.y + 50.0),
                );
                let size = if k % 3 == 0 { 5.0 } else { 400.0 };
                let rect = Rect::from_two_pos(a, a + egui::vec2(rng.range(-size, size), rng.range(-size, size)));
                let scan = box_select(&project, &view, rect);
                let binned = box_select_with(&project, Some(&index), &view, rect);
                assert_eq!(binned, scan, "seed {seed}, box {k} {rect:?}");
                boxes += 1;
                selected += scan.0.len();
            }
        }
    }
    println!("{selected} particles selected in {boxes} boxes");
    assert!(selected > 100 * boxes, "the boxes select too little: {selected} in {boxes}");
}

/// Particles on the boundary of the bins' tests: a box edge through a column of centres and a
/// click at a footprint's rim, where f32 rounding decides; and particles with centres that are
/// not finite, which the bins leave to the scan's test.
#[test]
fn boundary_cases_and_odd_centres_equal_the_scan() {
    let camera = Camera { position: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 };
    let view = ViewProjection::new(&camera, Rect::from_min_size(Pos2::ZERO, egui::vec2(800.0, 600.0)));
    let mut particles: Vec<Particle> = (0..5000)
        .map(|i| Particle::new(Vec3::new(0.0, (i as f32 / 5000.0 - 0.5) * 2.0, -(i % 7) as f32), 0.01, 1.0))
        .collect();
    particles.push(Particle::new(Vec3::new(f32::NAN, 0.0, 0.0), 0.1, 1.0));
    particles.push(Particle::new(Vec3::new(f32::INFINITY, 0.0, 0.0), 0.1, 1.0));
    let project = project_with(particles);
    let index = ParticleIndex::build(&project.particles);
    let x = view.project(Vec3::ZERO).unwrap().0.x;
    for dx in [-1e-3f32, 0.0, 1e-3] {
        let rect = Rect::from_min_max(Pos2::new(x + dx, 0.0), Pos2::new(x + 100.0, 600.0));
        assert_eq!(box_select_with(&project, Some(&index), &view, rect), box_select(&project, &view, rect));
    }
    for k in 0..400 {
        let p = &project.particles[k * 12];
        let (s, z) = view.project(p.center).unwrap();
        let rim = (p.radius * view.points_per_metre(z)).max(4.0);
        for d in [rim - 1e-3, rim, rim + 1e-3] {
            let pos = s + egui::vec2(d, 0.0);
            assert_eq!(pick_with(&project, Some(&index), &view, pos), pick(&project, &view, pos), "{k} at {d}");
        }
    }
}

/// The speed-up on a million particles (printed; `--nocapture`): the same answer, fewer tests.
#[test]
fn a_million_particles_pick_through_the_bins() {
    let mut rng = Rng(7);
    let project = project_with(random_particles(&mut rng, 1_000_000));
    let t = std::time::Instant::now();
    let index = ParticleIndex::build(&project.particles);
    let build = t.elapsed();
    let camera = Camera { position: Vec3::new(0.0, 1.0, 12.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 };
    let view = ViewProjection::new(&camera, Rect::from_min_size(Pos2::ZERO, egui::vec2(1280.0, 800.0)));
    let clicks: Vec<Pos2> = (0..50).map(|_| Pos2::new(rng.range(0.0, 1280.0), rng.range(0.0, 800.0))).collect();
    let t = std::time::Instant::now();
    let scan: Vec<_> = clicks.iter().map(|&p| pick(&project, &view, p)).collect();
    let scan_time = t.elapsed();
    let t = std::time::Instant::now();
    let binned: Vec<_> = clicks.iter().map(|&p| pick_with(&project, Some(&index), &view, p)).collect();
    let binned_time = t.elapsed();
    assert_eq!(binned, scan);
    println!(
        "10^6 particles: bins built in {build:?}; 50 clicks: scan {scan_time:?}, through the bins {binned_time:?}"
    );
}

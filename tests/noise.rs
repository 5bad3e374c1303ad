//! The medium's noise on the real pipeline: the injected EV against the f64 reference of
//! `fogsmith::reference::noise` on randomized scenes, the GPU's hash against the CPU's at
//! lattice points, dirty tracking of noise edits, extreme inputs, and the Nyquist note of
//! `fogsmith render`.

mod common;

use common::{pipeline, Rng};
use fogsmith::gpu::{cutoff_radius, FogPipeline, FrameRequest};
use fogsmith::reference::cell_center64;
use fogsmith::reference::noise::{lattice_value, Noise64};
use fogsmith::scene::{GridSpec, Medium, Noise, Particle, Project, Volume};
use glam::{DVec3, UVec3, Vec3};

fn bake(gpu: &mut FogPipeline, p: &Project) -> (Volume, u64) {
    let report = gpu.update(p, &FrameRequest::for_project(p)).unwrap();
    (gpu.read_ev().unwrap(), report.counters.cells_injected)
}

/// A project with no lights (only the EV is compared) on `grid`.
fn scene(grid: GridSpec, base: f32, particles: Vec<Particle>, noise: Option<Noise>) -> Project {
    let mut p = Project {
        grid,
        medium: Medium { base_extinction: base, noise, ..Medium::default() },
        particles,
        ..Project::default()
    };
    p.render.width = 8;
    p.render.height = 8;
    p
}

/// Worst |GPU − reference| / bound over all cells (asserting each is within its bound) and
/// the worst relative error. The reference at the exact (f64) cell centre is the base fog
/// plus the particles within the pipeline's cut-off radii, the noisy ones times the f64
/// modulation.
///
/// The bound is what f32 arithmetic allows:
/// - 1e-5 of the cell's largest possible value, (base + plain + (1 + a)·noisy): the f32
///   gaussian sum, as for EVs without noise (tests/pipeline.rs), scaled by the modulation;
/// - noisy·a·Δn for the noise itself. The GPU's cell centre is off by a few ulps of the
///   grid's largest coordinate M, and x·F (F = 2^o·frequency) adds an ulp of its own, so
///   octave o's lattice coordinate is off by at most F·2⁻²⁰·M per axis; value noise has
///   slope at most 1.5·2 = 3 per axis (smoothstep slope times the lattice values' range),
///   so Δv ≤ 9·F·2⁻²⁰·M, and over the weighted octaves Δn ≤ 9·2⁻²⁰·M·Σw_o·F_o/Σw_o, plus
///   2e-6 for the rounding of lattice values (hash to f32), smoothstep and lerps.
///   max(0, ·) is 1-Lipschitz, so clipping adds nothing.
/// - the same offset of the cell centre moves each gaussian's value by up to 2·d·δ/r²;
/// - where a cell sits on a particle's cut-off sphere (|d²/rc² − 1| < 1e-4) f32 and f64 may
///   disagree about including it: its whole (modulated) contribution.
fn compare(p: &Project, ev: &Volume) -> (f64, f64) {
    let noise = p.medium.noise.filter(|n| n.amplitude > 0.0).map(|n| Noise64::new(&n, &p.grid));
    let m = p.grid.min.abs().max(p.grid.max.abs()).max_element() as f64;
    // The drift x − offset, subtracted in f32 on the GPU, is off by an ulp of |x| + |offset|.
    let m_noise = m + noise.map_or(0.0, |n| n.offset.abs().max_element() as f64);
    let dn = noise.map_or(0.0, |n| {
        let (mut wf, mut w, mut f, mut norm) = (0.0, 1.0, n.frequency, 0.0);
        for _ in 0..n.octaves {
            wf += w * f;
            norm += w;
            w *= 0.5;
            f *= 2.0;
        }
        9.0 * 2f64.powi(-20) * m_noise * wf / norm + 2e-6
    });
    let a = noise.map_or(0.0, |n| n.amplitude);
    // Largest offset of the GPU's f32 cell centre from the exact one, per axis times √3.
    let delta = 2f64.powi(-20) * m * 3f64.sqrt();
    let r = p.grid.resolution;
    let (mut worst_ratio, mut worst_rel) = (0.0f64, 0.0f64);
    for k in 0..r.z {
        for j in 0..r.y {
            for i in 0..r.x {
                let x = cell_center64(&p.grid, i, j, k);
                let base = p.medium.base_at(x.y);
                let (mut plain, mut noisy, mut edge, mut shift) = (0.0, 0.0, 0.0, 0.0);
                for q in p.visible_particles() {
                    let d2 = (x - q.center.as_dvec3()).length_squared();
                    let rc2 = (cutoff_radius(q) as f64).powi(2);
                    let v = q.density as f64 * (-d2 / (q.radius as f64).powi(2)).exp();
                    let modulated = noise.is_some() && q.noise;
                    let scale = if modulated { 1.0 + a } else { 1.0 };
                    if (d2 / rc2 - 1.0).abs() < 1e-4 {
                        edge += v * scale;
                    }
                    if d2 < rc2 {
                        // The GPU's cell centre is off by up to δ: the gaussian by 2·d·δ/r².
                        shift += v * scale * 2.0 * d2.sqrt() * delta / (q.radius as f64).powi(2);
                    }
                    if d2 < rc2 {
                        if modulated {
                            noisy += v;
                        } else {
                            plain += v;
                        }
                    }
                }
                let want =
                    base + plain + noise.map_or(noisy, |n| if noisy > 0.0 { noisy * n.modulation(x) } else { 0.0 });
                let got = ev.get(i, j, k) as f64;
                assert!(got.is_finite() && got >= 0.0, "cell ({i},{j},{k}): {got}");
                let bound = 1e-5 * (base + plain + (1.0 + a) * noisy) + noisy * a * dn + edge + shift + 1e-30;
                let err = (got - want).abs();
                assert!(
                    err <= bound,
                    "cell ({i},{j},{k}) at {x}: GPU {got}, reference {want}, error {err:e} > bound {bound:e}"
                );
                worst_ratio = worst_ratio.max(err / bound);
                if want > 1e-6 {
                    worst_rel = worst_rel.max(err / want);
                }
            }
        }
    }
    (worst_ratio, worst_rel)
}

/// Random scenes: small (a cell or two) and large particles, some not taking the noise;
/// grids thin along one axis or not; first-octave frequencies from a tenth of the box to
/// finer than two cells (aliasing, octaves dropped); 1–8 octaves; amplitudes up to 20, so
/// max(0, 1 + a·n) clips; seeds up to u32::MAX (seed + o wraps).
#[test]
fn ev_with_noise_matches_the_f64_reference_on_random_scenes() {
    let mut gpu = pipeline();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    let (mut worst_ratio, mut worst_rel) = (0.0f64, 0.0f64);
    for scene_no in 0..14 {
        let min = rng.vec3(-6.0, 6.0);
        let size = rng.vec3(0.5, 4.0);
        let mut res =
            UVec3::new(8 + (rng.f32() * 20.0) as u32, 8 + (rng.f32() * 20.0) as u32, 8 + (rng.f32() * 20.0) as u32);
        if scene_no % 3 == 1 {
            res[scene_no % 3 + (scene_no / 3) % 2] = 1 + (rng.f32() * 2.0) as u32;
        }
        let grid = GridSpec { min, max: min + size, resolution: res };
        let cell = grid.cell_size().min_element();
        let particles = (0..1 + (rng.f32() * 6.0) as usize)
            .map(|n| {
                let radius =
                    if n % 2 == 0 { cell * rng.range(0.6, 2.0) } else { size.max_element() * rng.range(0.2, 0.8) };
                let mut q = Particle::new(min + size * rng.vec3(0.0, 1.0), radius, rng.range(0.1, 30.0));
                q.noise = rng.f32() < 0.75;
                q
            })
            .collect();
        let frequency =
            (0.1 + rng.f32() * 10.0 / size.min_element()) * if scene_no % 5 == 4 { 8.0 / cell } else { 1.0 };
        let amplitude = [0.3, 0.9, 2.5, 20.0][scene_no % 4];
        let seed = if scene_no % 3 == 0 { u32::MAX - (rng.f32() * 4.0) as u32 } else { (rng.f32() * 1e6) as u32 };
        let noise = Noise::new(amplitude, frequency, 1 + (rng.f32() * 8.0) as u32, seed);
        let p = scene(grid, if scene_no % 2 == 0 { 0.05 } else { 0.0 }, particles, Some(noise));
        let (ev, _) = bake(&mut gpu, &p);
        let (ratio, rel) = compare(&p, &ev);
        println!(
            "scene {scene_no}: res {:?}, {} particles, noise {:?} ({} octaves kept): error/bound {ratio:.3}, max relative error {rel:.2e}",
            res.to_array(),
            p.particles.len(),
            noise,
            noise.effective_octaves(&grid)
        );
        worst_ratio = worst_ratio.max(ratio);
        worst_rel = worst_rel.max(rel);
    }
    println!("noisy EV vs f64 reference: worst error/bound {worst_ratio:.3}, worst relative error {worst_rel:.2e}");
}

/// One octave on a grid whose cell centres are the noise's lattice points: there n(x) is the
/// lattice value itself, so the EV with noise over the EV without is 1 + h(i, j, k, seed),
/// which pins the GPU's hash to the CPU's (to f32's 24 bits of h) at 4096 lattice points,
/// negative indices and wrapping seeds included. Also: noise edits re-inject, a repeated
/// update does not, and a particle that does not take the noise is left as it was.
#[test]
fn gpu_hash_matches_the_cpu_at_lattice_points_and_noise_edits_reinject() {
    let mut gpu = pipeline();
    let grid = GridSpec { min: Vec3::splat(-8.5), max: Vec3::splat(7.5), resolution: UVec3::splat(16) };
    let blob = Particle::new(Vec3::new(0.3, -0.2, 0.1), 1e3, 1.0);
    let mut p = scene(grid, 0.0, vec![blob], None);
    let (plain, _) = bake(&mut gpu, &p);
    for seed in [0u32, 12345, u32::MAX] {
        p.medium.noise = Some(Noise::new(1.0, 1.0, 3, seed));
        assert_eq!(p.medium.noise.unwrap().effective_octaves(&grid), 1);
        let (noisy, injected) = bake(&mut gpu, &p);
        assert_eq!(injected, grid.cell_count(), "a noise edit re-injects every cell");
        let mut wrong_seed_agrees = 0;
        for k in 0..16u32 {
            for j in 0..16u32 {
                for i in 0..16u32 {
                    let x = cell_center64(&grid, i, j, k);
                    let (li, lj, lk) = (x.x as i32, x.y as i32, x.z as i32);
                    assert_eq!(DVec3::new(li as f64, lj as f64, lk as f64), x, "cell centres are lattice points");
                    let ratio = noisy.get(i, j, k) as f64 / plain.get(i, j, k) as f64;
                    let want = 1.0 + lattice_value(li, lj, lk, seed);
                    assert!(
                        (ratio - want).abs() <= 4.0 * 2f64.powi(-23),
                        "seed {seed}, lattice ({li},{lj},{lk}): GPU {ratio}, CPU {want}"
                    );
                    if (ratio - 1.0 - lattice_value(li, lj, lk, seed.wrapping_add(1))).abs() <= 4.0 * 2f64.powi(-23) {
                        wrong_seed_agrees += 1;
                    }
                }
            }
        }
        assert!(wrong_seed_agrees < 4, "the check tells seeds apart ({wrong_seed_agrees} matches)");
        assert_eq!(bake(&mut gpu, &p).1, 0, "an unchanged project re-injects nothing");
    }
    p.particles[0].noise = false;
    let (off, injected) = bake(&mut gpu, &p);
    assert!(injected > 0, "the particle's noise flag re-injects its bricks");
    assert_eq!(off.data, plain.data, "a particle without noise is injected as without any noise");
}

/// Two octaves kept (seed + 1 wrapping past u32::MAX) at lattice points of both, and the
/// octave sum in general, through the general bound.
#[test]
fn octaves_and_thin_grids_match_the_reference() {
    let mut gpu = pipeline();
    for (res, noise) in [
        (UVec3::new(16, 16, 16), Noise::new(3.0, 0.25, 5, u32::MAX)),
        (UVec3::new(40, 1, 33), Noise::new(1.5, 0.7, 6, 77)),
        (UVec3::new(2, 64, 3), Noise::new(0.5, 3.0, 4, 1 << 31)),
    ] {
        let grid = GridSpec { min: Vec3::splat(-8.5), max: Vec3::splat(7.5), resolution: res };
        let particles = vec![
            Particle::new(Vec3::new(0.3, -0.2, 0.1), 6.0, 2.0),
            Particle::new(Vec3::new(-3.0, 2.0, 1.0), 1.5, 9.0),
        ];
        let p = scene(grid, 0.02, particles, Some(noise));
        let (ev, _) = bake(&mut gpu, &p);
        let (ratio, rel) = compare(&p, &ev);
        println!(
            "res {:?}, {noise:?} ({} kept): error/bound {ratio:.3}, max relative error {rel:.2e}",
            res.to_array(),
            noise.effective_octaves(&grid)
        );
    }
}

/// Frequencies far above the grid's Nyquist limit, huge seeds and amplitudes, and a grid far
/// from the origin: every cell finite, never negative, never above (1 + a)·σ.
#[test]
fn extreme_noise_stays_finite() {
    let mut gpu = pipeline();
    for (min, frequency) in [(Vec3::splat(-1.0), 1e6f32), (Vec3::new(1e5, -3e5, 7e5), 1e6), (Vec3::splat(-1.0), 1e-6)] {
        let grid = GridSpec { min, max: min + 2.0, resolution: UVec3::splat(12) };
        let centre = min + 1.0;
        let noise = Noise::new(100.0, frequency, 16, u32::MAX);
        let p = scene(grid, 0.0, vec![Particle::new(centre, 0.7, 5.0)], Some(noise));
        let (ev, _) = bake(&mut gpu, &p);
        for (n, &v) in ev.data.iter().enumerate() {
            let [i, j, k] = grid.cell_of(n);
            let x = cell_center64(&grid, i, j, k);
            // The f32 cell centres of a grid 1e6 m out are off by up to a few 1/16 m ulps.
            let d = ((x - centre.as_dvec3()).length() - 0.2).max(0.0);
            let sigma = 5.0 * (-d * d / 0.49).exp();
            assert!(
                v.is_finite() && v >= 0.0 && v as f64 <= 101.0 * sigma * (1.0 + 1e-5) + 1e-30,
                "{frequency}: cell {n}: {v}"
            );
        }
        let kept = noise.effective_octaves(&grid);
        let note = noise.nyquist_note(&grid);
        if frequency > 1.0 {
            assert_eq!(kept, 1);
            let note = note.expect("a note");
            assert!(note.contains("15 of 16 octaves") && note.contains("aliases"), "{note}");
        } else {
            assert_eq!(kept, 16);
            assert_eq!(note, None);
        }
    }
}

/// `fogsmith render` says on stderr which octaves the grid drops, and nothing when none are.
#[test]
fn render_warns_about_dropped_octaves() {
    let dir = common::temp_dir();
    let project = |octaves: u32| {
        format!(
            "Project(grid: (min: (-1, -1, -1), max: (1, 1, 1), resolution: (16, 16, 16)), medium: (noise: Some((0.8, 1, {octaves}, 3))), particles: [(center: (0, 0, 0), radius: 0.5, density: 3)], render: (width: 16, height: 12))"
        )
    };
    // Cells of 0.125 m: octaves of spacing 1, 0.5, 0.25 are kept, finer ones dropped.
    for (octaves, want) in [(6, Some("3 of 6 octaves above the grid's Nyquist limit are dropped")), (3, None)] {
        let path = dir.path().join(format!("noise{octaves}.ron"));
        std::fs::write(&path, project(octaves)).unwrap();
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_fogsmith"))
            .args(["render", path.to_str().unwrap(), "-o", dir.path().join("out.png").to_str().unwrap(), "--quiet"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{stderr}");
        match want {
            Some(w) => assert!(stderr.contains(w) && stderr.contains("warning"), "{stderr}"),
            None => assert!(!stderr.contains("octave"), "{stderr}"),
        }
    }
}

/// The OPV of a noisy scene: its reference through the analytic medium includes the noise
/// (the GPU is far closer to it than to the same scene's reference without noise), and the
/// propagation's own error, against the grid's medium, is what it is without noise.
#[test]
fn opv_of_a_noisy_scene_matches_the_reference_with_noise() {
    use fogsmith::measure::{opv_errors, sample_cells};
    use fogsmith::scene::{Light, Scheme};
    let mut gpu = pipeline();
    let grid = GridSpec { min: Vec3::splat(-1.0), max: Vec3::ONE, resolution: UVec3::splat(32) };
    let particles =
        vec![Particle::new(Vec3::new(0.1, 0.0, -0.1), 0.6, 3.0), Particle::new(Vec3::new(-0.4, 0.3, 0.3), 0.35, 5.0)];
    let mut p = scene(grid, 0.05, particles, Some(Noise::new(1.5, 2.0, 5, 21)));
    p.lights = vec![Light::new(Vec3::new(0.8, 0.9, -0.7), 5.0, Vec3::ONE)];
    p.propagation.scheme = Scheme::Exact;
    let (ev, _) = bake(&mut gpu, &p);
    let opv = gpu.read_opv(0).unwrap();
    let cells = sample_cells(&p.grid, 600);
    let with = opv_errors(&p, 0, &ev, &opv, &cells);
    let mut smooth = p.clone();
    smooth.medium.noise = None;
    let without = opv_errors(&smooth, 0, &ev, &opv, &cells);
    let (scheme, total, wrong) = (
        with.scheme.transmittance_max_abs_error,
        with.total.transmittance_max_abs_error,
        without.total.transmittance_max_abs_error,
    );
    println!("noisy OPV (exact scheme, 32³, {} octaves kept): scheme error {scheme:.2e}, total against the noisy reference {total:.2e}, against the noise-free one {wrong:.2e}", p.medium.noise.unwrap().effective_octaves(&grid));
    assert!(!with.scheme.nan_or_inf);
    assert!(scheme <= 1e-3, "scheme error {scheme:e}");
    assert!(total * 4.0 < wrong, "the reference holds the noise: {total:e} vs {wrong:e} without it");
}

/// Wind: the noise drifts as x − offset, with the offset an animation's still carries
/// (velocity·t from `Project::at_frame`). At integer offsets the drifted cell centres are
/// still lattice points, so the EV ratio is 1 + h(i − ox, j − oy, k − oz) exactly: this pins
/// the drift's sign and axes on the GPU to the CPU's. At general offsets (frames of an
/// animation with wind) the EV matches the f64 reference within the f32 bound, and differs
/// from the undrifted EV.
#[test]
fn drifting_noise_matches_the_reference_at_several_times() {
    use fogsmith::scene::Animation;
    let mut gpu = pipeline();
    let grid = GridSpec { min: Vec3::splat(-8.5), max: Vec3::splat(7.5), resolution: UVec3::splat(16) };
    let blob = Particle::new(Vec3::new(0.3, -0.2, 0.1), 1e3, 1.0);
    let mut p = scene(grid, 0.0, vec![blob], None);
    let (plain, _) = bake(&mut gpu, &p);
    for offset in [Vec3::new(3.0, -2.0, 5.0), Vec3::new(-40.0, 17.0, 0.0)] {
        p.medium.noise = Some(Noise { offset, ..Noise::new(1.0, 1.0, 1, 99) });
        let (noisy, _) = bake(&mut gpu, &p);
        for k in 0..16u32 {
            for j in 0..16u32 {
                for i in 0..16u32 {
                    let x = cell_center64(&grid, i, j, k);
                    let (li, lj, lk) =
                        (x.x as i32 - offset.x as i32, x.y as i32 - offset.y as i32, x.z as i32 - offset.z as i32);
                    let ratio = noisy.get(i, j, k) as f64 / plain.get(i, j, k) as f64;
                    let want = 1.0 + lattice_value(li, lj, lk, 99);
                    assert!(
                        (ratio - want).abs() <= 4.0 * 2f64.powi(-23),
                        "offset {offset}, lattice ({li},{lj},{lk}): GPU {ratio}, CPU {want}"
                    );
                }
            }
        }
    }

    let grid = GridSpec {
        min: Vec3::new(-2.0, -1.0, -2.5),
        max: Vec3::new(2.0, 2.0, 1.5),
        resolution: UVec3::new(20, 14, 18),
    };
    let particles =
        vec![Particle::new(Vec3::new(0.3, 0.4, -0.5), 1.4, 2.0), Particle::new(Vec3::new(-1.0, 1.0, 0.5), 0.5, 6.0)];
    let mut p = scene(grid, 0.02, particles, None);
    p.medium.noise = Some(Noise { velocity: Vec3::new(1.3, -0.4, 2.7), ..Noise::new(2.5, 1.7, 4, u32::MAX) });
    p.animation = Some(Animation { fps: 24.0, start: 1, end: 2400 });
    let (still_ev, _) = bake(&mut gpu, &p.at_frame(0));
    for frame in [1, 7, 25, 240, 2400] {
        let still = p.at_frame(frame);
        let offset = still.medium.noise.unwrap().offset;
        assert_eq!(offset, Vec3::new(1.3, -0.4, 2.7) * (frame as f64 / 24.0) as f32);
        let (ev, _) = bake(&mut gpu, &still);
        let (ratio, rel) = compare(&still, &ev);
        println!("frame {frame}, offset {offset}: error/bound {ratio:.3}, max relative error {rel:.2e}");
        let moved = ev.data.iter().zip(&still_ev.data).filter(|(a, b)| a != b).count();
        assert!(moved * 2 > ev.data.len(), "frame {frame}: the wind moves the noise ({moved} cells changed)");
    }
}

//! What a call to the pipeline did and where it stands: counters, stage timings, the stage
//! still to run. Plain data, shared by the stages (which count their work) and the scheduler
//! (which times it and reports progress).

use std::ops::AddAssign;

/// Time per stage in milliseconds: GPU timestamps on hardware adapters that have them (see
/// [`FrameReport::gpu_timestamps`]), else wall time of the stage's host work, submits and
/// drained queue.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimings {
    pub inject: f64,
    pub propagate: f64,
    /// The multiple-scattering solve (`scattering`); 0 when none ran.
    pub scatter: f64,
    pub march: f64,
}

impl AddAssign for StageTimings {
    fn add_assign(&mut self, other: Self) {
        self.inject += other.inject;
        self.propagate += other.propagate;
        self.scatter += other.scatter;
        self.march += other.march;
    }
}

/// What a call did. Tests read these to prove that work was skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub dispatches: u32,
    pub cells_injected: u64,
    /// Particle–cell pairs injection evaluated (list lengths × cells of the bins it read).
    pub particle_evaluations: u64,
    /// Memory chunks whose particle–bin lists injection built and uploaded.
    pub inject_chunks: u32,
    pub cells_propagated: u64,
    pub lights_propagated: u32,
    /// Lights whose OPV was up to date, or that are hidden, dark or culled.
    pub lights_skipped: u32,
    /// Lights skipped because their contribution is provably negligible
    /// (see [`light_is_negligible`](super::light_is_negligible)).
    pub lights_culled: u32,
    /// Jacobi iterations (`giroud`) or dispatches (`sweep`, batches of shells of all lights).
    pub propagation_iterations: u32,
    pub samples_marched: u64,
    /// Empty 8³ bricks camera rays jumped over.
    pub bricks_skipped: u64,
    /// Rays stopped early because their transmittance fell below the cutoff.
    pub rays_terminated: u64,
    /// Camera rays marched: every pixel per-pixel; with adaptive sampling, the lattice and the
    /// rays refinement listed (padding included).
    pub rays_marched: u64,
}

/// Adds the counts of a later slice of the same update: work done adds up, the iteration
/// count is the largest, and the lights skipped and culled stay those judged by the first
/// slice (later slices judge the same lights again).
impl AddAssign for Counters {
    fn add_assign(&mut self, d: Self) {
        self.dispatches += d.dispatches;
        self.cells_injected += d.cells_injected;
        self.particle_evaluations += d.particle_evaluations;
        self.inject_chunks += d.inject_chunks;
        self.cells_propagated += d.cells_propagated;
        self.lights_propagated += d.lights_propagated;
        self.propagation_iterations = self.propagation_iterations.max(d.propagation_iterations);
        self.samples_marched += d.samples_marched;
        self.bricks_skipped += d.bricks_skipped;
        self.rays_terminated += d.rays_terminated;
        self.rays_marched += d.rays_marched;
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameReport {
    pub timings_ms: StageTimings,
    /// Whether `timings_ms` comes from GPU timestamp queries.
    pub gpu_timestamps: bool,
    pub counters: Counters,
}

/// Adds a later slice of the same update (see [`Counters`]' `AddAssign`).
impl AddAssign for FrameReport {
    fn add_assign(&mut self, other: Self) {
        self.timings_ms += other.timings_ms;
        self.counters += other.counters;
    }
}

/// The stage a pipeline is working on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum Stage {
    Inject,
    /// Propagating `lights` lights' optical depths.
    Propagate {
        lights: u32,
    },
    /// The multiple-scattering solve.
    Scatter,
    /// The full-resolution march.
    March,
    /// Nothing left: the shown image is full resolution with fresh optical depths.
    #[default]
    Done,
}

impl Stage {
    /// What the pipeline is doing, in words (progress bars and the status bar).
    pub fn name(self) -> String {
        match self {
            Stage::Inject => "inject".into(),
            Stage::Propagate { lights } => format!("propagate {lights} light{}", if lights == 1 { "" } else { "s" }),
            Stage::Scatter => "multiple scattering".into(),
            Stage::March => "march".into(),
            Stage::Done => "done".into(),
        }
    }
}

/// What [`FogPipeline::advance`](super::FogPipeline::advance) left behind.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Progress {
    /// What this call ran.
    pub report: FrameReport,
    /// A new image is on show since the previous call.
    pub new_image: bool,
    /// The image on show is of the scene of this call, optical depths aside (see
    /// `shadows_stale`): an edit that changed nothing the image shows needs no new one.
    pub shows_scene: bool,
    /// Size of the image on show (smaller than requested while the preview is refining).
    pub shown_size: [u32; 2],
    /// The image on show reads optical depths that lag the scene (moved lights, edited fog).
    pub shadows_stale: bool,
    /// The stage still to run, [`Stage::Done`] once converged.
    pub stage: Stage,
    /// Fraction of that stage done, in [0, 1].
    pub stage_fraction: f64,
}

impl Progress {
    pub fn converged(&self) -> bool {
        self.stage == Stage::Done
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_later_slice_adds_work_and_keeps_the_first_slices_judgements() {
        let mut total = Counters {
            dispatches: 2,
            lights_skipped: 1,
            lights_culled: 1,
            propagation_iterations: 5,
            ..Default::default()
        };
        total += Counters {
            dispatches: 3,
            samples_marched: 7,
            lights_skipped: 4,
            lights_culled: 4,
            propagation_iterations: 3,
            ..Default::default()
        };
        assert_eq!(
            total,
            Counters {
                dispatches: 5,
                samples_marched: 7,
                lights_skipped: 1,
                lights_culled: 1,
                propagation_iterations: 5,
                ..Default::default()
            }
        );
    }
}

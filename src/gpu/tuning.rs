//! [`Tuning`]: the pipeline's measurement switches. Each runs a stage another way that gives
//! the same result (the same image, the same volumes bit for bit) at another cost, so that
//! tests and benchmarks can compare the ways; [`Tuning::default`] is what a pipeline runs
//! with. `FogPipeline`'s `set_*` methods change them, and drop what a change invalidates.

/// Where injection sums the particles' gaussians into each cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InjectPath {
    /// The host on a software adapter (which runs on the same cores, where native loops over
    /// each particle's cells beat the shader's list walk many times over) for scenes dense
    /// in particles ([`HOST_MIN_ENTRIES_PER_BRICK`](super::HOST_MIN_ENTRIES_PER_BRICK)), the
    /// adapter otherwise. Brute-force injection and a fixed bin edge measure the adapter's
    /// path, so they select it.
    #[default]
    Auto,
    /// `host_sums`: the host scatters each particle over its cells; the adapter adds the
    /// base fog, layer and noise.
    Host,
    /// `shaders/inject.wgsl`: each cell evaluates the particles binned around it.
    Adapter,
}

/// How the stages run, where several ways give the same result.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Tuning {
    /// Every march uses the march built for every light kind and medium
    /// (`MarchFeatures::ALL`) instead of the one built for its scene, for measuring what that
    /// saves. Default: off. Applies to marches begun after it changes.
    pub general_march: bool,
    /// Base fog outside the grid tests every surface for every light, instead of only those
    /// that can hide a point or spot light from the segment marched. Default: off. Applies to
    /// marches begun after it changes.
    pub exhaustive_fog_shadows: bool,
    /// Every cell evaluates every particle instead of only those binned into its brick: the
    /// brute-force injection, for measuring what binning saves. Default: off.
    pub brute_force_injection: bool,
    /// Cells each sweep thread solves (at least one). Default: None, the adapter's
    /// (`sweep_cells_per_thread`); one lets a CPU adapter run the configuration a GPU uses.
    pub sweep_cells_per_thread: Option<u32>,
    /// Where the injection sums the particles. Default: [`InjectPath::Auto`].
    pub inject_path: InjectPath,
    /// The edge, in cells across (1, 2, 4 or 8), of the bins of the injection's particle
    /// lists. Default: None, the edge with the fewest evaluations; tests and benchmarks
    /// compare fixed ones.
    pub inject_bin_edge: Option<u32>,
    /// Cap on the particle–bin list bytes of one injection chunk. Default: None, one storage
    /// binding, the most a chunk can use; smaller chunks bound memory more tightly at the
    /// cost of more passes.
    pub inject_chunk_bytes: Option<u64>,
}

impl Tuning {
    /// The cells each sweep thread solves on an adapter of `device_type`.
    pub fn sweep_cells(&self, device_type: wgpu::DeviceType) -> u32 {
        self.sweep_cells_per_thread.unwrap_or_else(|| super::propagate::sweep_cells_per_thread(device_type)).max(1)
    }
}

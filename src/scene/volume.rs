//! A dense scalar grid read back from the pipeline: what slices, exporters and tests consume.

use super::GridSpec;
use glam::Vec3;

/// Dense f32 values at cell centres of a [`GridSpec`], x fastest, then y, then z.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    pub grid: GridSpec,
    pub data: Vec<f32>,
}

impl Volume {
    pub fn new(grid: GridSpec, data: Vec<f32>) -> Self {
        assert_eq!(data.len() as u64, grid.cell_count(), "volume data does not match its grid");
        Self { grid, data }
    }
    pub fn dims(&self) -> [u32; 3] {
        self.grid.resolution.to_array()
    }
    pub fn get(&self, i: u32, j: u32, k: u32) -> f32 {
        self.data[self.grid.index(i, j, k)]
    }
    pub fn cell_center(&self, i: u32, j: u32, k: u32) -> Vec3 {
        self.grid.cell_center(i, j, k)
    }
    pub fn max_value(&self) -> f32 {
        self.data.iter().copied().fold(f32::NEG_INFINITY, f32::max)
    }
}

/// Dense RGB values at cell centres of a [`GridSpec`], x fastest, then y, then z: the baked
/// emission (W·m⁻³·sr⁻¹ per channel).
#[derive(Clone, Debug, PartialEq)]
pub struct Volume3 {
    pub grid: GridSpec,
    pub data: Vec<[f32; 3]>,
}

impl Volume3 {
    pub fn new(grid: GridSpec, data: Vec<[f32; 3]>) -> Self {
        assert_eq!(data.len() as u64, grid.cell_count(), "volume data does not match its grid");
        Self { grid, data }
    }
    pub fn get(&self, i: u32, j: u32, k: u32) -> [f32; 3] {
        self.data[self.grid.index(i, j, k)]
    }
    /// The largest component of any cell.
    pub fn max_value(&self) -> f32 {
        self.data.iter().flatten().copied().fold(0.0, f32::max)
    }
}

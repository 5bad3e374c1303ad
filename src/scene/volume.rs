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

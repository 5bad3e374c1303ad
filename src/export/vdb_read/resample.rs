//! Resampling an imported grid into a project's dense grid, as OpenVDB's `BoxSampler` does.

use super::VdbFloatGrid;
use crate::scene::GridSpec;

/// Resamples `vdb` into a project grid: the value at each cell centre, times `scale`.
///
/// Cell centres are carried into the grid's export frame ([`VdbFloatGrid::frame`]) and mapped
/// to the VDB's index space; where a centre falls on a voxel centre
/// (within 10⁻⁴ voxel on every axis) that voxel's value is taken exactly, elsewhere values are
/// interpolated trilinearly between the 8 surrounding voxel centres (OpenVDB's `BoxSampler`).
/// Outside the tree the background is used. Returns dense values, x fastest.
pub fn resample_into(grid: &GridSpec, vdb: &VdbFloatGrid, scale: f32) -> Vec<f32> {
    let r = grid.resolution;
    let mut out = Vec::with_capacity(grid.cell_count() as usize);
    let min = grid.min.to_array().map(f64::from);
    let h = grid.cell_size().to_array().map(f64::from);
    for k in 0..r.z {
        for j in 0..r.y {
            for i in 0..r.x {
                let w = [0, 1, 2].map(|a| min[a] + ([i, j, k][a] as f64 + 0.5) * h[a]);
                let p = vdb.transform.world_to_index(vdb.frame.point(w));
                out.push(sample(vdb, p) * scale);
            }
        }
    }
    out
}

fn to_index(x: f64) -> i32 {
    x.clamp(i32::MIN as f64 + 2.0, i32::MAX as f64 - 2.0) as i32
}

fn sample(vdb: &VdbFloatGrid, p: [f64; 3]) -> f32 {
    if !p.iter().all(|c| c.is_finite()) {
        return vdb.background;
    }
    let rounded = p.map(f64::round);
    if (0..3).all(|a| (p[a] - rounded[a]).abs() < 1e-4) {
        return vdb.value_at(rounded.map(to_index));
    }
    let base = p.map(f64::floor);
    let t = [0, 1, 2].map(|a| p[a] - base[a]);
    let b = base.map(to_index);
    let mut acc = 0.0f64;
    for corner in 0..8 {
        let d: [i32; 3] = [corner & 1, (corner >> 1) & 1, (corner >> 2) & 1];
        let mut wgt = 1.0;
        for a in 0..3 {
            wgt *= if d[a] == 1 { t[a] } else { 1.0 - t[a] };
        }
        if wgt != 0.0 {
            acc += wgt * vdb.value_at([b[0] + d[0], b[1] + d[1], b[2] + d[2]]) as f64;
        }
    }
    acc as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::frame::Frame;
    use crate::export::vdb_read::VdbTransform;
    use std::collections::HashMap;

    #[test]
    fn trilinear_between_voxel_centres() {
        let mut g = VdbFloatGrid {
            name: "t".into(),
            background: 0.0,
            transform: VdbTransform::axis_aligned([0.5; 3], [0.0; 3]),
            half: false,
            metadata: Vec::new(),
            frame: Frame::NATIVE,
            leaves: HashMap::new(),
            tiles: HashMap::new(),
        };
        g.tiles.insert((1, [0, 0, 0]), (2.0, true));
        // Between voxel 7 (inside the tile) and 8 (background): the mean.
        assert_eq!(sample(&g, [7.5, 3.0, 3.0]), 1.0);
        assert_eq!(sample(&g, [3.0, 3.0, 3.0]), 2.0);
        assert_eq!(sample(&g, [f64::NAN, 0.0, 0.0]), 0.0);
        assert_eq!(g.active_voxel_count(), 512);
        assert_eq!(g.active_bbox(), Some(([0; 3], [7; 3])));
    }
}

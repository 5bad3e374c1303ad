//! Slice views of the baked volumes: which field, axis and index to show, extracting the
//! 2D slice from a [`Volume`], colour maps and the exact optical depths used by the error views.

use crate::scene::{GridSpec, Project, Volume};
use egui::Color32;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Field {
    /// σ_t, the extinction volume.
    #[default]
    Extinction,
    /// T towards the chosen light.
    OpticalDepth,
    /// exp(−T) towards the chosen light.
    Transmittance,
    /// Scheme error |T − T_grid|: against the line integral through the grid's own trilinear
    /// medium (CPU reference, this slice only). What the propagation scheme adds.
    Error,
    /// Resolution error |T_grid − T_clipped|: the grid's medium against the analytic gaussians
    /// clipped to the box. What a finer grid would remove; no scheme can.
    ResolutionError,
}

impl Field {
    pub const ALL: [Field; 5] =
        [Field::Extinction, Field::OpticalDepth, Field::Transmittance, Field::Error, Field::ResolutionError];
    pub fn label(self) -> &'static str {
        match self {
            Field::Extinction => "EV σt",
            Field::OpticalDepth => "OPV optical depth τ",
            Field::Transmittance => "transmittance exp(−τ)",
            Field::Error => "scheme error |τ − τ grid|",
            Field::ResolutionError => "resolution error |τ grid − τ exact|",
        }
    }
    pub fn unit(self) -> &'static str {
        match self {
            Field::Extinction => "1/m",
            Field::Transmittance => "",
            Field::OpticalDepth | Field::Error | Field::ResolutionError => "(optical depth)",
        }
    }
    pub fn needs_light(self) -> bool {
        self != Field::Extinction
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Axis {
    X,
    #[default]
    Y,
    Z,
}

impl Axis {
    pub const ALL: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];
    pub fn index(self) -> usize {
        self as usize
    }
    /// The grid axes along the image's columns and rows (rows grow upwards).
    pub fn image_axes(self) -> (usize, usize) {
        match self {
            Axis::X => (2, 1),
            Axis::Y => (0, 2),
            Axis::Z => (0, 1),
        }
    }
    pub fn label(self) -> &'static str {
        ["X", "Y", "Z"][self.index()]
    }
    /// The axis colour, as Blender and Godot draw x, y and z.
    pub fn colour(self) -> Color32 {
        [Color32::from_rgb(235, 70, 80), Color32::from_rgb(120, 200, 40), Color32::from_rgb(60, 130, 240)][self.index()]
    }
}

/// World position of the slice plane: the centre of cell `index` along `axis`.
pub fn slice_position(grid: &GridSpec, axis: Axis, index: u32) -> f32 {
    let a = axis.index();
    let n = grid.resolution.to_array()[a].max(1);
    grid.min[a] + (index.min(n - 1) as f32 + 0.5) * grid.cell_size()[a]
}

/// The slice plane's corners in world space, counter-clockwise in the image (bottom-left,
/// bottom-right, top-right, top-left).
pub fn slice_plane_corners(grid: &GridSpec, axis: Axis, index: u32) -> [glam::Vec3; 4] {
    let (ua, va) = axis.image_axes();
    let at = slice_position(grid, axis, index);
    let corner = |u: f32, v: f32| {
        let mut p = glam::Vec3::ZERO;
        p[axis.index()] = at;
        p[ua] = u;
        p[va] = v;
        p
    };
    let (lo, hi) = (grid.min, grid.max);
    [corner(lo[ua], lo[va]), corner(hi[ua], lo[va]), corner(hi[ua], hi[va]), corner(lo[ua], hi[va])]
}

/// Labels of a slice image: along its columns (left to right), along its rows (bottom to
/// top), both with their world range, and the plane itself, e.g. ("x -1.00 … 1.00 m",
/// "y 0.00 … 2.00 m", "z = 0.016 m").
pub fn slice_axis_labels(grid: &GridSpec, axis: Axis, index: u32) -> [String; 3] {
    let (ua, va) = axis.image_axes();
    let name = |a: usize| ["x", "y", "z"][a];
    [
        format!("{} {:.2} … {:.2} m", name(ua), grid.min[ua], grid.max[ua]),
        format!("{} {:.2} … {:.2} m", name(va), grid.min[va], grid.max[va]),
        format!("{} = {:.3} m", name(axis.index()), slice_position(grid, axis, index)),
    ]
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Colormap {
    #[default]
    Viridis,
    Inferno,
    Magma,
    Grayscale,
}

impl Colormap {
    pub const ALL: [Colormap; 4] = [Colormap::Viridis, Colormap::Inferno, Colormap::Magma, Colormap::Grayscale];
    pub fn label(self) -> &'static str {
        match self {
            Colormap::Viridis => "viridis",
            Colormap::Inferno => "inferno",
            Colormap::Magma => "magma",
            Colormap::Grayscale => "grayscale",
        }
    }

    /// Colour at `t` in [0, 1].
    pub fn color(self, t: f32) -> Color32 {
        const VIRIDIS: [[u8; 3]; 9] = [
            [68, 1, 84],
            [71, 44, 122],
            [59, 81, 139],
            [44, 113, 142],
            [33, 144, 141],
            [39, 173, 129],
            [92, 200, 99],
            [170, 220, 50],
            [253, 231, 37],
        ];
        const INFERNO: [[u8; 3]; 9] = [
            [0, 0, 4],
            [31, 12, 72],
            [85, 15, 109],
            [136, 34, 106],
            [186, 54, 85],
            [227, 89, 51],
            [249, 140, 10],
            [249, 201, 50],
            [252, 255, 164],
        ];
        const MAGMA: [[u8; 3]; 9] = [
            [0, 0, 4],
            [28, 16, 68],
            [79, 18, 123],
            [129, 37, 129],
            [181, 54, 122],
            [229, 80, 100],
            [251, 135, 97],
            [254, 194, 135],
            [252, 253, 191],
        ];
        let t = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
        let lut = match self {
            Colormap::Viridis => &VIRIDIS,
            Colormap::Inferno => &INFERNO,
            Colormap::Magma => &MAGMA,
            Colormap::Grayscale => {
                let g = (t * 255.0 + 0.5) as u8;
                return Color32::from_rgb(g, g, g);
            }
        };
        let x = t * (lut.len() - 1) as f32;
        let i = (x.floor() as usize).min(lut.len() - 2);
        let f = x - i as f32;
        let mix = |a: u8, b: u8| (a as f32 + (b as f32 - a as f32) * f + 0.5) as u8;
        let (a, b) = (lut[i], lut[i + 1]);
        Color32::from_rgb(mix(a[0], b[0]), mix(a[1], b[1]), mix(a[2], b[2]))
    }
}

/// What the Slices panel shows; remembered between runs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct SliceSettings {
    pub field: Field,
    pub light: usize,
    pub axis: Axis,
    /// Slice index along `axis`.
    pub index: u32,
    pub colormap: Colormap,
    pub log: bool,
}

impl Default for SliceSettings {
    fn default() -> Self {
        Self { field: Field::Extinction, light: 0, axis: Axis::Z, index: 32, colormap: Colormap::Viridis, log: false }
    }
}

/// One slice of a volume: `width` × `height` values, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct Slice {
    pub axis: Axis,
    pub index: u32,
    pub width: usize,
    pub height: usize,
    pub values: Vec<f32>,
}

impl Slice {
    /// The grid cell shown at column `x`, row `y`.
    pub fn cell(&self, x: usize, y: usize) -> [u32; 3] {
        let (ua, va) = self.axis.image_axes();
        let mut c = [0u32; 3];
        c[self.axis.index()] = self.index;
        c[ua] = x as u32;
        c[va] = (self.height - 1 - y) as u32;
        c
    }

    /// Every cell of the slice in image order.
    pub fn cells(&self) -> Vec<[u32; 3]> {
        (0..self.height).flat_map(|y| (0..self.width).map(move |x| (x, y))).map(|(x, y)| self.cell(x, y)).collect()
    }

    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.values[y * self.width + x]
    }

    /// Smallest and largest finite values.
    pub fn range(&self) -> (f32, f32) {
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for &v in self.values.iter().filter(|v| v.is_finite()) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if lo > hi {
            (0.0, 1.0)
        } else {
            (lo, hi)
        }
    }
}

/// Clamps a slice index into the grid along `axis`.
pub fn clamp_index(grid: &GridSpec, axis: Axis, index: u32) -> u32 {
    index.min(grid.resolution.to_array()[axis.index()].saturating_sub(1))
}

/// The slice of `volume` at `index` along `axis`.
pub fn extract(volume: &Volume, axis: Axis, index: u32) -> Slice {
    let dims = volume.dims();
    let index = clamp_index(&volume.grid, axis, index);
    let (ua, va) = axis.image_axes();
    let (width, height) = (dims[ua] as usize, dims[va] as usize);
    let mut slice = Slice { axis, index, width, height, values: Vec::with_capacity(width * height) };
    for y in 0..height {
        for x in 0..width {
            let [i, j, k] = slice.cell(x, y);
            slice.values.push(volume.get(i, j, k));
        }
    }
    slice
}

/// The slice view of a plane read back from the GPU (see [`crate::gpu::Plane`]).
pub fn from_plane(plane: &crate::gpu::Plane, axis: Axis) -> Slice {
    let (ua, va) = axis.image_axes();
    let mut dims = [0u32; 3];
    let (a, b) = match axis.index() {
        0 => (1, 2),
        1 => (0, 2),
        _ => (0, 1),
    };
    dims[a] = plane.dims[0];
    dims[b] = plane.dims[1];
    let (width, height) = (dims[ua] as usize, dims[va] as usize);
    let mut slice = Slice { axis, index: plane.index, width, height, values: Vec::with_capacity(width * height) };
    for y in 0..height {
        for x in 0..width {
            let c = slice.cell(x, y);
            slice.values.push(plane.values[(c[a] + c[b] * plane.dims[0]) as usize]);
        }
    }
    slice
}

/// Maps a value to [0, 1] for colouring, linearly or on a log scale spanning six decades
/// below the maximum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale {
    pub lo: f32,
    pub hi: f32,
    pub log: bool,
}

impl Scale {
    pub fn for_range(lo: f32, hi: f32, log: bool) -> Self {
        if log {
            let hi = hi.max(1e-12);
            let lo = if lo > 0.0 { lo.max(hi * 1e-6) } else { hi * 1e-6 };
            Self { lo, hi: hi.max(lo * 1.0001), log }
        } else {
            let lo = lo.min(0.0);
            Self { lo, hi: if hi > lo { hi } else { lo + 1.0 }, log }
        }
    }
    pub fn normalize(&self, v: f32) -> f32 {
        if self.log {
            let v = v.max(self.lo);
            (v / self.lo).ln() / (self.hi / self.lo).ln()
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }
    /// The value at fraction `t` of the scale.
    pub fn value_at(&self, t: f32) -> f32 {
        if self.log {
            self.lo * (self.hi / self.lo).powf(t)
        } else {
            self.lo + (self.hi - self.lo) * t
        }
    }
}

/// The slice as an image ready for an egui texture.
pub fn colorize(slice: &Slice, colormap: Colormap, scale: &Scale) -> egui::ColorImage {
    let pixels = slice.values.iter().map(|&v| colormap.color(scale.normalize(v))).collect();
    egui::ColorImage::new([slice.width, slice.height], pixels)
}

/// Exact optical depths T(cell, light) on `cells`, from the CPU reference, both error views'
/// references in one: the first `cells.len()` values through the grid's own trilinear medium
/// (the analytic medium sampled at the cell centres, as the EV holds it), then as many through
/// the analytic medium clipped to the grid box (base fog beyond it), the most any grid can
/// hold, so neither view shows the particles' tails outside the box. `layer`: the project's
/// base volume as [`crate::export::load_base_layer`] returns it, part of both references.
pub fn exact_optical_depth(
    project: &Project,
    layer: Option<&crate::scene::Volume>,
    light: usize,
    cells: &[[u32; 3]],
) -> Result<Vec<f64>, String> {
    if light >= project.lights.len() {
        return Err(format!("light {light} does not exist"));
    }
    if layer.is_some_and(|v| v.grid != project.grid) {
        return Err("the base volume is not on the project's grid".into());
    }
    let exact = crate::reference::Medium64::for_project(project, layer);
    let medium = crate::reference::GridMedium64::sampled(&project.grid, &exact);
    let mut out = crate::reference::grid_light_depth_cells(project, &medium, light, cells);
    out.extend(crate::reference::clipped_optical_depth_cells_with(project, &exact, light, cells));
    Ok(out)
}

/// The error view `field` per value of an optical-depth slice, from the references of
/// [`exact_optical_depth`]: the scheme error |T − T_grid|, or the resolution error
/// |T_grid − T_clipped| (which does not depend on the slice's values).
pub fn error_slice(opv: &Slice, exact: &[f64], field: Field) -> Slice {
    let n = opv.values.len();
    let (grid, clipped) = exact.split_at(n.min(exact.len()));
    let values = match field {
        Field::ResolutionError => grid.iter().zip(clipped).map(|(&g, &c)| (g - c).abs() as f32).collect(),
        _ => opv.values.iter().zip(grid).map(|(&t, &g)| (t as f64 - g).abs() as f32).collect(),
    };
    Slice { values, ..opv.clone() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slices_index_cells_consistently() {
        let grid = GridSpec { resolution: glam::UVec3::new(3, 4, 5), ..GridSpec::default() };
        let data = (0..60).map(|i| i as f32).collect();
        let vol = Volume::new(grid, data);
        for axis in Axis::ALL {
            let s = extract(&vol, axis, 1);
            for y in 0..s.height {
                for x in 0..s.width {
                    let [i, j, k] = s.cell(x, y);
                    assert_eq!(s.get(x, y), vol.get(i, j, k));
                }
            }
        }
        let s = extract(&vol, Axis::Z, 9);
        assert_eq!((s.index, s.width, s.height), (4, 3, 4));
        assert_eq!(s.cell(0, 0), [0, 3, 4], "row 0 is the top (largest y)");
    }

    /// The scheme view compares the OPV with the grid-medium reference, the resolution view
    /// that reference with the clipped analytic one, on a scene where both are known.
    #[test]
    fn error_views_pick_their_references() {
        let mut p = Project {
            grid: GridSpec { min: glam::Vec3::ZERO, max: glam::Vec3::ONE, resolution: glam::UVec3::new(4, 4, 1) },
            particles: Vec::new(),
            lights: vec![crate::scene::Light::new(glam::Vec3::new(3.0, 0.5, 0.5), 1.0, glam::Vec3::ONE)],
            ..Project::default()
        };
        p.medium.base_extinction = 0.5;
        let vol = Volume::new(p.grid, vec![0.0; 16]);
        let slice = extract(&vol, Axis::Z, 0);
        let cells = slice.cells();
        let exact = exact_optical_depth(&p, None, 0, &cells).unwrap();
        assert_eq!(exact.len(), 2 * cells.len());
        // Homogeneous fog: both references are β·distance, the OPV here is 0.
        let scheme = error_slice(&slice, &exact, Field::Error);
        let resolution = error_slice(&slice, &exact, Field::ResolutionError);
        for (n, c) in cells.iter().enumerate() {
            let x = crate::reference::cell_center64(&p.grid, c[0], c[1], c[2]);
            let d = 0.5 * (p.lights[0].position.as_dvec3() - x).length();
            assert!((scheme.values[n] as f64 - d).abs() < 1e-5, "{c:?}: {} vs {d}", scheme.values[n]);
            assert!(resolution.values[n].abs() < 1e-6, "{c:?}: {}", resolution.values[n]);
        }
        assert!(exact_optical_depth(&p, None, 1, &cells).is_err());
    }

    #[test]
    fn scales_map_the_range() {
        let lin = Scale::for_range(0.0, 4.0, false);
        assert_eq!(lin.normalize(1.0), 0.25);
        let log = Scale::for_range(1e-3, 10.0, true);
        assert!((log.normalize(10.0) - 1.0).abs() < 1e-6);
        assert!((log.value_at(log.normalize(0.5)) - 0.5).abs() < 1e-4);
        assert_eq!(Colormap::Grayscale.color(1.0), Color32::WHITE);
        assert_eq!(Colormap::Viridis.color(0.0), Color32::from_rgb(68, 1, 84));
    }
}

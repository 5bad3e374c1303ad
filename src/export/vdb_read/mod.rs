//! Importing a density grid from an OpenVDB file (OpenVDB, Houdini, Blender, or our writer).
//!
//! # Why our own reader and not vdb-rs
//!
//! Measured with vdb-rs 0.6.0 on files written by OpenVDB 10.0.1 (python3-openvdb and
//! vdb_tool) and by our writer, each read in a child process:
//!
//! | file | vdb-rs 0.6 |
//! |---|---|
//! | float, blosc / zip / uncompressed (OpenVDB) | correct (same active values as OpenVDB) |
//! | half, zip (our writer, `Tree_float_5_4_3_HalfFloat`) | **process abort**: "memory allocation of 71777214294589695 bytes failed", exit 134 |
//! | half, blosc (OpenVDB) and half, zip (vdb_tool) | `Err(InvalidNodeMetadata(128))` |
//! | `AffineMap` (rotated) / `NonlinearFrustumMap` grid | **panic** "Not supported AffineMap" / "… NonlinearFrustumMap" |
//! | Vec3s grid read as `[f32; 3]` | `Ok`, but iterates 0 voxels (silently empty) |
//! | grid with tiles | each tile is one item (261 633 items for 262 144 active voxels) |
//!
//! The abort cannot be contained (`catch_unwind` does not catch an allocation failure), so
//! vdb-rs could only be used behind a guard that parses the header, the descriptors, the
//! metadata and the transform itself and refuses half grids — and vdb-rs would then still
//! parse nodes with sizes read from the file unchecked. It also brings C code (blosc-src, built
//! with cc) and glam ≤ 0.24 next to our glam 0.30. The subset we need — float/half
//! `FloatGrid`s, uncompressed/zip/blosc, tiles, several grids — is the mirror of
//! [`super::vdb`]'s writer plus a blosc decoder: about as much code as the guard, with every
//! size checked against the bytes that are actually there. So: our own reader, pure Rust
//! (flate2 for zip, lz4_flex for blosc's LZ4), tested against OpenVDB's own files.
//!
//! # What it reads
//!
//! File format versions 222 to 224 (OpenVDB 3.0 and later; OpenVDB 10 writes 224), grids of type `Tree_float_5_4_3`
//! (float) and `Tree_float_5_4_3_HalfFloat`; value blocks uncompressed, zip, or blosc with the
//! LZ4 or zlib codec and byte shuffle (what OpenVDB writes). Transforms: uniform scale, scale,
//! translation, scale+translate and affine maps that permute and mirror the axes (every map
//! [`super::vdb`] writes, whatever the export frame). Everything else — other value
//! types (Vec3s, double...), instanced grids, rotated/sheared (not axis-permuting) affine maps,
//! frustum maps, bitshuffle, other blosc codecs — is refused with an error that names the file,
//! the grid and the problem. See [`super::vdb`] for the file layout.
//!
//! A grid whose metadata names an export frame (`up_axis`, `meters_per_unit`, `handedness`, as
//! Fogsmith writes them) is imported back into Fogsmith's own frame; see [`VdbFloatGrid::frame`].
//!
//! # Safety
//!
//! The whole file is read into memory (bounded by its real size); every count and size read
//! from it is checked against the bytes left before anything is allocated, decompressed blocks
//! have a fixed expected size (at most 32768 values of three components) and a grid may hold
//! at most [`MAX_LEAVES`] leaves and [`MAX_TILES`] tiles, so that memory stays within a small
//! multiple of the file's size and those limits. Each grid's topology must end where its
//! descriptor puts its values and its values where it puts its end (OpenVDB's own check), and
//! its tree must match the voxel count and bounds its metadata records: a damaged count is
//! refused rather than read as a different volume. Nothing here panics on any input.
//!
//! [`check_vdb_bytes`] reads every grid, vec3s ones included, for the farm's completeness check.
//!
//! # Parts
//!
//! `file` reads the header, the grid descriptors, metadata and transforms; `tree` the nodes
//! of one grid; `compression` their value blocks; `cursor` is the bounds-checked reader they
//! all use; `resample` carries a grid into a project's cells.

mod compression;
mod cursor;
mod file;
mod resample;
mod tree;

pub use resample::resample_into;

use super::frame::Frame;
use super::ExportError;
use crate::scene::{GridSpec, Volume};
use cursor::{checked_pos, Cursor};
use file::{float_type, parse_header, value_type, ValueType};
use std::collections::HashMap;
use std::path::Path;
use tree::read_grid;

/// Most leaves (8³ voxels) one imported grid may have: 2¹⁹ leaves = 268 M voxels (1 GiB).
pub const MAX_LEAVES: usize = 1 << 19;
/// Most tiles (constant blocks) one imported grid may keep: 2²² (about 200 MB of table).
pub const MAX_TILES: usize = 1 << 22;

/// Most cells a base volume is resampled into: 2³⁰ (4 GiB of f32), more than any adapter
/// binds as one buffer, so a larger project grid is refused before the dense copy is allocated.
pub const MAX_IMPORT_CELLS: u64 = 1 << 30;

/// A grid's entry in a file's table of contents.
#[derive(Clone, Debug, PartialEq)]
pub struct VdbGridInfo {
    pub name: String,
    /// The tree type, e.g. `Tree_float_5_4_3`, `Tree_float_5_4_3_HalfFloat`, `Tree_vec3s_5_4_3`.
    pub tree_type: String,
    /// Whether [`read_vdb_grid`] can import it (a float or half float grid, not an instance).
    pub importable: bool,
}

/// An axis-permuting index→world map: index axis a moves along world axis `axis[a]` by
/// `scale[a]` (signed) per voxel, so `world[axis[a]] = index[a] · scale[a] +
/// translation[axis[a]]`; voxel centres are at integer indices. `axis` is a permutation of
/// (0, 1, 2); for a plain scale-and-translate map it is the identity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VdbTransform {
    pub axis: [usize; 3],
    pub scale: [f64; 3],
    pub translation: [f64; 3],
}

impl VdbTransform {
    /// A map without permutation: `world = index · scale + translation`.
    pub fn axis_aligned(scale: [f64; 3], translation: [f64; 3]) -> Self {
        Self { axis: [0, 1, 2], scale, translation }
    }
    pub fn index_to_world(&self, ijk: [f64; 3]) -> [f64; 3] {
        let mut w = self.translation;
        for a in 0..3 {
            w[self.axis[a]] += ijk[a] * self.scale[a];
        }
        w
    }
    pub fn world_to_index(&self, xyz: [f64; 3]) -> [f64; 3] {
        [0, 1, 2].map(|a| (xyz[self.axis[a]] - self.translation[self.axis[a]]) / self.scale[a])
    }
}

/// A leaf: 8³ values, z fastest within the leaf, and its active mask.
#[derive(Clone, Debug)]
struct Leaf {
    mask: [u64; 8],
    values: Box<[f32; 512]>,
}

/// A float grid read from a file: sparse, with OpenVDB's accessor semantics.
#[derive(Clone, Debug)]
pub struct VdbFloatGrid {
    pub name: String,
    pub background: f32,
    pub transform: VdbTransform,
    /// Stored as half floats in the file.
    pub half: bool,
    /// The grid's metadata as (name, type name, raw bytes).
    pub metadata: Vec<(String, String, Vec<u8>)>,
    /// The export frame the grid's metadata names (`up_axis`, `meters_per_unit`,
    /// `handedness`); Fogsmith's own frame when it names none. [`resample_into`] carries
    /// project positions into this frame before it looks them up.
    pub frame: Frame,
    leaves: HashMap<[i32; 3], Leaf>,
    /// Tiles that differ from the background or are active: (level, origin) → (value, active).
    /// Level 1 covers 8³ voxels, 2 covers 128³, 3 covers 4096³ (a root tile).
    tiles: HashMap<(u8, [i32; 3]), (f32, bool)>,
}

const TILE_SHIFT: [u32; 4] = [0, 3, 7, 12];

impl VdbFloatGrid {
    /// The value OpenVDB's accessor returns at index `p` (active or not).
    pub fn value_at(&self, p: [i32; 3]) -> f32 {
        if let Some(leaf) = self.leaves.get(&p.map(|c| c & !7)) {
            return leaf.values[leaf_offset(p)];
        }
        for level in 1..=3u8 {
            let origin = p.map(|c| c & !((1i32 << TILE_SHIFT[level as usize]) - 1));
            if let Some(&(v, _)) = self.tiles.get(&(level, origin)) {
                return v;
            }
        }
        self.background
    }

    /// Whether the voxel at `p` is active.
    pub fn is_active(&self, p: [i32; 3]) -> bool {
        if let Some(leaf) = self.leaves.get(&p.map(|c| c & !7)) {
            let n = leaf_offset(p);
            return leaf.mask[n >> 6] >> (n & 63) & 1 == 1;
        }
        for level in 1..=3u8 {
            let origin = p.map(|c| c & !((1i32 << TILE_SHIFT[level as usize]) - 1));
            if let Some(&(_, on)) = self.tiles.get(&(level, origin)) {
                return on;
            }
        }
        false
    }

    /// Active voxels, tiles included (OpenVDB's `activeVoxelCount`).
    pub fn active_voxel_count(&self) -> u64 {
        let leaves: u64 = self.leaves.values().map(|l| l.mask.iter().map(|w| w.count_ones() as u64).sum::<u64>()).sum();
        let tiles: u64 = self
            .tiles
            .iter()
            .filter(|(_, (_, on))| *on)
            .map(|((level, _), _)| 1u64 << (3 * TILE_SHIFT[*level as usize]))
            .sum();
        leaves + tiles
    }

    /// Leaves in the grid.
    pub fn leaf_count(&self) -> usize {
        self.leaves.len()
    }

    /// Inclusive index bounds of the active voxels, or None when there are none.
    pub fn active_bbox(&self) -> Option<([i32; 3], [i32; 3])> {
        let mut lo = [i32::MAX; 3];
        let mut hi = [i32::MIN; 3];
        let mut grow = |a: [i32; 3], b: [i32; 3]| {
            for c in 0..3 {
                lo[c] = lo[c].min(a[c]);
                hi[c] = hi[c].max(b[c]);
            }
        };
        for (origin, leaf) in &self.leaves {
            for n in 0..512usize {
                if leaf.mask[n >> 6] >> (n & 63) & 1 == 1 {
                    let p =
                        [origin[0] + (n >> 6) as i32, origin[1] + ((n >> 3) & 7) as i32, origin[2] + (n & 7) as i32];
                    grow(p, p);
                }
            }
        }
        for ((level, origin), (_, on)) in &self.tiles {
            if *on {
                let size = (1i32 << TILE_SHIFT[*level as usize]) - 1;
                grow(*origin, origin.map(|c| c.saturating_add(size)));
            }
        }
        (lo[0] <= hi[0]).then_some((lo, hi))
    }
}

fn leaf_offset(p: [i32; 3]) -> usize {
    (((p[0] & 7) << 6) | ((p[1] & 7) << 3) | (p[2] & 7)) as usize
}

/// Imports a density grid as a base layer: reads grid `name` (see [`read_vdb_grid`]) and
/// resamples it into `target`'s cells, times `scale` (what a project's `base_volume` does).
pub fn import_density(path: &Path, name: Option<&str>, target: &GridSpec, scale: f32) -> Result<Volume, ExportError> {
    if !scale.is_finite() || scale < 0.0 {
        return Err(ExportError::invalid(
            path,
            format!("import scale {scale} is negative or not finite"),
            "use a scale >= 0",
        ));
    }
    if target.cell_count() > MAX_IMPORT_CELLS {
        let r = target.resolution;
        return Err(ExportError::invalid(
            path,
            format!(
                "the project grid {}×{}×{} has more cells than a base volume may fill ({MAX_IMPORT_CELLS})",
                r.x, r.y, r.z
            ),
            "lower grid.resolution",
        ));
    }
    let grid = read_vdb_grid(path, name)?;
    let data = resample_into(target, &grid, scale);
    let bad = data.iter().filter(|v| !v.is_finite() || **v < 0.0).count();
    if let Some(first) = data.iter().position(|v| !v.is_finite() || *v < 0.0) {
        let cell = target.cell_of(first);
        return Err(ExportError::invalid(
            path,
            format!(
                "grid {:?} gives {bad} cells a density that is negative or not finite (first: cell {cell:?}, value {})",
                grid.name, data[first]
            ),
            "a density must be finite and >= 0: import a fog density grid, not a level set, or lower base_volume.scale",
        ));
    }
    Ok(Volume { grid: *target, data })
}

/// Lists the grids of a VDB file.
pub fn list_vdb_grids(path: &Path) -> Result<Vec<VdbGridInfo>, ExportError> {
    let bytes = std::fs::read(path).map_err(|source| ExportError::Read { path: path.to_path_buf(), source })?;
    let file = parse_header(path, &bytes)?;
    Ok(file
        .descriptors
        .iter()
        .map(|d| VdbGridInfo {
            name: d.name.clone(),
            tree_type: d.tree_type.clone(),
            importable: d.instance_parent.is_empty() && float_type(&d.tree_type).is_some(),
        })
        .collect())
}

/// Reads the float grid named `name` (or, when None, the grid named `density`, else the
/// first float grid) from a VDB file.
pub fn read_vdb_grid(path: &Path, name: Option<&str>) -> Result<VdbFloatGrid, ExportError> {
    let bytes = std::fs::read(path).map_err(|source| ExportError::Read { path: path.to_path_buf(), source })?;
    read_vdb_grid_from_bytes(path, &bytes, name)
}

/// [`read_vdb_grid`] on a file already in memory; `path` names errors.
pub fn read_vdb_grid_from_bytes(path: &Path, bytes: &[u8], name: Option<&str>) -> Result<VdbFloatGrid, ExportError> {
    let file = parse_header(path, bytes)?;
    let names =
        || file.descriptors.iter().map(|d| format!("{:?} ({})", d.name, d.tree_type)).collect::<Vec<_>>().join(", ");
    let desc = match name {
        Some(n) => file.descriptors.iter().find(|d| d.name == n).ok_or_else(|| {
            ExportError::invalid(
                path,
                format!("no grid named {n:?}; the file has {}", names()),
                "pick one of the grids listed",
            )
        })?,
        None => file
            .descriptors
            .iter()
            .find(|d| d.name == "density" && float_type(&d.tree_type).is_some())
            .or_else(|| file.descriptors.iter().find(|d| float_type(&d.tree_type).is_some()))
            .ok_or_else(|| {
                ExportError::unsupported(
                    path,
                    format!("no float grid to import; the file has {}", names()),
                    "export a float density grid (FloatGrid)",
                )
            })?,
    };
    if !desc.instance_parent.is_empty() {
        return Err(ExportError::unsupported(
            path,
            format!("grid {:?} is an instance of grid {:?}, which is not supported", desc.name, desc.instance_parent),
            "import the parent grid, or save the file without instancing",
        ));
    }
    let half = float_type(&desc.tree_type).ok_or_else(|| {
        ExportError::unsupported(
            path,
            format!(
                "grid {:?} has type {}; only float grids (FloatGrid, float or half) can be imported as density",
                desc.name, desc.tree_type
            ),
            "export the density as a float grid",
        )
    })?;
    let mut cur = Cursor { path, bytes, pos: desc.grid_pos, version: file.version, grid: desc.name.clone() };
    cur.pos = checked_pos(&cur, desc.grid_pos)?;
    read_grid(&mut cur, desc, ValueType { half, components: 1 })
}

/// Reads every grid of a VDB file in memory, float and vec3s, float or half (every grid type
/// Fogsmith writes), to tell a whole file from a damaged one; `path` names errors. A file
/// without grids, and a grid of another type or an instance, are refused.
pub fn check_vdb_bytes(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    let file = parse_header(path, bytes)?;
    if file.descriptors.is_empty() {
        return Err(ExportError::invalid(
            path,
            "the file holds no grids (a damaged header?); every VDB Fogsmith writes holds at least one",
            "export it again",
        ));
    }
    for desc in &file.descriptors {
        let kind = value_type(&desc.tree_type).filter(|_| desc.instance_parent.is_empty()).ok_or_else(|| {
            ExportError::unsupported(
                path,
                format!("grid {:?} has type {}, which this check does not read", desc.name, desc.tree_type),
                "check the file with OpenVDB's vdb_print",
            )
        })?;
        let mut cur = Cursor { path, bytes, pos: desc.grid_pos, version: file.version, grid: desc.name.clone() };
        read_grid(&mut cur, desc, kind)?;
    }
    Ok(())
}

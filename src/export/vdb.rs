//! A small OpenVDB writer: baked grids as `.vdb` files that OpenVDB, Houdini and Blender open.
//!
//! # What is written
//!
//! One `FloatGrid` (tree type `Tree_float_5_4_3`, or `Tree_float_5_4_3_HalfFloat` when
//! [`VdbOptions::half`] is set) per [`VdbGrid`]: usually `density` (the extinction EV, 1/m,
//! grid class "fog volume") and per light `optical_depth_<i>` (T), optionally
//! `transmittance_<i>` (exp(−T)), both of class "unknown" since they are not densities; see
//! [`grids_from_volumes`]. A baked emission is a `Vec3SGrid` (`Tree_vec3s_5_4_3`, class
//! "unknown", vector type "invariant"), stored like a float grid with three values per voxel
//! and tile, and a background of three equal components.
//!
//! # File layout (OpenVDB file format 224, what OpenVDB 10 writes; all little-endian)
//!
//! ```text
//! header      i64 magic 0x56444220 (" BDV"), u32 file version 224, u32 library 10, u32 0,
//!             u8 1 (grid offsets present), 36 ASCII bytes uuid,
//!             file metadata (u32 count, entries as below), u32 grid count
//! per grid    descriptor: string name, string tree type, string "" (no instance parent),
//!             i64 grid position, i64 block position, i64 end position
//!   grid pos: u32 compression flags (2 = active-mask, | 1 = zip),
//!             metadata: u32 count, then per entry string name, string type, u32 size, bytes
//!             transform: string map type, then the map's Vec3d fields
//!             topology: i32 1 (buffer count); root: f32 background, u32 tile count (0),
//!             u32 child count, per child i32×3 origin + internal-5 topology
//!             internal node: child mask, value mask, compressed tile values, children
//!             leaf: value mask (64 bytes)
//!   block pos: per leaf, in the same order: value mask + compressed values
//! strings     u32 length + bytes
//! ```
//!
//! The tree is OpenVDB's standard one: root → internal nodes of 32³ children (covering 4096³
//! voxels) → internal nodes of 16³ children (128³ voxels) → leaves of 8³ voxels. Inside a
//! node, children and voxels are numbered with **z fastest** (`x·N² + y·N + z`), unlike
//! [`Volume`]'s x-fastest layout. Masks are arrays of u64 words, bit `n % 64` of word `n / 64`.
//!
//! # Sparsity
//!
//! A voxel is active when `|value − background| > threshold` (NaN is active). Inactive voxels
//! store the background (0 for density and optical depth, 1 for transmittance), so below the
//! threshold a value reads back as the background. Leaves without an active voxel are not
//! written. With [`VdbOptions::tiles`], a leaf whose 512 voxels are all active and equal is
//! written as an active constant tile of its 16³ parent node instead (homogeneous base fog).
//!
//! # Values ("compressed values")
//!
//! Every node's values are written as OpenVDB's `writeCompressedValues` does with active-mask
//! compression: one byte of metadata (0: every inactive value is the background), then only
//! the active values, as f32 or — with [`VdbOptions::half`] — as IEEE half floats rounded to
//! nearest even (what `saveFloatAsHalf` writes; the background and the inactive values stay
//! f32, truncated to half precision). With zip each value block is `i64 size` + zlib stream,
//! or `−size` + raw bytes when zlib does not make it smaller; an empty half block is omitted.
//! (OpenVDB itself never zips fog volumes, but reads zipped ones.)
//!
//! # Transform
//!
//! Index (i, j, k) is the project's cell (i, j, k) and maps to its centre `min + (i + ½)·h`,
//! carried into the export frame ([`VdbOptions::frame`], see [`super::frame`]) as
//! `scale · M · (min + (i + ½)·h)`. When M is the identity (a Y-up right-handed frame), cubic
//! cells give a `UniformScaleTranslateMap` and cells whose sizes differ by more than one part
//! in 10⁶ a `ScaleTranslateMap` with a per-axis scale, which OpenVDB and Houdini read alike
//! (some tools want uniform voxels; keep cells cubic for those). Any other frame gives an
//! `AffineMap` (a 4×4 row-vector matrix, translation in the last row) whose upper 3×3 is the
//! signed axis permutation M times the cell sizes: the voxels are not resampled.
//!
//! # Metadata per grid
//!
//! `name`, `class` ("fog volume" or "unknown"), `creator` ("fogsmith"), `file_compression`,
//! `file_bbox_min`/`file_bbox_max`, `file_voxel_count`, `is_saved_as_half_float` (half only),
//! the export frame as `up_axis` ("Y" or "Z"), `meters_per_unit` (double: 1 or 0.01) and
//! `handedness` ("right" or "left"), and on a light's grids `light_index` (int32, its place
//! in the list), `light_id` (int32, its stable id in the project), `light_position` (vec3s, in the export frame), `light_intensity` (float, W/sr),
//! `light_color` (vec3s, linear RGB). A frame of an animation adds `frame` (int32) and `fps`
//! (float). The file's own metadata holds `creator`, the export frame and the time, and for an
//! export of a project the medium's `fogsmith_albedo` and `fogsmith_anisotropy` (floats).

use super::frame::Frame;
use super::sequence::FrameTime;
use super::{write_bytes_atomic, ExportError, LightInfo};
use crate::scene::{GridSpec, Volume, Volume3};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

/// OpenVDB's file magic, " BDV" as an i64.
pub const VDB_MAGIC: i64 = 0x5644_4220;
/// The file format version written: 224, what OpenVDB 10 (and every release since 4.0) writes.
pub const VDB_FILE_VERSION: u32 = 224;
/// Compression flag: zlib.
pub const COMPRESS_ZIP: u32 = 1;
/// Compression flag: only active values are stored (plus the inactive ones' metadata).
pub const COMPRESS_ACTIVE_MASK: u32 = 2;
/// Compression flag: blosc (read only; the writer does not produce it).
pub const COMPRESS_BLOSC: u32 = 4;

/// How value blocks are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum VdbCompression {
    /// Raw values (active values only). Fastest to read and write.
    None,
    /// zlib per value block (flate2, level 6). The default: smaller, still fast.
    #[default]
    Zip,
}

/// Export settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VdbOptions {
    pub compression: VdbCompression,
    /// Store values as 16-bit half floats (`Tree_float_5_4_3_HalfFloat`). Default false.
    pub half: bool,
    /// Voxels with `|value − background| <= threshold` are inactive and read back as the
    /// background. Default 0: only exact background values are dropped.
    pub threshold: f32,
    /// Write fully active constant 8³ blocks as tiles. Default true.
    pub tiles: bool,
    /// Axes and units of the grids' world space. Default Fogsmith's own (Y-up, metres).
    pub frame: Frame,
    /// The animation frame and rate the grids are of; None for a still.
    pub time: Option<FrameTime>,
    /// The medium's albedo and anisotropy g, recorded in the file's metadata as
    /// `fogsmith_albedo` and `fogsmith_anisotropy` so that an importer (the Blender add-on)
    /// can build the fog's material from the file alone. Default None: neither is written.
    pub medium: Option<(f32, f32)>,
}

impl Default for VdbOptions {
    fn default() -> Self {
        Self {
            compression: VdbCompression::Zip,
            half: false,
            threshold: 0.0,
            tiles: true,
            frame: Frame::NATIVE,
            time: None,
            medium: None,
        }
    }
}

/// OpenVDB's grid class, which tells tools how to show a grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GridClass {
    /// A density (extinction): Blender and Houdini render it as fog.
    FogVolume,
    /// Any other scalar field (optical depth, transmittance).
    Unknown,
}

impl GridClass {
    pub fn as_str(self) -> &'static str {
        match self {
            GridClass::FogVolume => "fog volume",
            GridClass::Unknown => "unknown",
        }
    }
}

/// A metadata value attached to a grid.
#[derive(Clone, Debug, PartialEq)]
pub enum MetaValue {
    String(String),
    Float(f32),
    Double(f64),
    Int32(i32),
    Int64(i64),
    Bool(bool),
    Vec3i([i32; 3]),
    Vec3s([f32; 3]),
}

impl MetaValue {
    fn type_name(&self) -> &'static str {
        match self {
            MetaValue::String(_) => "string",
            MetaValue::Float(_) => "float",
            MetaValue::Double(_) => "double",
            MetaValue::Int32(_) => "int32",
            MetaValue::Int64(_) => "int64",
            MetaValue::Bool(_) => "bool",
            MetaValue::Vec3i(_) => "vec3i",
            MetaValue::Vec3s(_) => "vec3s",
        }
    }
    fn bytes(&self) -> Vec<u8> {
        match self {
            MetaValue::String(s) => s.as_bytes().to_vec(),
            MetaValue::Float(v) => v.to_le_bytes().to_vec(),
            MetaValue::Double(v) => v.to_le_bytes().to_vec(),
            MetaValue::Int32(v) => v.to_le_bytes().to_vec(),
            MetaValue::Int64(v) => v.to_le_bytes().to_vec(),
            MetaValue::Bool(v) => vec![*v as u8],
            MetaValue::Vec3i(v) => v.iter().flat_map(|c| c.to_le_bytes()).collect(),
            MetaValue::Vec3s(v) => v.iter().flat_map(|c| c.to_le_bytes()).collect(),
        }
    }
}

/// One grid to write: dense values on a project grid plus its name and metadata.
#[derive(Clone, Debug)]
pub struct VdbGrid<'a> {
    /// Grid name; unique within a file.
    pub name: String,
    pub spec: GridSpec,
    /// Dense values, x fastest (as [`Volume::data`]), `components` per cell.
    pub values: Cow<'a, [f32]>,
    /// 1: a float grid; 3: a vec3s grid (values interleaved per cell).
    pub components: usize,
    /// Value of inactive voxels and of everything outside the tree (every component).
    pub background: f32,
    pub class: GridClass,
    /// Extra metadata (light information...). `name`, `class`, `creator` and the `file_*`
    /// entries are added by the writer.
    pub metadata: Vec<(String, MetaValue)>,
}

impl<'a> VdbGrid<'a> {
    /// A grid viewing `volume` with background 0.
    pub fn from_volume(name: impl Into<String>, volume: &'a Volume) -> Self {
        Self {
            name: name.into(),
            spec: volume.grid,
            values: Cow::Borrowed(&volume.data),
            components: 1,
            background: 0.0,
            class: GridClass::FogVolume,
            metadata: Vec::new(),
        }
    }

    /// A vec3s grid viewing `volume` with background 0, class unknown and vector type
    /// invariant (a colour, not a direction: transforms leave it as it is).
    pub fn from_volume3(name: impl Into<String>, volume: &'a Volume3) -> Self {
        Self {
            name: name.into(),
            spec: volume.grid,
            values: Cow::Borrowed(volume.data.as_flattened()),
            components: 3,
            background: 0.0,
            class: GridClass::Unknown,
            metadata: vec![("vector_type".into(), MetaValue::String("invariant".into()))],
        }
    }
}

/// Which grids [`grids_from_volumes`] makes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct GridSelection {
    pub density: bool,
    pub optical_depth: bool,
    pub transmittance: bool,
}

impl Default for GridSelection {
    /// Density and optical depth; transmittance on request.
    fn default() -> Self {
        Self { density: true, optical_depth: true, transmittance: false }
    }
}

impl std::str::FromStr for GridSelection {
    type Err = String;
    /// Parses the CLI's `--grids density,optical_depth,transmittance` (any subset, in any
    /// order, at least one).
    fn from_str(s: &str) -> Result<Self, String> {
        let mut sel = GridSelection { density: false, optical_depth: false, transmittance: false };
        for word in s.split(',').map(str::trim).filter(|w| !w.is_empty()) {
            match word {
                "density" => sel.density = true,
                "optical_depth" => sel.optical_depth = true,
                "transmittance" => sel.transmittance = true,
                other => {
                    return Err(format!(
                        "unknown grid {other:?}: use density, optical_depth and/or transmittance, comma-separated"
                    ))
                }
            }
        }
        if sel == (GridSelection { density: false, optical_depth: false, transmittance: false }) {
            return Err("no grid selected: use density, optical_depth and/or transmittance, comma-separated".into());
        }
        Ok(sel)
    }
}

/// The standard grid list: `density` from the EV (class fog volume), and per light
/// `optical_depth_<i>` and (optionally) `transmittance_<i>` = exp(−T) with background 1 (class
/// unknown), each light grid carrying the light's metadata. Light positions are written as
/// given: pass them through [`LightInfo::in_frame`] for an export frame.
pub fn grids_from_volumes<'a>(
    ev: &'a Volume,
    lights: &'a [(&'a Volume, LightInfo)],
    which: GridSelection,
) -> Vec<VdbGrid<'a>> {
    let mut out = Vec::new();
    if which.density {
        out.push(VdbGrid::from_volume("density", ev));
    }
    for (i, (opv, light)) in lights.iter().enumerate() {
        let meta = vec![
            ("light_index".to_string(), MetaValue::Int32(i as i32)),
            ("light_id".to_string(), MetaValue::Int32(light.id as i32)),
            ("light_position".to_string(), MetaValue::Vec3s(light.position)),
            ("light_intensity".to_string(), MetaValue::Float(light.intensity)),
            ("light_color".to_string(), MetaValue::Vec3s(light.color)),
        ];
        if which.optical_depth {
            let mut g = VdbGrid::from_volume(format!("optical_depth_{i}"), opv);
            g.class = GridClass::Unknown;
            g.metadata = meta.clone();
            out.push(g);
        }
        if which.transmittance {
            let values: Vec<f32> = opv.data.iter().map(|t| (-t).exp()).collect();
            out.push(VdbGrid {
                name: format!("transmittance_{i}"),
                spec: opv.grid,
                values: Cow::Owned(values),
                components: 1,
                background: 1.0,
                class: GridClass::Unknown,
                metadata: meta,
            });
        }
    }
    out
}

/// What a write produced.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VdbStats {
    /// Size of the file written.
    pub bytes: u64,
    pub grids: Vec<VdbGridStats>,
}

/// Per-grid counts.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VdbGridStats {
    pub name: String,
    /// Active voxels, tiles included (OpenVDB's `activeVoxelCount`).
    pub active_voxels: u64,
    /// Leaves written.
    pub leaves: u64,
    /// Constant 8³ tiles written.
    pub tiles: u64,
    /// Bytes of this grid in the file.
    pub bytes: u64,
}

/// Writes `grids` to `path` as an OpenVDB file, atomically (temporary file + rename).
pub fn write_vdb(path: &Path, grids: &[VdbGrid], opts: &VdbOptions) -> Result<VdbStats, ExportError> {
    write_vdb_with_progress(path, grids, opts, &mut |_| {})
}

/// [`write_vdb`] reporting progress in [0, 1] (for the editor's background export).
pub fn write_vdb_with_progress(
    path: &Path,
    grids: &[VdbGrid],
    opts: &VdbOptions,
    progress: &mut dyn FnMut(f32),
) -> Result<VdbStats, ExportError> {
    let (bytes, stats) = encode_vdb_with_progress(path, grids, opts, progress)?;
    write_bytes_atomic(path, &bytes)?;
    progress(1.0);
    Ok(stats)
}

/// Encodes the file in memory (what [`write_vdb`] writes); `path` only names errors.
pub fn encode_vdb(path: &Path, grids: &[VdbGrid], opts: &VdbOptions) -> Result<(Vec<u8>, VdbStats), ExportError> {
    encode_vdb_with_progress(path, grids, opts, &mut |_| {})
}

fn encode_vdb_with_progress(
    path: &Path,
    grids: &[VdbGrid],
    opts: &VdbOptions,
    progress: &mut dyn FnMut(f32),
) -> Result<(Vec<u8>, VdbStats), ExportError> {
    check_grids(path, grids, opts)?;

    let mut out = Vec::new();
    out.extend_from_slice(&VDB_MAGIC.to_le_bytes());
    put_u32(&mut out, VDB_FILE_VERSION);
    put_u32(&mut out, 10);
    put_u32(&mut out, 0);
    out.push(1); // grid offsets follow each descriptor
    let uuid_at = out.len();
    // Filled in from the content once the file is encoded.
    out.extend_from_slice(&[b'0'; 36]);
    // File-level metadata, sorted by name.
    let mut file_meta: BTreeMap<&str, MetaValue> = frame_metadata(opts).into_iter().collect();
    file_meta.insert("creator", MetaValue::String("fogsmith".into()));
    if let Some((albedo, anisotropy)) = opts.medium {
        file_meta.insert("fogsmith_albedo", MetaValue::Float(albedo));
        file_meta.insert("fogsmith_anisotropy", MetaValue::Float(anisotropy));
    }
    put_u32(&mut out, file_meta.len() as u32);
    for (k, v) in &file_meta {
        put_meta(&mut out, k, v);
    }
    put_u32(&mut out, grids.len() as u32);

    let mut stats = VdbStats::default();
    // Progress counts 8-cell slabs of z, over all grids.
    let total: u64 = grids.iter().map(|g| g.spec.resolution.z.div_ceil(8) as u64).sum::<u64>().max(1);
    let mut done = 0u64;
    for g in grids {
        let start = out.len();
        let mut tick = || {
            done += 1;
            progress(done as f32 / total as f32 * 0.99);
        };
        let mut s = encode_grid(&mut out, g, opts, &mut tick);
        s.bytes = (out.len() - start) as u64;
        stats.grids.push(s);
    }
    stats.bytes = out.len() as u64;
    let uuid = content_uuid(&out[uuid_at + 36..]);
    out[uuid_at..uuid_at + 36].copy_from_slice(uuid.as_bytes());
    Ok((out, stats))
}

/// Refuses what no grid file can hold: a negative threshold, unnamed or duplicate grids, values
/// that do not match the grid, boxes without volume, indices beyond 2³⁰, and (for half
/// floats) values beyond half precision.
pub(super) fn check_grids(path: &Path, grids: &[VdbGrid], opts: &VdbOptions) -> Result<(), ExportError> {
    if opts.threshold.is_nan() || opts.threshold < 0.0 {
        return Err(ExportError::invalid(
            path,
            format!("threshold {} is negative or NaN", opts.threshold),
            "use a threshold >= 0",
        ));
    }
    for (n, g) in grids.iter().enumerate() {
        if opts.half {
            check_half_range(path, &format!("grid {:?}", g.name), &g.values, "write full floats (no half option)")?;
        }
        if g.name.is_empty() || g.name.contains('\u{1e}') {
            return Err(ExportError::invalid(
                path,
                format!("grid {n} has an empty or invalid name"),
                "name every grid",
            ));
        }
        if grids[..n].iter().any(|o| o.name == g.name) {
            return Err(ExportError::invalid(
                path,
                format!("two grids are named {:?}", g.name),
                "give each grid a unique name",
            ));
        }
        if g.components != 1 && g.components != 3 {
            return Err(ExportError::invalid(
                path,
                format!("grid {:?} has {} components per cell", g.name, g.components),
                "write float (1) or vec3s (3) grids",
            ));
        }
        if g.values.len() as u64 != g.spec.cell_count() * g.components as u64 {
            return Err(ExportError::invalid(
                path,
                format!(
                    "grid {:?} has {} values for {} cells of {} components",
                    g.name,
                    g.values.len(),
                    g.spec.cell_count(),
                    g.components
                ),
                "pass a volume that matches its grid",
            ));
        }
        let r = g.spec.resolution;
        if r.x > 1 << 30 || r.y > 1 << 30 || r.z > 1 << 30 {
            return Err(ExportError::invalid(
                path,
                format!("grid {:?} resolution {r} is too large for a VDB index", g.name),
                "use a smaller grid",
            ));
        }
        let h = g.spec.cell_size();
        if !(h.x > 0.0 && h.y > 0.0 && h.z > 0.0 && h.is_finite() && g.spec.min.is_finite()) {
            return Err(ExportError::invalid(
                path,
                format!("grid {:?} has a degenerate box (cell size {h})", g.name),
                "give the grid a box with max > min",
            ));
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------
// Tree construction

pub(super) const LEAF_VOXELS: usize = 512;

pub(super) struct Leaf {
    pub(super) mask: [u64; 8],
    /// `LEAF_VOXELS` voxels of the grid's components each.
    pub(super) values: Vec<f32>,
}

#[derive(Default)]
pub(super) struct Node4 {
    /// Child index (z fastest, 16³) → leaf.
    pub(super) leaves: BTreeMap<u32, Leaf>,
    /// Child index → active constant tile value (the grid's components).
    pub(super) tiles: BTreeMap<u32, Vec<f32>>,
}

#[derive(Default)]
pub(super) struct Node5 {
    /// Child index (z fastest, 32³) → 16³ node.
    pub(super) children: BTreeMap<u32, Node4>,
}

pub(super) struct Tree {
    /// Root children by origin (multiples of 4096), in OpenVDB's (x, y, z) order.
    pub(super) roots: BTreeMap<[i32; 3], Node5>,
    pub(super) active: u64,
    pub(super) leaves: u64,
    pub(super) tiles: u64,
    pub(super) bbox: Option<([i32; 3], [i32; 3])>,
}

pub(super) fn build_tree(g: &VdbGrid, opts: &VdbOptions, tick: &mut dyn FnMut()) -> Tree {
    let r = g.spec.resolution;
    let (nx, ny, nz) = (r.x as i32, r.y as i32, r.z as i32);
    let mut tree = Tree { roots: BTreeMap::new(), active: 0, leaves: 0, tiles: 0, bbox: None };
    let bg = g.background;
    let nc = g.components;
    // NaN differences compare false: NaN voxels are active. A vector is active when any
    // component is.
    let is_active = |v: &[f32]| v.iter().any(|&c| (c - bg).abs() > opts.threshold || (c - bg).is_nan());
    let mut oz = 0;
    while oz < nz {
        let mut oy = 0;
        while oy < ny {
            let mut ox = 0;
            while ox < nx {
                let mut mask = [0u64; 8];
                let mut values = vec![bg; LEAF_VOXELS * nc];
                let mut count = 0u32;
                let mut lo = [i32::MAX; 3];
                let mut hi = [i32::MIN; 3];
                for dz in 0..8 {
                    let z = oz + dz;
                    if z >= nz {
                        break;
                    }
                    for dy in 0..8 {
                        let y = oy + dy;
                        if y >= ny {
                            break;
                        }
                        let row = (y as usize + ny as usize * z as usize) * nx as usize;
                        for dx in 0..8 {
                            let x = ox + dx;
                            if x >= nx {
                                break;
                            }
                            let at = (row + x as usize) * nc;
                            let v = &g.values[at..at + nc];
                            if is_active(v) {
                                let n = ((dx << 6) | (dy << 3) | dz) as usize;
                                mask[n >> 6] |= 1 << (n & 63);
                                values[n * nc..(n + 1) * nc].copy_from_slice(v);
                                count += 1;
                                for (a, c) in [x, y, z].into_iter().enumerate() {
                                    lo[a] = lo[a].min(c);
                                    hi[a] = hi[a].max(c);
                                }
                            }
                        }
                    }
                }
                if count > 0 {
                    tree.active += count as u64;
                    tree.bbox = Some(match tree.bbox {
                        None => (lo, hi),
                        Some((a, b)) => (
                            [a[0].min(lo[0]), a[1].min(lo[1]), a[2].min(lo[2])],
                            [b[0].max(hi[0]), b[1].max(hi[1]), b[2].max(hi[2])],
                        ),
                    });
                    let origin5 = [ox & !4095, oy & !4095, oz & !4095];
                    let i5 = (((ox & 4095) >> 7) << 10 | ((oy & 4095) >> 7) << 5 | ((oz & 4095) >> 7)) as u32;
                    let i4 = (((ox & 127) >> 3) << 8 | ((oy & 127) >> 3) << 4 | ((oz & 127) >> 3)) as u32;
                    let node4 = tree.roots.entry(origin5).or_default().children.entry(i5).or_default();
                    let first = values[..nc].to_vec();
                    let constant = count as usize == LEAF_VOXELS
                        && values.chunks(nc).all(|v| v.iter().zip(&first).all(|(a, b)| a.to_bits() == b.to_bits()));
                    if opts.tiles && constant {
                        node4.tiles.insert(i4, first);
                        tree.tiles += 1;
                    } else {
                        node4.leaves.insert(i4, Leaf { mask, values });
                        tree.leaves += 1;
                    }
                }
                ox += 8;
            }
            oy += 8;
        }
        oz += 8;
        tick();
    }
    tree
}

// ---------------------------------------------------------------------------------------
// Encoding

fn encode_grid(out: &mut Vec<u8>, g: &VdbGrid, opts: &VdbOptions, tick: &mut dyn FnMut()) -> VdbGridStats {
    let tree = build_tree(g, opts, tick);
    let half = opts.half;
    let mut flags = COMPRESS_ACTIVE_MASK;
    if opts.compression == VdbCompression::Zip {
        flags |= COMPRESS_ZIP;
    }

    // Descriptor with placeholder offsets.
    put_str(out, &g.name);
    let value_type = if g.components == 3 { "vec3s" } else { "float" };
    let half_suffix = if half { "_HalfFloat" } else { "" };
    put_str(out, &format!("Tree_{value_type}_5_4_3{half_suffix}"));
    put_str(out, "");
    let offsets_at = out.len();
    out.extend_from_slice(&[0u8; 24]);
    let grid_pos = out.len();

    put_u32(out, flags);

    // Metadata, sorted by name as OpenVDB's MetaMap writes it.
    let mut meta: BTreeMap<String, MetaValue> = BTreeMap::new();
    for (k, v) in &g.metadata {
        meta.insert(k.clone(), v.clone());
    }
    meta.insert("name".into(), MetaValue::String(g.name.clone()));
    meta.insert("class".into(), MetaValue::String(g.class.as_str().into()));
    for (k, v) in frame_metadata(opts) {
        meta.insert(k.into(), v);
    }
    meta.insert("creator".into(), MetaValue::String("fogsmith".into()));
    let compression_name = match opts.compression {
        VdbCompression::None => "active values",
        VdbCompression::Zip => "zip + active values",
    };
    meta.insert("file_compression".into(), MetaValue::String(compression_name.into()));
    if let Some((lo, hi)) = tree.bbox {
        meta.insert("file_bbox_min".into(), MetaValue::Vec3i(lo));
        meta.insert("file_bbox_max".into(), MetaValue::Vec3i(hi));
    }
    meta.insert("file_voxel_count".into(), MetaValue::Int64(tree.active as i64));
    if half {
        meta.insert("is_saved_as_half_float".into(), MetaValue::Bool(true));
    }
    put_u32(out, meta.len() as u32);
    for (k, v) in &meta {
        put_meta(out, k, v);
    }

    put_transform(out, &g.spec, &opts.frame);

    // Topology.
    let bg_stored = if half { half_round(g.background) } else { g.background };
    out.extend_from_slice(&1i32.to_le_bytes());
    for _ in 0..g.components {
        out.extend_from_slice(&bg_stored.to_le_bytes());
    }
    put_u32(out, 0); // root tiles
    put_u32(out, tree.roots.len() as u32);
    for (origin, n5) in &tree.roots {
        for c in origin {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let mut child_mask = vec![0u64; 32768 / 64];
        for &i in n5.children.keys() {
            child_mask[i as usize >> 6] |= 1 << (i & 63);
        }
        put_mask(out, &child_mask);
        put_mask(out, &vec![0u64; 32768 / 64]); // no active tiles at this level
        put_values(out, &[], flags, half); // metadata 0: inactive values are the background
        for n4 in n5.children.values() {
            let mut child_mask = [0u64; 64];
            let mut value_mask = [0u64; 64];
            for &i in n4.leaves.keys() {
                child_mask[i as usize >> 6] |= 1 << (i & 63);
            }
            for &i in n4.tiles.keys() {
                value_mask[i as usize >> 6] |= 1 << (i & 63);
            }
            put_mask(out, &child_mask);
            put_mask(out, &value_mask);
            let tile_values: Vec<f32> = n4.tiles.values().flatten().copied().collect();
            put_values(out, &tile_values, flags, half);
            for leaf in n4.leaves.values() {
                put_mask(out, &leaf.mask);
            }
        }
    }

    // Buffers.
    let block_pos = out.len();
    let mut active = Vec::with_capacity(LEAF_VOXELS * g.components);
    for n5 in tree.roots.values() {
        for n4 in n5.children.values() {
            for leaf in n4.leaves.values() {
                put_mask(out, &leaf.mask);
                active.clear();
                for n in 0..LEAF_VOXELS {
                    if leaf.mask[n >> 6] >> (n & 63) & 1 == 1 {
                        active.extend_from_slice(&leaf.values[n * g.components..(n + 1) * g.components]);
                    }
                }
                put_values(out, &active, flags, half);
            }
        }
    }
    let end_pos = out.len();
    for (k, p) in [grid_pos, block_pos, end_pos].into_iter().enumerate() {
        out[offsets_at + 8 * k..offsets_at + 8 * k + 8].copy_from_slice(&(p as i64).to_le_bytes());
    }
    VdbGridStats { name: g.name.clone(), active_voxels: tree.active, leaves: tree.leaves, tiles: tree.tiles, bytes: 0 }
}

/// The up axis, units and handedness, and an animation frame's number and rate, as
/// metadata entries.
fn frame_metadata(opts: &VdbOptions) -> Vec<(&'static str, MetaValue)> {
    let frame = &opts.frame;
    let mut out = vec![
        ("handedness", MetaValue::String(frame.handedness_name().into())),
        ("meters_per_unit", MetaValue::Double(frame.meters_per_unit())),
        ("up_axis", MetaValue::String(frame.up_name().into())),
    ];
    if let Some(t) = opts.time {
        out.extend([("frame", MetaValue::Int32(t.frame)), ("fps", MetaValue::Float(t.fps))]);
    }
    out
}

/// The index-to-world map of `spec` in `frame` as a 4×4 row-vector matrix (OpenVDB's
/// convention: `world = [i j k 1] · A`; row a < 3 is the world step of index axis a, row 3
/// the world position of voxel 0's centre).
pub fn index_to_world_matrix(spec: &GridSpec, frame: &Frame) -> [[f64; 4]; 4] {
    let (h, t) = transform_of(spec);
    let m = frame.matrix();
    let s = frame.scale();
    let mut a = [[0.0; 4]; 4];
    for (ia, row) in a.iter_mut().take(3).enumerate() {
        for b in 0..3 {
            row[b] = s * m[b][ia] * h[ia];
        }
    }
    a[3] = {
        let p = frame.point(t);
        [p[0], p[1], p[2], 1.0]
    };
    a
}

fn put_transform(out: &mut Vec<u8>, spec: &GridSpec, frame: &Frame) {
    let put = |out: &mut Vec<u8>, v: f64| out.extend_from_slice(&v.to_le_bytes());
    if frame.keeps_axes() {
        let (h, t) = transform_of(spec);
        let s = frame.scale();
        let (scale, translation) = (h.map(|c| c * s), t.map(|c| c * s));
        let uniform = is_uniform(scale);
        put_str(out, if uniform { "UniformScaleTranslateMap" } else { "ScaleTranslateMap" });
        let inv = scale.map(|s| 1.0 / s);
        for v in [translation, scale, scale, inv, inv.map(|i| i * i), inv.map(|i| 0.5 * i)] {
            for c in v {
                put(out, c);
            }
        }
    } else {
        put_str(out, "AffineMap");
        for row in index_to_world_matrix(spec, frame) {
            for c in row {
                put(out, c);
            }
        }
    }
}

/// World-space scale (cell size) and translation (centre of cell 0) of a project grid.
pub fn transform_of(spec: &GridSpec) -> ([f64; 3], [f64; 3]) {
    let min = spec.min.to_array().map(f64::from);
    let max = spec.max.to_array().map(f64::from);
    let res = spec.resolution.to_array().map(f64::from);
    let scale = [0, 1, 2].map(|a| (max[a] - min[a]) / res[a]);
    let uniform = is_uniform(scale);
    let scale = if uniform { [scale[0]; 3] } else { scale };
    let translation = [0, 1, 2].map(|a| min[a] + 0.5 * scale[a]);
    (scale, translation)
}

fn is_uniform(s: [f64; 3]) -> bool {
    let tol = 1e-6 * s[0].abs();
    (s[1] - s[0]).abs() <= tol && (s[2] - s[0]).abs() <= tol
}

/// Refuses values that half floats cannot hold: beyond ±65504 they would be stored as
/// infinity (dense fog's optical depth easily exceeds it).
pub(crate) fn check_half_range(path: &Path, what: &str, values: &[f32], fix: &str) -> Result<(), ExportError> {
    let max = half::f16::MAX.to_f32();
    let over = values.iter().filter(|v| v.abs() > max).count();
    if over > 0 {
        let largest = values.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        return Err(ExportError::invalid(
            path,
            format!("{what} has {over} values beyond half precision's ±{max} (largest {largest}); as half floats they would be infinite"),
            fix,
        ));
    }
    Ok(())
}

/// f32 → nearest half (ties to even) → f32, as OpenVDB's `truncateRealToHalf`.
pub fn half_round(v: f32) -> f32 {
    half::f16::from_f32(v).to_f32()
}

/// One value block as OpenVDB's `writeCompressedValues` with active-mask compression writes
/// it when every inactive value is the background: metadata byte 0, then the active values.
fn put_values(out: &mut Vec<u8>, active: &[f32], flags: u32, half: bool) {
    out.push(0);
    let raw: Vec<u8> = if half {
        if active.is_empty() {
            return; // OpenVDB's HalfWriter writes nothing for an empty block
        }
        active.iter().flat_map(|v| half::f16::from_f32(*v).to_le_bytes()).collect()
    } else {
        active.iter().flat_map(|v| v.to_le_bytes()).collect()
    };
    if flags & COMPRESS_ZIP != 0 {
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
        let zipped = z.write_all(&raw).and_then(|()| z.finish()).ok().filter(|zipped| zipped.len() < raw.len());
        match zipped {
            Some(zipped) => {
                out.extend_from_slice(&(zipped.len() as i64).to_le_bytes());
                out.extend_from_slice(&zipped);
            }
            None => {
                out.extend_from_slice(&(-(raw.len() as i64)).to_le_bytes());
                out.extend_from_slice(&raw);
            }
        }
    } else {
        out.extend_from_slice(&raw);
    }
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_str(out: &mut Vec<u8>, s: &str) {
    put_u32(out, s.len() as u32);
    out.extend_from_slice(s.as_bytes());
}

fn put_mask(out: &mut Vec<u8>, words: &[u64]) {
    for w in words {
        out.extend_from_slice(&w.to_le_bytes());
    }
}

fn put_meta(out: &mut Vec<u8>, name: &str, v: &MetaValue) {
    put_str(out, name);
    put_str(out, v.type_name());
    let b = v.bytes();
    put_u32(out, b.len() as u32);
    out.extend_from_slice(&b);
}

/// A version-4-shaped UUID derived from the file's bytes after it (FNV-1a, two seeds): the
/// file's identity for OpenVDB's caches, which changes with its content, while the same grids
/// give the same file bit for bit (a farm task's frame equals a local export's).
fn content_uuid(content: &[u8]) -> String {
    let fnv = |seed: u64| content.iter().fold(seed, |h, &b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01B3));
    let a = fnv(0xCBF2_9CE4_8422_2325);
    let b = fnv(0x9E37_79B9_7F4A_7C15);
    let b = (b & 0x3FFF_FFFF_FFFF_FFFF) | 0x8000_0000_0000_0000;
    let a = (a & 0xFFFF_FFFF_FFFF_0FFF) | 0x0000_0000_0000_4000;
    format!(
        "{:08x}-{:04x}-{:04x}-{:04x}-{:012x}",
        a >> 32,
        (a >> 16) & 0xFFFF,
        a & 0xFFFF,
        b >> 48,
        b & 0xFFFF_FFFF_FFFF
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec3, Vec3};

    #[test]
    fn grid_selection_parses() {
        let all: GridSelection = "density, optical_depth,transmittance".parse().unwrap();
        assert!(all.density && all.optical_depth && all.transmittance);
        let t: GridSelection = "transmittance".parse().unwrap();
        assert!(!t.density && !t.optical_depth && t.transmittance);
        assert!("density,smoke".parse::<GridSelection>().unwrap_err().contains("\"smoke\""));
        assert!("".parse::<GridSelection>().is_err());
    }

    #[test]
    fn uuid_looks_like_a_uuid_and_follows_the_content() {
        let a = content_uuid(b"grids");
        let b = content_uuid(b"grids!");
        assert_eq!(a.len(), 36);
        assert_ne!(a, b);
        assert_eq!(a, content_uuid(b"grids"));
        assert_eq!(a.as_bytes()[14], b'4');
    }

    #[test]
    fn transform_maps_index_to_cell_centres() {
        let spec =
            GridSpec { min: Vec3::new(-1.0, 0.0, 2.0), max: Vec3::new(1.0, 1.0, 2.5), resolution: UVec3::new(8, 4, 2) };
        let (s, t) = transform_of(&spec);
        assert_eq!(s, [0.25; 3]);
        assert_eq!(t, [-0.875, 0.125, 2.125]);
        let spec = GridSpec { resolution: UVec3::new(8, 8, 2), ..spec };
        assert_eq!(transform_of(&spec).0, [0.25, 0.125, 0.25]);
    }

    #[test]
    fn progress_reaches_one_and_bad_input_is_refused() {
        let spec = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::new(4, 4, 20) };
        let v = Volume::new(spec, vec![1.0; 320]);
        let dir = std::env::temp_dir().join(format!("fogsmith-vdb-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("p.vdb");
        let mut seen = Vec::new();
        write_vdb_with_progress(&path, &[VdbGrid::from_volume("density", &v)], &VdbOptions::default(), &mut |p| {
            seen.push(p)
        })
        .unwrap();
        assert_eq!(seen.last(), Some(&1.0));
        assert!(seen.windows(2).all(|w| w[0] <= w[1]));
        let twice = [VdbGrid::from_volume("density", &v), VdbGrid::from_volume("density", &v)];
        let err = write_vdb(&dir.join("q.vdb"), &twice, &VdbOptions::default()).unwrap_err().to_string();
        assert!(err.contains("q.vdb") && err.contains("two grids"), "{err}");
        assert!(!dir.join("q.vdb").exists());
        // A folder that does not exist: an error naming the file, and no partial file.
        let err = write_vdb(&dir.join("missing/r.vdb"), &twice[..1], &VdbOptions::default()).unwrap_err().to_string();
        assert!(err.contains("r.vdb") && err.contains("cannot write"), "{err}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! A NanoVDB writer: the grids of a VDB export as one `.nvdb` file, for renderers and engines
//! that load NanoVDB directly (GPU path tracers, game engines) without OpenVDB.
//!
//! The same grids as [`super::vdb`] (from the same [`VdbGrid`]s, so with the same names,
//! sparsity, tiles, voxel values and index-to-world map): float grids (`GridType::Float`) and
//! the baked emission as `GridType::Vec3f`, class `FogVolume` for density and `Unknown` for
//! the rest. Values are always 32-bit floats and the file is not compressed (codec none):
//! [`VdbOptions::half`] and [`VdbOptions::compression`] apply to the VDB only.
//!
//! # Version
//!
//! NanoVDB 32.4.2, the one in OpenVDB 10.0.1 (Debian 12's `libnanovdb-tools`). Readers of
//! major version 32 accept it (the major number is NanoVDB's ABI and file format version);
//! 32.6 and later (OpenVDB 11 to 13, up to 32.9) read 32.4 files and validate their checksum
//! the 32.4 way. That is why only the "partial" checksum is written: 32.4's full checksum
//! hashes an array of `uint_fast32_t` (8 bytes on Linux, 4 elsewhere), which 32.6+ no longer
//! reproduce, while the partial one (CRC-32 of the grid from byte 16 up to the first upper
//! node) is checked alike by every version. A grid without nodes carries "no checksum".
//!
//! # Layout (little-endian)
//!
//! ```text
//! file header   u64 magic "NanoVDB0", u32 version, u16 grid count, u16 codec (0)
//! per grid      176-byte metadata record (sizes, name hash, voxel count, type, class,
//!               world and index bboxes, voxel size, name size, node and tile counts,
//!               codec, version) + the name with its NUL
//! per grid      the grid buffer, exactly as it lies in memory:
//!   GridData  672  magic, checksum, version, flags, index 0 of 1, buffer size, name,
//!                  map (3×3 + inverse + translation, f32 and f64), world bbox, voxel size,
//!                  class, type, no blind data
//!   TreeData   64  offsets of the first leaf, lower, upper and root (0: none), counts
//!   RootData       bbox, tile count, background, min, max, average, std deviation;
//!                  then one 32-byte tile per 4096³ child: key, child offset, state, value
//!   upper nodes    32³: bbox, flags, value and child masks, stats, 32768 tiles/offsets
//!   lower nodes    16³: the same with 4096 entries
//!   leaves         8³: bbox min + extent, flags, mask, stats, 512 values
//! ```
//!
//! Nodes are 32-byte aligned and stored breadth-first (every upper node, then every lower
//! node, then every leaf, each in the order of its parent's child mask); child offsets are
//! relative to the parent node (the root's, to RootData). Inside a node, entries are numbered
//! z fastest as in OpenVDB. Each node records the index bbox of its active values and their
//! minimum, maximum, average and population standard deviation, accumulated as NanoVDB's
//! `GridStats` does (an active tile counts as all the voxels of the child it stands for, and
//! a vec3's statistics are of its squared length). The world bbox is that of the index bbox's
//! voxel corners `[min, max + 1]` through the map.

use super::vdb::{
    build_tree, check_grids, index_to_world_matrix, GridClass, Node4, Tree, VdbGrid, VdbGridStats, VdbOptions,
    VdbStats, LEAF_VOXELS,
};
use super::{write_bytes_atomic, ExportError};

/// "NanoVDB0" as a little-endian u64: the file and grid magic of NanoVDB 32.4.
pub const NANOVDB_MAGIC: u64 = 0x3042_4456_6f6e_614e;
/// The version written: (major, minor, patch).
pub const NANOVDB_VERSION: (u32, u32, u32) = (32, 4, 2);
/// Size of a grid's header (`GridData`).
pub const GRID_DATA_SIZE: usize = 672;
/// Size of the tree header (`TreeData`).
pub const TREE_DATA_SIZE: usize = 64;
/// Size of a file's per-grid metadata record, without the name.
pub const META_DATA_SIZE: usize = 176;
/// Longest grid name NanoVDB keeps in its header (longer ones need blind data).
pub const MAX_NAME: usize = 255;

const GRID_TYPE_FLOAT: u32 = 1;
const GRID_TYPE_VEC3F: u32 = 6;
const GRID_CLASS_UNKNOWN: u32 = 0;
const GRID_CLASS_FOG_VOLUME: u32 = 2;
const FLAG_HAS_BBOX: u32 = 1 << 1;
const FLAG_HAS_MIN_MAX: u32 = 1 << 2;
const FLAG_HAS_AVERAGE: u32 = 1 << 3;
const FLAG_HAS_STD_DEVIATION: u32 = 1 << 4;
const FLAG_IS_BREADTH_FIRST: u32 = 1 << 5;
/// Node flag: the node holds active values (its bbox is set).
const NODE_HAS_BBOX: u8 = 2;

/// The packed version number.
pub fn version_id() -> u32 {
    let (major, minor, patch) = NANOVDB_VERSION;
    major << 21 | minor << 10 | patch
}

/// NanoVDB's grid-name hash (`io::stringHash`), which readers match names by.
pub fn string_hash(name: &str) -> u64 {
    name.bytes().fold(0u64, |hash, b| {
        let overflow = hash >> 56;
        hash.wrapping_mul(67).wrapping_add(b as u64 + overflow)
    })
}

/// Writes `grids` to `path` as a NanoVDB file, atomically (temporary file + rename).
pub fn write_nanovdb(path: &std::path::Path, grids: &[VdbGrid], opts: &VdbOptions) -> Result<VdbStats, ExportError> {
    write_nanovdb_with_progress(path, grids, opts, &mut |_| {})
}

/// [`write_nanovdb`] reporting progress in [0, 1].
pub fn write_nanovdb_with_progress(
    path: &std::path::Path,
    grids: &[VdbGrid],
    opts: &VdbOptions,
    progress: &mut dyn FnMut(f32),
) -> Result<VdbStats, ExportError> {
    let (bytes, stats) = encode_nanovdb_with_progress(path, grids, opts, progress)?;
    write_bytes_atomic(path, &bytes)?;
    progress(1.0);
    Ok(stats)
}

/// Encodes the file in memory (what [`write_nanovdb`] writes); `path` only names errors.
pub fn encode_nanovdb(
    path: &std::path::Path,
    grids: &[VdbGrid],
    opts: &VdbOptions,
) -> Result<(Vec<u8>, VdbStats), ExportError> {
    encode_nanovdb_with_progress(path, grids, opts, &mut |_| {})
}

fn encode_nanovdb_with_progress(
    path: &std::path::Path,
    grids: &[VdbGrid],
    opts: &VdbOptions,
    progress: &mut dyn FnMut(f32),
) -> Result<(Vec<u8>, VdbStats), ExportError> {
    let opts = VdbOptions { half: false, ..*opts };
    check_grids(path, grids, &opts)?;
    if let Some(g) = grids.iter().find(|g| g.name.len() > MAX_NAME || g.name.contains('\0')) {
        return Err(ExportError::invalid(
            path,
            format!("grid name {:?} is longer than NanoVDB's {MAX_NAME} bytes or holds a NUL", g.name),
            "use a shorter grid name",
        ));
    }
    if grids.is_empty() || grids.len() > u16::MAX as usize {
        return Err(ExportError::invalid(
            path,
            format!("{} grids: a NanoVDB file holds 1 to {}", grids.len(), u16::MAX),
            "select at least one grid",
        ));
    }
    let total: u64 = grids.iter().map(|g| g.spec.resolution.z.div_ceil(8) as u64).sum::<u64>().max(1);
    let mut done = 0u64;
    let mut buffers = Vec::with_capacity(grids.len());
    for g in grids {
        let mut tick = || {
            done += 1;
            progress(done as f32 / total as f32 * 0.99);
        };
        let tree = build_tree(g, &opts, &mut tick);
        buffers.push(encode_grid(g, &tree, &opts));
    }

    let mut out = Vec::new();
    put_u64(&mut out, NANOVDB_MAGIC);
    put_u32(&mut out, version_id());
    out.extend_from_slice(&(grids.len() as u16).to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes()); // codec none
    for (g, b) in grids.iter().zip(&buffers) {
        put_meta(&mut out, g, b);
    }
    let mut stats = VdbStats::default();
    for b in &buffers {
        out.extend_from_slice(&b.bytes);
        stats.grids.push(b.stats.clone());
    }
    stats.bytes = out.len() as u64;
    Ok((out, stats))
}

// ---------------------------------------------------------------------------------------
// Statistics, as NanoVDB's `Stats` accumulates them (f64 running mean and sum of squares).

#[derive(Clone, Copy)]
struct Stats {
    /// Minimum and maximum by `key` (the value, or a vec3's squared length), with the value.
    min: (f32, [f32; 3]),
    max: (f32, [f32; 3]),
    count: u64,
    avg: f64,
    aux: f64,
}

impl Stats {
    fn new() -> Self {
        Stats { min: (f32::MAX, [f32::MAX; 3]), max: (f32::MIN, [f32::MIN; 3]), count: 0, avg: 0.0, aux: 0.0 }
    }

    fn key(v: &[f32]) -> (f32, [f32; 3]) {
        match v {
            [x] => (*x, [*x; 3]),
            _ => (v[0] * v[0] + v[1] * v[1] + v[2] * v[2], [v[0], v[1], v[2]]),
        }
    }

    fn extrema(&mut self, p: (f32, [f32; 3])) {
        if p.0 < self.min.0 {
            self.min = p;
        }
        if self.max.0 < p.0 {
            self.max = p;
        }
    }

    fn add(&mut self, v: &[f32]) {
        let p = Self::key(v);
        self.extrema(p);
        self.count += 1;
        let delta = p.0 as f64 - self.avg;
        self.avg += delta / self.count as f64;
        self.aux += delta * (p.0 as f64 - self.avg);
    }

    /// A constant tile standing for `n` values.
    fn add_n(&mut self, v: &[f32], n: u64) {
        let p = Self::key(v);
        let denom = 1.0 / (self.count + n) as f64;
        let delta = p.0 as f64 - self.avg;
        self.avg += denom * delta * n as f64;
        self.aux += denom * delta * delta * self.count as f64 * n as f64;
        self.extrema(p);
        self.count += n;
    }

    fn merge(&mut self, o: &Stats) {
        if o.count == 0 {
            return;
        }
        let denom = 1.0 / (self.count + o.count) as f64;
        let delta = o.avg - self.avg;
        self.avg += denom * delta * o.count as f64;
        self.aux += o.aux + denom * delta * delta * self.count as f64 * o.count as f64;
        if o.min.0 < self.min.0 {
            self.min = o.min;
        }
        if self.max.0 < o.max.0 {
            self.max = o.max;
        }
        self.count += o.count;
    }

    fn std(&self) -> f64 {
        if self.count < 2 {
            0.0
        } else {
            (self.aux / self.count as f64).sqrt()
        }
    }

    /// min, max (the grid's components each), average, std deviation.
    fn put(&self, out: &mut [u8], at: usize, nc: usize) {
        let comps = |p: &(f32, [f32; 3])| if nc == 1 { vec![p.0] } else { p.1.to_vec() };
        put_f32s(out, at, &comps(&self.min));
        put_f32s(out, at + 4 * nc, &comps(&self.max));
        put_f32s(out, at + 8 * nc, &[self.avg as f32, self.std() as f32]);
    }
}

/// An index bbox of active values; empty is NanoVDB's (i32::MAX, i32::MIN).
#[derive(Clone, Copy)]
struct BBox {
    min: [i32; 3],
    max: [i32; 3],
}

impl BBox {
    const EMPTY: BBox = BBox { min: [i32::MAX; 3], max: [i32::MIN; 3] };

    fn is_empty(&self) -> bool {
        (0..3).any(|a| self.min[a] > self.max[a])
    }

    fn expand(&mut self, o: &BBox) {
        for a in 0..3 {
            self.min[a] = self.min[a].min(o.min[a]);
            self.max[a] = self.max[a].max(o.max[a]);
        }
    }

    fn put(&self, out: &mut [u8], at: usize) {
        for (k, c) in self.min.iter().chain(&self.max).enumerate() {
            out[at + 4 * k..at + 4 * k + 4].copy_from_slice(&c.to_le_bytes());
        }
    }
}

// ---------------------------------------------------------------------------------------
// Node sizes and field offsets for a value of `nc` f32 components.

const fn align32(n: usize) -> usize {
    n.div_ceil(32) * 32
}

fn root_size(nc: usize) -> usize {
    align32(36 + 12 * nc)
}

const ROOT_TILE_SIZE: usize = 32;

/// An internal node of 2^(3·log2dim) entries: (offset of the stats, offset of the table,
/// bytes per table entry, node size).
fn internal_layout(log2dim: u32, nc: usize) -> (usize, usize, usize, usize) {
    let entries = 1usize << (3 * log2dim);
    let mask = entries / 8;
    let stats = 32 + 2 * mask;
    let table = align32(stats + 8 * nc + 8);
    let entry = (4 * nc).max(8).div_ceil(8) * 8;
    (stats, table, entry, align32(table + entries * entry))
}

/// A leaf: (offset of the values, leaf size).
fn leaf_layout(nc: usize) -> (usize, usize) {
    let values = align32(88 + 8 * nc);
    (values, align32(values + LEAF_VOXELS * 4 * nc))
}

// ---------------------------------------------------------------------------------------
// Encoding

struct GridBuffer {
    bytes: Vec<u8>,
    stats: VdbGridStats,
    /// [leaves, lower nodes, upper nodes]
    node_count: [u32; 3],
    /// Active tiles in [lower, upper, root] nodes.
    tile_count: [u32; 3],
    voxels: u64,
    index_bbox: BBox,
    world_bbox: ([f64; 3], [f64; 3]),
    voxel_size: [f64; 3],
    grid_type: u32,
    grid_class: u32,
}

/// Where each node of the tree goes, breadth-first.
struct Placement {
    uppers: Vec<usize>,
    lowers: Vec<usize>,
    leaves: Vec<usize>,
    size: usize,
}

fn place(tree: &Tree, nc: usize) -> Placement {
    let upper_size = internal_layout(5, nc).3;
    let lower_size = internal_layout(4, nc).3;
    let leaf_size = leaf_layout(nc).1;
    let mut at = GRID_DATA_SIZE + TREE_DATA_SIZE + root_size(nc) + ROOT_TILE_SIZE * tree.roots.len();
    let mut p = Placement { uppers: Vec::new(), lowers: Vec::new(), leaves: Vec::new(), size: 0 };
    for _ in tree.roots.values() {
        p.uppers.push(at);
        at += upper_size;
    }
    for n5 in tree.roots.values() {
        for _ in n5.children.values() {
            p.lowers.push(at);
            at += lower_size;
        }
    }
    for n4 in tree.roots.values().flat_map(|n5| n5.children.values()) {
        for _ in n4.leaves.values() {
            p.leaves.push(at);
            at += leaf_size;
        }
    }
    p.size = at;
    p
}

fn encode_grid(g: &VdbGrid, tree: &Tree, opts: &VdbOptions) -> GridBuffer {
    let nc = g.components;
    let placement = place(tree, nc);
    let mut buf = vec![0u8; placement.size];
    let bg = vec![g.background; nc];

    let (u_stats, u_table, u_entry, _) = internal_layout(5, nc);
    let (l_stats, l_table, l_entry, _) = internal_layout(4, nc);
    let mut lower_k = 0;
    let mut leaf_k = 0;
    let mut root_total = (Stats::new(), BBox::EMPTY);
    let mut lower_tiles = 0u32;
    let root_at = GRID_DATA_SIZE + TREE_DATA_SIZE;
    for (r, (origin5, n5)) in tree.roots.iter().enumerate() {
        let up = placement.uppers[r];
        let mut up_total = (Stats::new(), BBox::EMPTY);
        // Every table entry starts as the background; children overwrite theirs.
        for n in 0..32768 {
            put_f32s(&mut buf, up + u_table + n * u_entry, &bg);
        }
        for (&i5, n4) in &n5.children {
            let lo = placement.lowers[lower_k];
            lower_k += 1;
            let origin4 = child_origin(*origin5, i5, 5, 7);
            let (stats4, bbox4) =
                encode_lower(&mut buf, lo, origin4, n4, nc, &bg, (l_stats, l_table, l_entry), &placement, &mut leaf_k);
            lower_tiles += n4.tiles.len() as u32;
            buf[up + 32 + 4096 + (i5 as usize >> 3)] |= 1 << (i5 & 7); // child mask
            put_child(&mut buf, up + u_table + i5 as usize * u_entry, u_entry, lo - up);
            up_total.0.merge(&stats4);
            up_total.1.expand(&bbox4);
        }
        up_total.1.put(&mut buf, up);
        buf[up + 24] = NODE_HAS_BBOX;
        up_total.0.put(&mut buf, up + u_stats, nc);
        // Root tile: key, offset from RootData, state 0, value 0.
        let tile = root_at + root_size(nc) + r * ROOT_TILE_SIZE;
        let key = ((origin5[2] as u32 >> 12) as u64)
            | ((origin5[1] as u32 >> 12) as u64) << 21
            | ((origin5[0] as u32 >> 12) as u64) << 42;
        put_u64_at(&mut buf, tile, key);
        put_i64(&mut buf, tile + 8, (up - root_at) as i64);
        root_total.0.merge(&up_total.0);
        root_total.1.expand(&up_total.1);
    }

    // RootData
    let (root_stats, bbox) = root_total;
    bbox.put(&mut buf, root_at);
    put_u32_at(&mut buf, root_at + 24, tree.roots.len() as u32);
    put_f32s(&mut buf, root_at + 28, &bg);
    if tree.roots.is_empty() {
        put_f32s(&mut buf, root_at + 28 + 4 * nc, &bg);
        put_f32s(&mut buf, root_at + 28 + 8 * nc, &bg);
    } else {
        root_stats.put(&mut buf, root_at + 28 + 4 * nc, nc);
    }

    // TreeData: offsets from the tree of the first leaf, lower, upper node and the root.
    let tree_at = GRID_DATA_SIZE;
    let first = |v: &Vec<usize>| v.first().map_or(0, |&a| (a - tree_at) as u64);
    put_u64_at(&mut buf, tree_at, first(&placement.leaves));
    put_u64_at(&mut buf, tree_at + 8, first(&placement.lowers));
    put_u64_at(&mut buf, tree_at + 16, first(&placement.uppers));
    put_u64_at(&mut buf, tree_at + 24, (root_at - tree_at) as u64);
    let node_count = [placement.leaves.len() as u32, placement.lowers.len() as u32, placement.uppers.len() as u32];
    let tile_count = [lower_tiles, 0, 0];
    for (k, c) in node_count.iter().chain(&tile_count).enumerate() {
        put_u32_at(&mut buf, tree_at + 32 + 4 * k, *c);
    }
    put_u64_at(&mut buf, tree_at + 56, tree.active);

    // GridData
    let a = index_to_world_matrix(&g.spec, &opts.frame);
    let mat: [[f64; 3]; 3] = [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[j][i]));
    let inv_a = invert3([0, 1, 2].map(|i| [a[i][0], a[i][1], a[i][2]]));
    let inv: [[f64; 3]; 3] = [0, 1, 2].map(|i| [0, 1, 2].map(|j| inv_a[j][i]));
    let vec = [a[3][0], a[3][1], a[3][2]];
    let apply = |p: [f64; 3]| {
        [0, 1, 2].map(|i| p[0].mul_add(mat[i][0], p[1].mul_add(mat[i][1], p[2].mul_add(mat[i][2], vec[i]))))
    };
    let world_bbox = if bbox.is_empty() {
        ([f64::MAX; 3], [-f64::MAX; 3])
    } else {
        let (lo, hi) = (bbox.min.map(f64::from), bbox.max.map(|c| c as f64 + 1.0));
        let mut w = (apply(lo), apply(lo));
        for corner in 0..8 {
            let p = [0, 1, 2].map(|k| if corner >> k & 1 == 1 { hi[k] } else { lo[k] });
            for (k, q) in apply(p).into_iter().enumerate() {
                w.0[k] = w.0[k].min(q);
                w.1[k] = w.1[k].max(q);
            }
        }
        w
    };
    let voxel_size = [0, 1, 2].map(|r| (a[r][0] * a[r][0] + a[r][1] * a[r][1] + a[r][2] * a[r][2]).sqrt());
    let grid_type = if nc == 3 { GRID_TYPE_VEC3F } else { GRID_TYPE_FLOAT };
    let grid_class = match g.class {
        GridClass::FogVolume => GRID_CLASS_FOG_VOLUME,
        GridClass::Unknown => GRID_CLASS_UNKNOWN,
    };
    let mut flags = FLAG_IS_BREADTH_FIRST | FLAG_HAS_MIN_MAX | FLAG_HAS_AVERAGE | FLAG_HAS_STD_DEVIATION;
    if !bbox.is_empty() {
        flags |= FLAG_HAS_BBOX;
    }
    put_u64_at(&mut buf, 0, NANOVDB_MAGIC);
    put_u32_at(&mut buf, 16, version_id());
    put_u32_at(&mut buf, 20, flags);
    put_u32_at(&mut buf, 24, 0); // grid index
    put_u32_at(&mut buf, 28, 1); // grid count
    put_u64_at(&mut buf, 32, placement.size as u64);
    buf[40..40 + g.name.len()].copy_from_slice(g.name.as_bytes());
    let map_at = 296;
    let f32s = |m: &[[f64; 3]; 3]| m.iter().flatten().map(|&v| v as f32).collect::<Vec<_>>();
    put_f32s(&mut buf, map_at, &f32s(&mat));
    put_f32s(&mut buf, map_at + 36, &f32s(&inv));
    put_f32s(&mut buf, map_at + 72, &vec.map(|v| v as f32));
    put_f32s(&mut buf, map_at + 84, &[1.0]); // taper
    put_f64s(&mut buf, map_at + 88, mat.as_flattened());
    put_f64s(&mut buf, map_at + 160, inv.as_flattened());
    put_f64s(&mut buf, map_at + 232, &vec);
    put_f64s(&mut buf, map_at + 256, &[1.0]);
    put_f64s(&mut buf, 560, &world_bbox.0);
    put_f64s(&mut buf, 584, &world_bbox.1);
    put_f64s(&mut buf, 608, &voxel_size);
    put_u32_at(&mut buf, 632, grid_class);
    put_u32_at(&mut buf, 636, grid_type);
    // Blind data offset and count, padding: 0.

    // The partial checksum: CRC-32 of everything before the first upper node, past the magic
    // and the checksum itself; the upper half "empty" (all bits set) marks it partial.
    let checksum = match placement.uppers.first() {
        Some(&end) => 0xFFFF_FFFF_0000_0000 | crc32fast::hash(&buf[16..end]) as u64,
        None => u64::MAX,
    };
    put_u64_at(&mut buf, 8, checksum);

    GridBuffer {
        stats: VdbGridStats {
            name: g.name.clone(),
            active_voxels: tree.active,
            leaves: tree.leaves,
            tiles: tree.tiles,
            bytes: buf.len() as u64,
        },
        bytes: buf,
        node_count,
        tile_count,
        voxels: tree.active,
        index_bbox: bbox,
        world_bbox,
        voxel_size,
        grid_type,
        grid_class,
    }
}

/// Writes a lower node and its leaves; returns their statistics and bbox.
#[allow(clippy::too_many_arguments)]
fn encode_lower(
    buf: &mut [u8],
    lo: usize,
    origin: [i32; 3],
    n4: &Node4,
    nc: usize,
    bg: &[f32],
    (l_stats, l_table, l_entry): (usize, usize, usize),
    placement: &Placement,
    leaf_k: &mut usize,
) -> (Stats, BBox) {
    let (leaf_values, _) = leaf_layout(nc);
    let mut total = (Stats::new(), BBox::EMPTY);
    for n in 0..4096 {
        put_f32s(buf, lo + l_table + n * l_entry, bg);
    }
    // Active tiles first, as GridStats visits them.
    for (&i4, value) in &n4.tiles {
        buf[lo + 32 + (i4 as usize >> 3)] |= 1 << (i4 & 7); // value mask
        put_f32s(buf, lo + l_table + i4 as usize * l_entry, value);
        total.0.add_n(value, LEAF_VOXELS as u64);
        let o = child_origin(origin, i4, 4, 3);
        total.1.expand(&BBox { min: o, max: o.map(|c| c + 7) });
    }
    for (&i4, leaf) in &n4.leaves {
        let at = placement.leaves[*leaf_k];
        *leaf_k += 1;
        let o = child_origin(origin, i4, 4, 3);
        let mut stats = Stats::new();
        let mut bbox = BBox::EMPTY;
        for n in 0..LEAF_VOXELS {
            if leaf.mask[n >> 6] >> (n & 63) & 1 == 1 {
                stats.add(&leaf.values[n * nc..(n + 1) * nc]);
                let p = [o[0] + (n >> 6) as i32, o[1] + (n >> 3 & 7) as i32, o[2] + (n & 7) as i32];
                bbox.expand(&BBox { min: p, max: p });
            }
        }
        // bbox min, its extent per axis, flags, mask, stats, values
        for k in 0..3 {
            put_u32_at(buf, at + 4 * k, bbox.min[k] as u32);
            buf[at + 12 + k] = (bbox.max[k] - bbox.min[k]) as u8;
        }
        buf[at + 15] = NODE_HAS_BBOX;
        for (k, w) in leaf.mask.iter().enumerate() {
            put_u64_at(buf, at + 16 + 8 * k, *w);
        }
        stats.put(buf, at + 80, nc);
        put_f32s(buf, at + leaf_values, &leaf.values);
        buf[lo + 32 + 512 + (i4 as usize >> 3)] |= 1 << (i4 & 7); // child mask
        put_child(buf, lo + l_table + i4 as usize * l_entry, l_entry, at - lo);
        total.0.merge(&stats);
        total.1.expand(&bbox);
    }
    total.1.put(buf, lo);
    buf[lo + 24] = NODE_HAS_BBOX;
    total.0.put(buf, lo + l_stats, nc);
    total
}

/// The origin of child `i` (z fastest, 2^log2dim per axis) of a node at `origin` whose
/// children span 2^child_total voxels per axis.
fn child_origin(origin: [i32; 3], i: u32, log2dim: u32, child_total: u32) -> [i32; 3] {
    let m = (1 << log2dim) - 1;
    let local = [i >> (2 * log2dim), (i >> log2dim) & m, i & m];
    [0, 1, 2].map(|a| origin[a] + ((local[a] as i32) << child_total))
}

/// The inverse of a 3×3 matrix by Gauss–Jordan elimination with partial pivoting (exact
/// reciprocals for the signed, scaled permutations of the export frames).
fn invert3(m: [[f64; 3]; 3]) -> [[f64; 3]; 3] {
    let mut a = m;
    let mut inv = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for col in 0..3 {
        let pivot = (col..3).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs())).unwrap_or(col);
        a.swap(col, pivot);
        inv.swap(col, pivot);
        let d = a[col][col];
        for k in 0..3 {
            a[col][k] /= d;
            inv[col][k] /= d;
        }
        for row in 0..3 {
            let f = a[row][col];
            if row != col && f != 0.0 {
                for k in 0..3 {
                    a[row][k] -= f * a[col][k];
                    inv[row][k] -= f * inv[col][k];
                }
            }
        }
    }
    inv
}

/// The file's metadata record of one grid, and its name.
fn put_meta(out: &mut Vec<u8>, g: &VdbGrid, b: &GridBuffer) {
    let size = b.bytes.len() as u64;
    put_u64(out, size); // in memory
    put_u64(out, size); // on disk: no codec
    put_u64(out, string_hash(&g.name));
    put_u64(out, b.voxels);
    put_u32(out, b.grid_type);
    put_u32(out, b.grid_class);
    for v in b.world_bbox.0.iter().chain(&b.world_bbox.1) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for c in b.index_bbox.min.iter().chain(&b.index_bbox.max) {
        out.extend_from_slice(&c.to_le_bytes());
    }
    for v in &b.voxel_size {
        out.extend_from_slice(&v.to_le_bytes());
    }
    put_u32(out, g.name.len() as u32 + 1);
    for c in b.node_count.iter().chain(&[1]).chain(&b.tile_count) {
        put_u32(out, *c);
    }
    out.extend_from_slice(&0u16.to_le_bytes()); // codec
    out.extend_from_slice(&0u16.to_le_bytes()); // padding
    put_u32(out, version_id());
    out.extend_from_slice(g.name.as_bytes());
    out.push(0);
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_u64(out: &mut Vec<u8>, v: u64) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_u32_at(buf: &mut [u8], at: usize, v: u32) {
    buf[at..at + 4].copy_from_slice(&v.to_le_bytes());
}

fn put_u64_at(buf: &mut [u8], at: usize, v: u64) {
    buf[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

fn put_i64(buf: &mut [u8], at: usize, v: i64) {
    buf[at..at + 8].copy_from_slice(&v.to_le_bytes());
}

/// A table entry of `entry` bytes that holds a child: its offset from the parent, the rest 0.
fn put_child(buf: &mut [u8], at: usize, entry: usize, offset: usize) {
    put_i64(buf, at, offset as i64);
    buf[at + 8..at + entry].fill(0);
}

fn put_f32s(buf: &mut [u8], at: usize, v: &[f32]) {
    for (k, c) in v.iter().enumerate() {
        buf[at + 4 * k..at + 4 * k + 4].copy_from_slice(&c.to_le_bytes());
    }
}

fn put_f64s(buf: &mut [u8], at: usize, v: &[f64]) {
    for (k, c) in v.iter().enumerate() {
        buf[at + 8 * k..at + 8 * k + 8].copy_from_slice(&c.to_le_bytes());
    }
}

/// Checks that `bytes` is a complete NanoVDB file as [`write_nanovdb`] writes it: its
/// segments' headers, metadata records and grids lie within it and add up to its length, and
/// every grid starts with NanoVDB's magic and a major version 32. A farm task's resume test
/// for files without a checksum sidecar.
pub fn check_nanovdb_bytes(bytes: &[u8]) -> Result<(), String> {
    let u64_at = |at: usize| bytes.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])));
    let u32_at = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes(b.try_into().unwrap_or([0; 4])));
    let short = |at: usize| format!("truncated at byte {at} of {}", bytes.len());
    let mut at = 0usize;
    while at < bytes.len() {
        if u64_at(at) != Some(NANOVDB_MAGIC) {
            return Err(format!("no NanoVDB header at byte {at}"));
        }
        let version = u32_at(at + 8).ok_or_else(|| short(at))?;
        if version >> 21 != NANOVDB_VERSION.0 {
            return Err(format!("NanoVDB major version {} (not {})", version >> 21, NANOVDB_VERSION.0));
        }
        let count = bytes.get(at + 12..at + 14).map(|b| u16::from_le_bytes([b[0], b[1]])).ok_or_else(|| short(at))?;
        at += 16;
        let mut sizes = Vec::with_capacity(count as usize);
        for _ in 0..count {
            let size = u64_at(at + 8).ok_or_else(|| short(at))?;
            let name = u32_at(at + 136).ok_or_else(|| short(at))? as usize;
            sizes.push(size);
            at = at.checked_add(META_DATA_SIZE + name).filter(|&e| e <= bytes.len()).ok_or_else(|| short(at))?;
        }
        for size in sizes {
            let end = usize::try_from(size).ok().and_then(|s| at.checked_add(s)).filter(|&e| e <= bytes.len());
            let end = end.ok_or_else(|| short(at))?;
            if size < (GRID_DATA_SIZE + TREE_DATA_SIZE) as u64 || u64_at(at) != Some(NANOVDB_MAGIC) {
                return Err(format!("no NanoVDB grid at byte {at}"));
            }
            at = end;
        }
    }
    if at == 0 {
        return Err("the file is empty".into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{GridSpec, Volume};
    use glam::{UVec3, Vec3};

    #[test]
    fn node_sizes_are_nanovdbs() {
        // sizeof(RootData), sizeof(InternalData<…, 5>), <…, 4> and sizeof(LeafData) in
        // NanoVDB 32.4 for float and Vec3f values.
        assert_eq!(
            (root_size(1), internal_layout(5, 1).3, internal_layout(4, 1).3, leaf_layout(1).1),
            (64, 270400, 33856, 2144)
        );
        assert_eq!(
            (root_size(3), internal_layout(5, 3).3, internal_layout(4, 3).3, leaf_layout(3).1),
            (96, 532544, 66624, 6272)
        );
        assert_eq!(version_id(), 32 << 21 | 4 << 10 | 2);
        assert_eq!(string_hash(""), 0);
        assert_eq!(string_hash("ab"), 97 * 67 + 98);
    }

    #[test]
    fn nanovdb_files_check_whole_and_truncated() {
        let spec = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::new(9, 4, 3) };
        let v = Volume::new(spec, (0..108).map(|n| (n % 5) as f32).collect());
        let path = std::path::Path::new("unit.nvdb");
        let (bytes, stats) =
            encode_nanovdb(path, &[VdbGrid::from_volume("density", &v)], &VdbOptions::default()).unwrap();
        assert_eq!(stats.bytes as usize, bytes.len());
        assert_eq!(stats.grids[0].active_voxels, 108 - 108 / 5 - 1);
        check_nanovdb_bytes(&bytes).unwrap();
        for cut in [0, 10, 100, bytes.len() - 1] {
            assert!(check_nanovdb_bytes(&bytes[..cut]).is_err(), "cut at {cut}");
        }
    }
}

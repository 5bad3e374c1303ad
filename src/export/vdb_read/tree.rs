//! A grid's tree: the root's tiles and children, the internal nodes' masks and tiles, and the
//! leaves' values (float or half, one or three components, through `compression`), each size
//! checked against the bytes left and the grid's limits ([`MAX_LEAVES`](super::MAX_LEAVES),
//! [`MAX_TILES`](super::MAX_TILES)). The topology must end where the grid's descriptor puts
//! its values, the values where it puts the grid's end, and the tree must match the voxel
//! count and bounds its metadata records: otherwise a damaged count would be read as a
//! different volume.

use super::compression::read_data;
use super::cursor::Cursor;
use super::file::{frame_of, read_transform, skip_metadata, Descriptor, ValueType};
use super::{Leaf, VdbFloatGrid, MAX_LEAVES, MAX_TILES};
use crate::export::vdb::{COMPRESS_ACTIVE_MASK, COMPRESS_BLOSC, COMPRESS_ZIP};
use crate::export::ExportError;
use std::collections::HashMap;

pub(super) fn read_grid(cur: &mut Cursor, desc: &Descriptor, kind: ValueType) -> Result<VdbFloatGrid, ExportError> {
    let half = kind.half;
    let compression = cur.u32("the compression flags")?;
    if compression & !(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC) != 0 {
        return Err(cur.corrupt(format!("unknown compression flags {compression:#x}")));
    }
    let metadata = skip_metadata(cur)?;
    let transform = read_transform(cur)?;

    // Topology.
    let buffer_count = cur.i32("the buffer count")?;
    if buffer_count != 1 {
        return Err(cur.corrupt(format!("buffer count {buffer_count}, expected 1")));
    }
    let background = read_value(cur, kind.components, "the background value")?;
    let num_tiles = cur.count(13 + 4 * kind.components, "the root tile count")?;
    let num_children = cur.u32("the root child count")? as usize;
    let mut tiles = HashMap::new();
    for _ in 0..num_tiles {
        let origin = [cur.i32("a root tile")?, cur.i32("a root tile")?, cur.i32("a root tile")?];
        let value = read_value(cur, kind.components, "a root tile value")?;
        let active = cur.u8("a root tile state")? != 0;
        if origin.iter().any(|c| c & 4095 != 0) {
            return Err(cur.corrupt(format!("root tile origin {origin:?} is not a multiple of 4096")));
        }
        if active || value != background {
            tiles.insert((3u8, origin), (value, active));
        }
    }
    // Each root child needs at least 12 bytes of origin and 8 KiB of masks.
    if num_children.saturating_mul(12 + 8192) > cur.remaining() {
        return Err(cur.corrupt(format!("the root child count is {num_children}, more than the file can hold")));
    }
    let ctx = Ctx { compression, half, components: kind.components, background };
    // Leaf origins in file order, with their topology masks.
    let mut leaf_order: Vec<[i32; 3]> = Vec::new();
    for _ in 0..num_children {
        let origin =
            [cur.i32("a root child origin")?, cur.i32("a root child origin")?, cur.i32("a root child origin")?];
        if origin.iter().any(|c| c & 4095 != 0) {
            return Err(cur.corrupt(format!("root child origin {origin:?} is not a multiple of 4096")));
        }
        read_internal(cur, &ctx, origin, 5, &mut tiles, &mut leaf_order)?;
    }

    // The topology ends where the descriptor says the buffers begin, as OpenVDB checks: a
    // count or mask changed in the file reads past it or stops short.
    if cur.pos != desc.block_pos {
        return Err(cur.corrupt(format!(
            "the tree's topology ends at byte {}, but the grid's descriptor puts its values at byte {}",
            cur.pos, desc.block_pos
        )));
    }
    let mut leaves = HashMap::with_capacity(leaf_order.len());
    let mut values = vec![0.0f32; 512];
    for origin in leaf_order {
        let mask_vec = cur.mask(8, "a leaf's value mask")?;
        let mut mask = [0u64; 8];
        mask.copy_from_slice(&mask_vec);
        read_values(cur, &ctx, &mut values, &mask_vec)?;
        let mut boxed = Box::new([0.0f32; 512]);
        boxed.copy_from_slice(&values);
        leaves.insert(origin, Leaf { mask, values: boxed });
    }
    if cur.pos != desc.end_pos {
        return Err(cur.corrupt(format!(
            "the grid's values end at byte {}, but its descriptor puts its end at byte {}",
            cur.pos, desc.end_pos
        )));
    }
    let frame = frame_of(&metadata);
    let grid = VdbFloatGrid { name: desc.name.clone(), background, transform, half, metadata, frame, leaves, tiles };
    check_statistics(cur, &grid)?;
    Ok(grid)
}

/// One value at full precision (backgrounds, tiles and inactive values are never half).
fn read_value(cur: &mut Cursor, components: usize, what: &str) -> Result<f32, ExportError> {
    let first = cur.f32(what)?;
    for _ in 1..components {
        cur.f32(what)?;
    }
    Ok(first)
}

/// The voxel count and bounds that OpenVDB (and our writer) record in a grid's metadata
/// (`file_voxel_count`, `file_bbox_min`, `file_bbox_max`) match the tree read: a changed mask
/// or value in the file's topology shows as a different count.
fn check_statistics(cur: &Cursor, grid: &VdbFloatGrid) -> Result<(), ExportError> {
    let get =
        |name: &str, ty: &str| grid.metadata.iter().find(|(n, t, _)| n == name && t == ty).map(|m| m.2.as_slice());
    if let Some(count) = get("file_voxel_count", "int64").and_then(|v| <[u8; 8]>::try_from(v).ok()) {
        let (recorded, read) = (i64::from_le_bytes(count), grid.active_voxel_count());
        if recorded >= 0 && recorded as u64 != read {
            return Err(cur.corrupt(format!("the tree holds {read} active voxels, its metadata records {recorded}")));
        }
    }
    let vec3i = |name: &str| {
        get(name, "vec3i")
            .filter(|v| v.len() == 12)
            .map(|v| [0, 1, 2].map(|c| i32::from_le_bytes([v[4 * c], v[4 * c + 1], v[4 * c + 2], v[4 * c + 3]])))
    };
    if let (Some(lo), Some(hi), Some(bbox)) = (vec3i("file_bbox_min"), vec3i("file_bbox_max"), grid.active_bbox()) {
        if (lo, hi) != bbox {
            return Err(cur.corrupt(format!(
                "the tree's active voxels span {:?} to {:?}, its metadata records {lo:?} to {hi:?}",
                bbox.0, bbox.1
            )));
        }
    }
    Ok(())
}

struct Ctx {
    compression: u32,
    half: bool,
    components: usize,
    background: f32,
}

/// An internal node's topology (log2 dim 5 or 4) and, recursively, its children's.
fn read_internal(
    cur: &mut Cursor,
    ctx: &Ctx,
    origin: [i32; 3],
    log2: u32,
    tiles: &mut HashMap<(u8, [i32; 3]), (f32, bool)>,
    leaf_order: &mut Vec<[i32; 3]>,
) -> Result<(), ExportError> {
    let size = 1usize << (3 * log2);
    let words = size / 64;
    let child_mask = cur.mask(words, "an internal node's child mask")?;
    let value_mask = cur.mask(words, "an internal node's value mask")?;
    let mut values = vec![0.0f32; size];
    read_values(cur, ctx, &mut values, &value_mask)?;
    // Child (or tile) n covers 2^child_total voxels per axis.
    let child_total: u32 = if log2 == 5 { 7 } else { 3 };
    let level: u8 = if log2 == 5 { 2 } else { 1 };
    let offset = |n: usize| {
        let n = n as i32;
        let l = log2 as i32;
        let dim = (1i32 << l) - 1;
        // Wrapping, as OpenVDB's coordinates do, so that no origin in a file can overflow.
        [
            origin[0].wrapping_add(((n >> (2 * l)) & dim) << child_total),
            origin[1].wrapping_add(((n >> l) & dim) << child_total),
            origin[2].wrapping_add((n & dim) << child_total),
        ]
    };
    for n in 0..size {
        let is_child = child_mask[n >> 6] >> (n & 63) & 1 == 1;
        if is_child {
            continue;
        }
        let active = value_mask[n >> 6] >> (n & 63) & 1 == 1;
        if active || values[n] != ctx.background {
            if tiles.len() >= MAX_TILES {
                return Err(ExportError::unsupported(
                    cur.path,
                    format!("grid {:?} has more than {MAX_TILES} tiles, too many to import", cur.grid),
                    "prune or resample the grid before importing it",
                ));
            }
            tiles.insert((level, offset(n)), (values[n], active));
        }
    }
    for (w, word) in child_mask.iter().enumerate() {
        let mut bits = *word;
        while bits != 0 {
            let n = w * 64 + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let child_origin = offset(n);
            if log2 == 5 {
                read_internal(cur, ctx, child_origin, 4, tiles, leaf_order)?;
            } else {
                if leaf_order.len() >= MAX_LEAVES {
                    return Err(ExportError::unsupported(
                        cur.path,
                        format!(
                            "grid {:?} has more than {MAX_LEAVES} leaves ({} M voxels), too many to import",
                            cur.grid,
                            MAX_LEAVES * 512 / 1_000_000
                        ),
                        "resample the grid to a coarser voxel size before importing it",
                    ));
                }
                cur.take(64, "a leaf's topology mask")?;
                leaf_order.push(child_origin);
            }
        }
    }
    Ok(())
}

/// OpenVDB's `readCompressedValues`: fills `dest` (one node's values) from a value block.
fn read_values(cur: &mut Cursor, ctx: &Ctx, dest: &mut [f32], value_mask: &[u64]) -> Result<(), ExportError> {
    let meta = cur.u8("a value block's metadata")?;
    if meta > 6 {
        return Err(cur.corrupt(format!("unknown value block metadata {meta}")));
    }
    let bg = ctx.background;
    let mut inactive0 = if meta == 1 { -bg } else { bg };
    let mut inactive1 = bg;
    if meta == 2 || meta == 4 || meta == 5 {
        inactive0 = read_value(cur, ctx.components, "an inactive value")?;
        if meta == 5 {
            inactive1 = read_value(cur, ctx.components, "an inactive value")?;
        }
    }
    let selection =
        if meta == 3 || meta == 4 || meta == 5 { Some(cur.mask(dest.len() / 64, "a selection mask")?) } else { None };
    let mask_compressed = ctx.compression & COMPRESS_ACTIVE_MASK != 0 && meta != 6;
    let count = if mask_compressed { value_mask.iter().map(|w| w.count_ones() as usize).sum() } else { dest.len() };
    let mut temp = vec![0.0f32; count];
    let n = ctx.components;
    if ctx.half {
        if count > 0 {
            let raw = read_data(cur, ctx.compression, count * n * 2)?;
            for (t, c) in temp.iter_mut().zip(raw.chunks_exact(2 * n)) {
                *t = half::f16::from_le_bytes([c[0], c[1]]).to_f32();
            }
        }
    } else {
        let raw = read_data(cur, ctx.compression, count * n * 4)?;
        for (t, c) in temp.iter_mut().zip(raw.chunks_exact(4 * n)) {
            *t = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        }
    }
    if count == dest.len() {
        dest.copy_from_slice(&temp);
    } else {
        let mut src = temp.into_iter();
        for (n, d) in dest.iter_mut().enumerate() {
            let on = value_mask[n >> 6] >> (n & 63) & 1 == 1;
            *d = if on {
                src.next().unwrap_or(bg)
            } else if selection.as_ref().is_some_and(|s| s[n >> 6] >> (n & 63) & 1 == 1) {
                inactive1
            } else {
                inactive0
            };
        }
    }
    Ok(())
}

//! The file around the trees: the header and grid descriptors, each grid's metadata and
//! transform, and the export frame the metadata names.

use super::cursor::Cursor;
use super::VdbTransform;
use crate::export::frame::Frame;
use crate::export::vdb::VDB_MAGIC;
use crate::export::ExportError;
use std::path::Path;

pub(super) fn float_type(tree_type: &str) -> Option<bool> {
    value_type(tree_type).filter(|t| t.components == 1).map(|t| t.half)
}

/// What kind of values a tree holds: float or half in the file, 1 (float) or 3 (vec3s)
/// components. A vec3s grid is read for its structure; its first component stands for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct ValueType {
    pub(super) half: bool,
    pub(super) components: usize,
}

/// The value type of the trees this reader parses: float and vec3s, each float or half.
pub(super) fn value_type(tree_type: &str) -> Option<ValueType> {
    let (components, half) = match tree_type {
        "Tree_float_5_4_3" => (1, false),
        "Tree_float_5_4_3_HalfFloat" => (1, true),
        "Tree_vec3s_5_4_3" => (3, false),
        "Tree_vec3s_5_4_3_HalfFloat" => (3, true),
        _ => return None,
    };
    Some(ValueType { half, components })
}

pub(super) struct Descriptor {
    pub(super) name: String,
    pub(super) tree_type: String,
    pub(super) instance_parent: String,
    pub(super) grid_pos: usize,
    pub(super) block_pos: usize,
    pub(super) end_pos: usize,
}

pub(super) struct FileHeader {
    pub(super) version: u32,
    pub(super) descriptors: Vec<Descriptor>,
}

pub(super) fn parse_header(path: &Path, bytes: &[u8]) -> Result<FileHeader, ExportError> {
    let mut cur = Cursor { path, bytes, pos: 0, version: 0, grid: String::new() };
    let magic = cur.i64("the file magic").map_err(|_| not_vdb(path))?;
    if magic != VDB_MAGIC {
        return Err(not_vdb(path));
    }
    let version = cur.u32("the file version")?;
    if !(222..=224).contains(&version) {
        return Err(ExportError::unsupported(
            path,
            format!("OpenVDB file format version {version} is not supported (this reader knows versions 222 to 224)"),
            "re-save the file with a current OpenVDB, Houdini or Blender",
        ));
    }
    cur.version = version;
    let _lib_major = cur.u32("the library version")?;
    let _lib_minor = cur.u32("the library version")?;
    let has_offsets = cur.u8("the grid-offsets flag")?;
    if has_offsets == 0 {
        return Err(ExportError::unsupported(
            path,
            "the file has no grid offsets (an old streaming layout)",
            "re-save the file with a current OpenVDB, Houdini or Blender",
        ));
    }
    cur.take(36, "the file UUID")?;
    skip_metadata(&mut cur)?;
    let n = cur.count(36, "the grid count")?;
    let mut descriptors = Vec::with_capacity(n);
    for _ in 0..n {
        let mut name = cur.string("a grid name")?;
        // OpenVDB appends "\x1e<n>" to repeated names.
        if let Some(i) = name.find('\u{1e}') {
            name.truncate(i);
        }
        let tree_type = cur.string("a grid type")?;
        let instance_parent = cur.string("a grid's instance parent")?;
        let grid_pos = cur.i64("a grid position")?;
        let block_pos = cur.i64("a grid's block position")?;
        let end_pos = cur.i64("a grid's end position")?;
        let ok = |p: i64| p >= 0 && (p as u64) <= bytes.len() as u64;
        if !(ok(grid_pos)
            && ok(block_pos)
            && ok(end_pos)
            && grid_pos as usize >= cur.pos
            && grid_pos <= block_pos
            && block_pos <= end_pos)
        {
            return Err(cur.corrupt(format!(
                "grid {name:?}: offsets {grid_pos}, {block_pos}, {end_pos} do not fit a {}-byte file",
                bytes.len()
            )));
        }
        descriptors.push(Descriptor {
            name,
            tree_type,
            instance_parent,
            grid_pos: grid_pos as usize,
            block_pos: block_pos as usize,
            end_pos: end_pos as usize,
        });
        cur.pos = end_pos as usize;
    }
    Ok(FileHeader { version, descriptors })
}

fn not_vdb(path: &Path) -> ExportError {
    ExportError::Invalid {
        path: path.to_path_buf(),
        problem: "not an OpenVDB file (no \" BDV\" magic at its start)".into(),
        fix: "pick a .vdb file".into(),
    }
}

pub(super) fn skip_metadata(cur: &mut Cursor) -> Result<Vec<(String, String, Vec<u8>)>, ExportError> {
    let n = cur.count(12, "the metadata count")?;
    let mut out = Vec::with_capacity(n);
    for _ in 0..n {
        let name = cur.string("a metadata name")?;
        let ty = cur.string("a metadata type")?;
        let size = cur.u32("a metadata size")? as usize;
        let value = cur.take(size, "a metadata value")?.to_vec();
        out.push((name, ty, value));
    }
    Ok(out)
}

pub(super) fn read_transform(cur: &mut Cursor) -> Result<VdbTransform, ExportError> {
    let map = cur.string("the transform's map type")?;
    let (path, grid) = (cur.path, cur.grid.clone());
    let unsupported = |problem: String| {
        ExportError::unsupported(
            path,
            format!("grid {grid:?}: {problem}"),
            "resample the grid to an axis-aligned (scale and translate) transform before exporting it",
        )
    };
    let t = match map.as_str() {
        "UniformScaleMap" | "ScaleMap" => {
            let scale = cur.vec3d("the map's scale")?;
            for _ in 0..4 {
                cur.vec3d("the map's derived values")?;
            }
            VdbTransform::axis_aligned(scale, [0.0; 3])
        }
        "UniformScaleTranslateMap" | "ScaleTranslateMap" => {
            let translation = cur.vec3d("the map's translation")?;
            let scale = cur.vec3d("the map's scale")?;
            for _ in 0..4 {
                cur.vec3d("the map's derived values")?;
            }
            VdbTransform::axis_aligned(scale, translation)
        }
        "TranslationMap" => VdbTransform::axis_aligned([1.0; 3], cur.vec3d("the map's translation")?),
        "AffineMap" | "UnitaryMap" => {
            // A 4×4 matrix of doubles, row vectors: world = [i j k 1] · M.
            let mut m = [[0.0f64; 4]; 4];
            for row in m.iter_mut() {
                for c in row.iter_mut() {
                    *c = cur.f64("the affine matrix")?;
                }
            }
            // Each index axis (row) must move along exactly one world axis, each world axis
            // taken once: a scale times a signed permutation.
            let size = m[..3].iter().flat_map(|r| r[..3].iter()).fold(0.0f64, |a, v| a.max(v.abs()));
            let mut axis = [usize::MAX; 3];
            let mut scale = [0.0; 3];
            for a in 0..3 {
                let big: Vec<usize> = (0..3).filter(|&b| m[a][b].abs() > 1e-9 * size).collect();
                if big.len() != 1 || axis[..a].contains(&big[0]) {
                    return Err(unsupported(format!(
                        "its {map} rotates or shears the voxels (not axis-aligned, nor an axis permutation), which cannot be imported exactly"
                    )));
                }
                axis[a] = big[0];
                scale[a] = m[a][big[0]];
            }
            if m[0][3] != 0.0 || m[1][3] != 0.0 || m[2][3] != 0.0 {
                return Err(unsupported(format!("its {map} is a projective map, which cannot be imported")));
            }
            VdbTransform { axis, scale, translation: [m[3][0], m[3][1], m[3][2]] }
        }
        "NonlinearFrustumMap" => {
            return Err(unsupported("it uses a frustum (camera-shaped) transform, which cannot be imported".into()));
        }
        other => return Err(unsupported(format!("unknown transform map type {other:?}"))),
    };
    if !t.scale.iter().all(|s| s.is_finite() && *s != 0.0) || !t.translation.iter().all(|c| c.is_finite()) {
        return Err(cur.corrupt(format!("degenerate transform (scale {:?}, translation {:?})", t.scale, t.translation)));
    }
    Ok(t)
}

/// The export frame named by `up_axis`, `meters_per_unit` and `handedness`, or Fogsmith's own.
pub(super) fn frame_of(metadata: &[(String, String, Vec<u8>)]) -> Frame {
    let get =
        |name: &str, ty: &str| metadata.iter().find(|(n, t, _)| n == name && t == ty).map(|(_, _, v)| v.as_slice());
    let text = |name| get(name, "string").map(|v| String::from_utf8_lossy(v).into_owned());
    let mpu = get("meters_per_unit", "double").and_then(|v| <[u8; 8]>::try_from(v).ok()).map(f64::from_le_bytes);
    match (text("up_axis"), mpu, text("handedness")) {
        (Some(up), Some(mpu), Some(hand)) => Frame::from_names(&up, mpu, &hand).unwrap_or(Frame::NATIVE),
        _ => Frame::NATIVE,
    }
}

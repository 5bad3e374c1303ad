//! Interchange: baked grids out as OpenVDB and OpenEXR, and a VDB density in as a base layer.
//!
//! - [`image`]: rendered images: tone-mapped PNG, linear HDR EXR.
//! - [`frame`]: the up axis, units and handedness of the tool a file is for (`--preset`).
//! - [`usd`]: the whole scene as an OpenUSD stage whose volume points at the exported VDB.
//! - [`ktx`]: the extinction as a KTX2 3D texture plus a Bevy `FogVolume` snippet.
//! - [`vdb`]: a small OpenVDB writer (file format 224, as OpenVDB 10 writes it) for the
//!   extinction grid (`density`) and one optical-depth grid per light (`optical_depth_<i>`,
//!   optionally `transmittance_<i>`), sparse, float or half, uncompressed or zip.
//! - [`nanovdb`]: the same grids as a NanoVDB file (version 32.4, uncompressed), for renderers
//!   and engines that load NanoVDB without OpenVDB.
//! - [`vdb_read`]: our own reader for the subset of OpenVDB files an artist imports as fog:
//!   float/half `FloatGrid`s, uncompressed, zip or blosc (lz4), tiles, several grids per file;
//!   it refuses everything else with a message, never panics and bounds every allocation.
//!   [`vdb_read::resample_into`] turns such a grid into a project's dense grid.
//! - [`exr`]: the linear HDR render, the grids as one multi-layer EXR (a layer per quantity
//!   per z-slice) and the extinction as a 2D slice atlas for game engines.
//! - [`sequence`]: frame lists (`--frames 1-120x4`) and frame-numbered output paths
//!   (`fog.####.vdb`) for animations.
//! - [`plan`]: which of these files to write and with which settings, and the one function
//!   that writes them; `fogsmith export` and the editor's Export window both call it.
//!
//! Every writer writes a temporary file beside the destination and renames it into place,
//! so a failed export never leaves a partial file at the destination.
//!
//! Nothing here calls the GPU: exporters take [`crate::scene::Volume`]s (the EV and the
//! per-light optical depths read back by the pipeline), the read-back [`crate::gpu::Image`]
//! and [`LightInfo`].

pub mod exr;
pub mod exr_read;
pub mod frame;
pub mod godot;
pub mod image;
pub mod ktx;
pub mod nanovdb;
pub mod plan;
pub mod sequence;
pub mod staged;
pub mod usd;
pub mod vdb;
pub mod vdb_read;

pub use plan::{write_plan, ExportPlan, ExportSettings};
pub use staged::Staged;

use std::io::Write;
use std::path::{Path, PathBuf};

/// What a light contributes to an export: metadata on its grids. Plain data, filled by the
/// caller from the project's lights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LightInfo {
    /// The light's stable id in the project (written as `light_id`).
    pub id: u32,
    /// World-space position, metres.
    pub position: [f32; 3],
    /// Radiant intensity, W/sr.
    pub intensity: f32,
    /// Linear RGB colour.
    pub color: [f32; 3],
}

impl LightInfo {
    /// The light with its position carried into `frame` (see [`frame::Frame::point`]).
    pub fn in_frame(&self, frame: &frame::Frame) -> LightInfo {
        LightInfo { position: frame.point_f32(self.position), ..*self }
    }
}

/// Why an export or an import failed. Every variant names the file, the problem and, where
/// there is one, what to do about it.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    #[error("{path}: cannot write: {source}. Check that the folder exists, is writable and has free space.")]
    Write { path: PathBuf, source: std::io::Error },
    #[error("{path}: cannot read: {source}. Check the path and the file's permissions.")]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{path}: {problem}. {fix}")]
    Invalid { path: PathBuf, problem: String, fix: String },
    #[error("{path}: not a readable OpenVDB file: {problem} (at byte {offset}). The file is damaged or truncated; export it again from the application that made it.")]
    Corrupt { path: PathBuf, problem: String, offset: u64 },
    #[error("{path}: {problem}. {fix}")]
    Unsupported { path: PathBuf, problem: String, fix: String },
}

impl ExportError {
    pub(crate) fn invalid(path: &Path, problem: impl Into<String>, fix: impl Into<String>) -> Self {
        ExportError::Invalid { path: path.to_path_buf(), problem: problem.into(), fix: fix.into() }
    }
    pub(crate) fn unsupported(path: &Path, problem: impl Into<String>, fix: impl Into<String>) -> Self {
        ExportError::Unsupported { path: path.to_path_buf(), problem: problem.into(), fix: fix.into() }
    }
}

/// Writes `bytes` to `path` atomically: a temporary file in the same folder, flushed and
/// synced, then renamed over the destination. On failure the temporary file is removed and
/// the destination is untouched.
pub(crate) fn write_atomic(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<(), ExportError>,
) -> Result<(), ExportError> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "export".into());
    // Unique per process and per call, so that two exports to one destination never share it.
    static COUNTER: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = COUNTER.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = dir.join(format!(".{}.{}-{}.tmp", file_name, std::process::id(), n));
    let result = write(&tmp).and_then(|()| {
        std::fs::rename(&tmp, path).map_err(|source| ExportError::Write { path: path.to_path_buf(), source })
    });
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// [`write_atomic`] for an in-memory file.
pub(crate) fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<(), ExportError> {
    write_atomic(path, |tmp| {
        let err = |source| ExportError::Write { path: path.to_path_buf(), source };
        let mut f = std::fs::File::create(tmp).map_err(err)?;
        f.write_all(bytes).map_err(err)?;
        f.sync_all().map_err(err)?;
        Ok(())
    })
}

/// Writes a text file atomically.
pub fn write_text(path: &Path, text: &str) -> Result<(), ExportError> {
    write_bytes_atomic(path, text.as_bytes())
}

/// The project's `base_volume` resampled into its grid and multiplied by its scale, or
/// `None` when it has none: the one place that turns `base_volume` into extinction values.
/// The editor's preview, slices and exports, `verify`, `render` and `export` all load it
/// here, so none of them can leave the imported fog out. A relative path is resolved
/// against the folder of `project_path` (the project file; `None` for a project never
/// saved, when it is taken as relative to the working directory). It lives here, not in
/// `scene`, so that the model does not depend on a file format.
pub fn load_base_layer(
    project: &crate::scene::Project,
    project_path: Option<&Path>,
) -> Result<Option<crate::scene::Volume>, ExportError> {
    let Some(base) = &project.base_volume else { return Ok(None) };
    let dir = project_path.and_then(Path::parent).filter(|d| !d.as_os_str().is_empty());
    let path = base.resolved_path(dir);
    vdb_read::import_density(&path, Some(&base.grid), &project.grid, base.scale).map(Some)
}

/// Export metadata of the project's lights, indexed like its OPVs.
pub fn light_infos(project: &crate::scene::Project) -> Vec<LightInfo> {
    project
        .lights
        .iter()
        .map(|l| LightInfo {
            id: l.id,
            position: l.position.to_array(),
            intensity: l.intensity,
            color: l.color.to_array(),
        })
        .collect()
}

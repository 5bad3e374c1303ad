//! The project's base volume: the one place that turns `base_volume` into extinction
//! values on the project's grid. The editor's preview, slices and exports, `verify`,
//! `render` and `export` all load it through [`Project::load_base_volume`], so none of
//! them can leave the imported fog out.

use super::{Project, Volume};
use crate::export::{vdb_read, ExportError};
use std::path::Path;

impl Project {
    /// The `base_volume` grid resampled into the project's grid and multiplied by its scale,
    /// or `None` when the project has none. A relative path is resolved against the folder
    /// of `project_path` (the project file; `None` for a project never saved, when a
    /// relative path is taken as relative to the working directory).
    pub fn load_base_volume(&self, project_path: Option<&Path>) -> Result<Option<Volume>, ExportError> {
        let Some(base) = &self.base_volume else { return Ok(None) };
        let dir = project_path.and_then(Path::parent).filter(|d| !d.as_os_str().is_empty());
        let path = base.resolved_path(dir);
        vdb_read::import_density(&path, Some(&base.grid), &self.grid, base.scale).map(Some)
    }
}

//! Outputs written beside their targets and moved into place together, so a failed or
//! cancelled export leaves every existing file untouched.

/// Output files written beside their targets and moved into place together at the end, so
/// that an error or Ctrl+C leaves every existing output untouched and no temporary behind.
#[derive(Default)]
pub struct Staged {
    files: Vec<(std::path::PathBuf, std::path::PathBuf)>,
}

impl Staged {
    /// Where to write `target` for now.
    pub fn path(&mut self, target: &std::path::Path) -> std::path::PathBuf {
        // The extension stays last: some writers check it.
        let stem = target.file_stem().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let temp = match target.extension() {
            Some(ext) => target.with_file_name(format!(".{stem}.fogsmith-partial.{}", ext.to_string_lossy())),
            None => target.with_file_name(format!(".{stem}.fogsmith-partial")),
        };
        self.files.push((temp.clone(), target.to_path_buf()));
        temp
    }

    /// Runs `write` on the staged path of `target`; an error names `target`, not the staged file.
    pub fn write<T, E: std::fmt::Display>(
        &mut self,
        target: &std::path::Path,
        write: impl FnOnce(&std::path::Path) -> Result<T, E>,
    ) -> Result<T, String> {
        let temp = self.path(target);
        write(&temp).map_err(|e| e.to_string().replace(&*temp.to_string_lossy(), &target.to_string_lossy()))
    }

    /// Moves every staged file onto its target.
    pub fn commit(mut self) -> std::io::Result<()> {
        while let Some((temp, target)) = self.files.first().cloned() {
            std::fs::rename(&temp, &target)?;
            self.files.remove(0);
        }
        Ok(())
    }
}

impl Drop for Staged {
    fn drop(&mut self) {
        for (temp, _) in &self.files {
            let _ = std::fs::remove_file(temp);
        }
    }
}

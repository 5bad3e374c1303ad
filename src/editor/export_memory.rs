//! The Export window's last choices per project, in one small RON file in the editor's state
//! directory, keyed by the project file's canonical path; an unsaved project's choices last for
//! the session. A file that cannot be read is ignored with a note and replaced at the next
//! export. With them, the Export window's state: open on some choices or closed.

use super::export_choices::ExportChoices;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The file's name in the state directory.
pub const FILE_NAME: &str = "export-choices.ron";

/// Projects remembered; the least recently exported are forgotten first.
const MAX_PROJECTS: usize = 64;

/// What the file holds: the most recently exported project first.
#[derive(Default, Serialize, Deserialize)]
struct Stored {
    projects: Vec<(PathBuf, ExportChoices)>,
}

pub(crate) struct ExportMemory {
    file: PathBuf,
    /// The file's content once read (empty if it was missing or unreadable).
    stored: Option<Stored>,
    /// The untitled project's choices, this session only.
    unsaved: Option<ExportChoices>,
}

impl ExportMemory {
    pub fn new(state_dir: PathBuf) -> Self {
        Self { file: state_dir.join(FILE_NAME), stored: None, unsaved: None }
    }

    /// Reads the file the first time it is needed; the note says why it was ignored.
    fn load(&mut self) -> (&mut Stored, Option<String>) {
        let mut note = None;
        if self.stored.is_none() {
            let stored = match std::fs::read_to_string(&self.file) {
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => Stored::default(),
                Err(e) => {
                    note = Some(format!(
                        "Ignored {}: {e}; the Export window starts from the defaults",
                        self.file.display()
                    ));
                    Stored::default()
                }
                Ok(text) => ron::from_str(&text).unwrap_or_else(|e: ron::error::SpannedError| {
                    let first = e.to_string().lines().next().unwrap_or_default().to_string();
                    note = Some(format!(
                        "Ignored {} ({first}); the Export window starts from the defaults",
                        self.file.display()
                    ));
                    Stored::default()
                }),
            };
            self.stored = Some(stored);
        }
        (self.stored.get_or_insert_with(Stored::default), note)
    }

    /// The choices last used for `project` (None: the untitled project), or the defaults, and
    /// a note when the file had to be ignored.
    pub fn recall(&mut self, project: Option<&Path>) -> (ExportChoices, Option<String>) {
        let Some(project) = project else { return (self.unsaved.unwrap_or_default(), None) };
        let key = canonical(project);
        let (stored, note) = self.load();
        let choices = stored.projects.iter().find(|(p, _)| *p == key).map(|(_, c)| *c).unwrap_or_default();
        (choices, note)
    }

    /// Remembers `choices` for `project` and writes the file (None: for this session only).
    pub fn remember(&mut self, project: Option<&Path>, choices: ExportChoices) -> Result<(), String> {
        let Some(project) = project else {
            self.unsaved = Some(choices);
            return Ok(());
        };
        let key = canonical(project);
        let file = self.file.clone();
        let (stored, _) = self.load();
        stored.projects.retain(|(p, _)| *p != key);
        stored.projects.insert(0, (key, choices));
        stored.projects.truncate(MAX_PROJECTS);
        let text = ron::ser::to_string_pretty(&*stored, ron::ser::PrettyConfig::new())
            .map_err(|e| format!("Could not remember the export choices: {e}"))?;
        let written = file
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| crate::scene::io::write_atomic(&file, text.as_bytes(), false));
        written.map_err(|e| format!("Could not remember the export choices in {}: {e}", file.display()))
    }
}

fn canonical(path: &Path) -> PathBuf {
    std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf())
}

/// The Export window while open, and the remembered choices.
pub(crate) struct ExportUi {
    pub window: Option<ExportChoices>,
    pub memory: ExportMemory,
}

impl ExportUi {
    pub fn new(state_dir: PathBuf) -> Self {
        Self { window: None, memory: ExportMemory::new(state_dir) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::editor::export_choices::ExportFormat;

    fn ktx2() -> ExportChoices {
        ExportChoices { format: ExportFormat::Ktx2, ..ExportChoices::default() }
    }

    #[test]
    fn choices_are_kept_per_project_and_for_the_untitled_one_this_session_only() {
        let dir = tempfile::tempdir().unwrap();
        let project = dir.path().join("p.ron");
        std::fs::write(&project, "").unwrap();
        let mut memory = ExportMemory::new(dir.path().join("state"));
        assert_eq!(memory.recall(Some(&project)), (ExportChoices::default(), None));
        memory.remember(Some(&project), ktx2()).unwrap();
        memory.remember(None, ExportChoices { format: ExportFormat::Image, ..ExportChoices::default() }).unwrap();
        assert_eq!(memory.recall(None).0.format, ExportFormat::Image);

        // Another run reads the file; the path is the same file by another spelling.
        let mut next = ExportMemory::new(dir.path().join("state"));
        let other_spelling = dir.path().join(".").join("p.ron");
        assert_eq!(next.recall(Some(&other_spelling)), (ktx2(), None));
        assert_eq!(next.recall(None), (ExportChoices::default(), None), "the untitled project's are not kept");
    }

    #[test]
    fn a_damaged_file_is_ignored_with_one_note_and_replaced() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join(FILE_NAME), "(projects: [(\"x\", (format: Vdb, preset: Some(Maya").unwrap();
        let project = dir.path().join("p.ron");
        let mut memory = ExportMemory::new(dir.path().to_path_buf());
        let (choices, note) = memory.recall(Some(&project));
        assert_eq!(choices, ExportChoices::default());
        let note = note.expect("a note");
        assert!(note.contains(FILE_NAME) && !note.contains('\n'), "{note}");
        assert_eq!(memory.recall(Some(&project)).1, None, "said once");
        memory.remember(Some(&project), ktx2()).unwrap();
        assert_eq!(ExportMemory::new(dir.path().to_path_buf()).recall(Some(&project)), (ktx2(), None));
    }
}

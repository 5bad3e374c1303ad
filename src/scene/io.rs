//! Loading and saving projects as RON.
//!
//! Loading reports syntax errors and invalid values with the file, line and column, and
//! validates the project once: what the pipeline and the editor then hold is trusted.
//! Saving is atomic: the text goes to a temporary file in the same directory, is flushed
//! to disk, the previous file is kept as `<name>.bak`, and only then is the temporary file
//! renamed over the destination, so a crash never leaves a half-written project. Projects
//! with many particles keep them in a binary sidecar (see [`sidecar`](super::sidecar)),
//! written before the RON that names it.

use super::sidecar::{self, ParticleFile, SIDECAR_MIN_PARTICLES, SIDECAR_PROJECT_VERSION};
use super::{validate::ValidationError, Project, MAX_RESOLUTION_DEFAULT, PROJECT_VERSION};
use std::io::Write;
use std::path::{Path, PathBuf};

/// Why a project could not be loaded or saved.
#[derive(Debug, thiserror::Error)]
pub enum ProjectError {
    #[error("{path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}:{line}:{col}: {message}")]
    Syntax { path: PathBuf, line: usize, col: usize, message: String },
    #[error("{path}:{line}:{col}: {error}")]
    Invalid { path: PathBuf, line: usize, col: usize, error: ValidationError },
    #[error("could not serialise the project: {0}")]
    Serialize(String),
    /// The particle sidecar a project file names is missing, damaged or invalid.
    #[error("{path}: {message}")]
    Sidecar { path: PathBuf, message: String },
}

/// Reads, parses and validates a project file.
pub fn load_project(path: &Path) -> Result<Project, ProjectError> {
    load_project_with(path, &mut |_, _| {})
}

/// [`load_project`], telling `progress` each step's name and the fraction of the load
/// done before it.
pub fn load_project_with(path: &Path, progress: &mut dyn FnMut(&str, f64)) -> Result<Project, ProjectError> {
    progress("reading", 0.0);
    let text = std::fs::read_to_string(path).map_err(|source| ProjectError::Io { path: path.to_owned(), source })?;
    parse_project_with(&text, path, progress)
}

/// Parses and validates project text; `origin` names the source in error messages, and a
/// particle sidecar is read from its directory.
pub fn parse_project(text: &str, origin: &Path) -> Result<Project, ProjectError> {
    parse_project_with(text, origin, &mut |_, _| {})
}

fn parse_project_with(text: &str, origin: &Path, progress: &mut dyn FnMut(&str, f64)) -> Result<Project, ProjectError> {
    progress("parsing", 0.1);
    let options = ron::Options::default();
    let project: Project = options.from_str(text).map_err(|e| ProjectError::Syntax {
        path: origin.to_owned(),
        line: e.position.line,
        col: e.position.col,
        message: e.code.to_string(),
    })?;
    complete_load(project, text, origin, progress)
}

/// What every load does once `text` (from `origin`) is parsed into `project`: reads the
/// particle sidecar it names from `origin`'s directory, brings it to the current version and
/// validates it, telling `progress` each step.
pub(crate) fn complete_load(
    mut project: Project,
    text: &str,
    origin: &Path,
    progress: &mut dyn FnMut(&str, f64),
) -> Result<Project, ProjectError> {
    let invalid = |error: ValidationError| {
        let (line, col) = locate_field(text, &error.field).unwrap_or((1, 1));
        ProjectError::Invalid { path: origin.to_owned(), line, col, error }
    };
    let sidecar = match project.particle_file.take() {
        Some(file) => {
            if !project.particles.is_empty() {
                return Err(invalid(ValidationError {
                    field: "particle_file".into(),
                    problem: "the project lists particles and also names a particle file; keep one of them".into(),
                }));
            }
            progress("reading particles", 0.5);
            let at = origin.parent().unwrap_or(Path::new("")).join(&file.file);
            let bytes = std::fs::read(&at).map_err(|source| ProjectError::Sidecar {
                path: at.clone(),
                message: format!(
                    "cannot read the particles of {} ({source}); keep this file beside the project, or open the project's .bak",
                    origin.display()
                ),
            })?;
            project.particles =
                sidecar::decode(&bytes, &file).map_err(|message| ProjectError::Sidecar { path: at.clone(), message })?;
            Some(at)
        }
        None if project.version == SIDECAR_PROJECT_VERSION => {
            return Err(invalid(ValidationError {
                field: "version".into(),
                problem: format!(
                    "version {SIDECAR_PROJECT_VERSION} keeps the particles in a file named by particle_file, which is missing; restore that line or load the .bak"
                ),
            }))
        }
        None => None,
    };
    progress("validating", 0.8);
    let located = |error: ValidationError| match &sidecar {
        Some(at) if error.field.starts_with("particles[") => {
            ProjectError::Sidecar { path: at.clone(), message: error.to_string() }
        }
        _ => invalid(error),
    };
    let project = migrate(project).map_err(located)?;
    project.validate(MAX_RESOLUTION_DEFAULT).map_err(located)?;
    Ok(project)
}

/// The version of a project file that names none.
pub(crate) fn unversioned() -> u32 {
    1
}

/// Brings an older project up to [`PROJECT_VERSION`] and checks what the version implies.
///
/// - Version 1 had no ids: particles and lights get their list positions as ids, so what
///   the editor called "Particle 79" stays #79.
/// - Versions 2 and 3: ids must be unique per kind.
/// - Version 3 added animation (`animation`, `tracks`, the noise's wind): older files are
///   stills and read unchanged.
///
/// Every version then has its next-id counters raised above every id in use, and becomes
/// the current version.
fn migrate(mut project: Project) -> Result<Project, ValidationError> {
    let field = |f: &str, problem: String| ValidationError { field: f.into(), problem };
    match project.version {
        1 => {
            for (i, p) in project.particles.iter_mut().enumerate() {
                p.id = i as u32;
            }
            for (i, l) in project.lights.iter_mut().enumerate() {
                l.id = i as u32;
            }
            project.next_id = super::NextIds { particle: project.particles.len() as u32, light: project.lights.len() as u32 };
        }
        2 | PROJECT_VERSION | SIDECAR_PROJECT_VERSION => {
            if let Some((a, b)) = super::ids::first_duplicate(project.particles.iter().map(|p| p.id)) {
                let msg = format!("id {} is already used by particles[{a}]; give every particle its own id", project.particles[b].id);
                return Err(field(&format!("particles[{b}].id"), msg));
            }
            if let Some((a, b)) = super::ids::first_duplicate(project.lights.iter().map(|l| l.id)) {
                let msg = format!("id {} is already used by lights[{a}]; give every light its own id", project.lights[b].id);
                return Err(field(&format!("lights[{b}].id"), msg));
            }
        }
        v => {
            return Err(field(
                "version",
                format!("version {v} is not a project format this build reads (1 to {PROJECT_VERSION}); a newer Fogsmith wrote it, or the number was edited"),
            ))
        }
    }
    project.raise_next_ids();
    project.version = PROJECT_VERSION;
    Ok(project)
}

/// The project as RON text, in the shape of the documented example.
pub fn to_ron_string(project: &Project) -> Result<String, ProjectError> {
    let config = ron::ser::PrettyConfig::new().struct_names(false).indentor("    ").separate_tuple_members(false);
    let body = ron::ser::to_string_pretty(project, config).map_err(|e| ProjectError::Serialize(e.to_string()))?;
    Ok(format!("Project{body}\n"))
}

/// Saves atomically, keeping the previous version as `<path>.bak`. With
/// [`SIDECAR_MIN_PARTICLES`] particles or more, they go to a sidecar written first; the
/// sidecars that neither the new file nor the `.bak` name are removed after the rename.
pub fn save_project(path: &Path, project: &Project) -> Result<(), ProjectError> {
    if project.version != PROJECT_VERSION {
        return Err(ProjectError::Serialize(format!(
            "the project has version {}, but this build writes only version {PROJECT_VERSION}",
            project.version
        )));
    }
    let mut unique;
    let mut project = project;
    if super::ids::first_duplicate(project.particles.iter().map(|p| p.id)).is_some()
        || super::ids::first_duplicate(project.lights.iter().map(|l| l.id)).is_some()
    {
        // A project built in code: number it so that the file loads.
        unique = project.clone();
        unique.ensure_unique_ids();
        project = &unique;
    }
    let io = |at: &Path| {
        let at = at.to_owned();
        move |source| ProjectError::Io { path: at, source }
    };
    // The sidecar the current file names: it becomes the .bak's.
    let previous = std::fs::read_to_string(path).ok().and_then(|t| sidecar::named_in(&t));
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let written = if project.particles.len() >= SIDECAR_MIN_PARTICLES {
        let (bytes, crc32) = sidecar::encode(&project.particles);
        let file = sidecar::sidecar_name(path, crc32);
        write_atomic(&dir.join(&file), &bytes, false).map_err(io(&dir.join(&file)))?;
        let head = Project {
            version: SIDECAR_PROJECT_VERSION,
            particle_file: Some(ParticleFile { file: file.clone(), count: project.particles.len() as u64, crc32 }),
            ..project.without_particles()
        };
        let result = to_ron_string(&head).and_then(|text| write_atomic(path, text.as_bytes(), true).map_err(io(path)));
        if let Err(e) = result {
            if previous.as_ref() != Some(&file) {
                let _ = std::fs::remove_file(dir.join(&file));
            }
            return Err(e);
        }
        Some(file)
    } else {
        let text = to_ron_string(project)?;
        write_atomic(path, text.as_bytes(), true).map_err(io(path))?;
        None
    };
    remove_stale_sidecars(path, &dir, [written, previous]);
    Ok(())
}

/// Removes the sidecars of the project file `path` other than `keep`.
pub(crate) fn remove_stale_sidecars(path: &Path, dir: &Path, keep: [Option<PathBuf>; 2]) {
    let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else { return };
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        if sidecar::is_sidecar_of(&name, &file) && !keep.iter().flatten().any(|k| k.as_os_str() == file.as_str()) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// Writes `bytes` to `path` through a temporary sibling file and a rename; with `backup`,
/// an existing file is first preserved as `<path>.bak`.
pub fn write_atomic(path: &Path, bytes: &[u8], backup: bool) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_owned(),
        _ => PathBuf::from("."),
    };
    let name = path
        .file_name()
        .ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "the path names no file"))?;
    let tmp = dir.join(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        if backup && path.exists() {
            let mut bak = path.as_os_str().to_owned();
            bak.push(".bak");
            std::fs::copy(path, PathBuf::from(bak))?;
        }
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Finds the line and column of a field path such as `particles[3].radius` in RON text,
/// falling back to the nearest enclosing field that exists in the text.
pub fn locate_field(text: &str, field: &str) -> Option<(usize, usize)> {
    let positions = field_positions(text);
    let mut path = field.to_string();
    loop {
        if let Some(pos) = positions.iter().find(|(p, _)| *p == path) {
            return Some(pos.1);
        }
        let cut = path.rfind(['.', '['])?;
        path.truncate(cut);
    }
}

/// Every `key:` and list element of a RON document with its path and (line, column).
fn field_positions(text: &str) -> Vec<(String, (usize, usize))> {
    enum Frame {
        Record { prefix: String, key: Option<String> },
        List { prefix: String, index: usize, started: bool },
    }
    fn path_of(stack: &[Frame]) -> String {
        match stack.last() {
            Some(Frame::Record { prefix, key: Some(k) }) => {
                if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                }
            }
            Some(Frame::Record { prefix, key: None }) => prefix.clone(),
            Some(Frame::List { prefix, index, .. }) => format!("{prefix}[{index}]"),
            None => String::new(),
        }
    }
    let mut out = Vec::new();
    let mut stack: Vec<Frame> = Vec::new();
    let chars: Vec<char> = text.chars().collect();
    let (mut line, mut col) = (1usize, 1usize);
    let mut i = 0;
    let advance = |c: char, line: &mut usize, col: &mut usize| {
        if c == '\n' {
            *line += 1;
            *col = 1;
        } else {
            *col += 1;
        }
    };
    while i < chars.len() {
        let c = chars[i];
        if let Some(Frame::List { index, started, prefix }) = stack.last_mut() {
            if !*started && !c.is_whitespace() && c != ']' {
                *started = true;
                out.push((format!("{prefix}[{index}]"), (line, col)));
            }
        }
        match c {
            '/' if chars.get(i + 1) == Some(&'/') => {
                while i < chars.len() && chars[i] != '\n' {
                    i += 1;
                }
                continue;
            }
            '"' => {
                advance(c, &mut line, &mut col);
                i += 1;
                while i < chars.len() && chars[i] != '"' {
                    if chars[i] == '\\' {
                        advance(chars[i], &mut line, &mut col);
                        i += 1;
                    }
                    if i < chars.len() {
                        advance(chars[i], &mut line, &mut col);
                        i += 1;
                    }
                }
            }
            '(' | '{' => {
                let prefix = path_of(&stack);
                stack.push(Frame::Record { prefix, key: None });
            }
            '[' => {
                let prefix = path_of(&stack);
                stack.push(Frame::List { prefix, index: 0, started: false });
            }
            ')' | '}' | ']' => {
                stack.pop();
            }
            ',' => {
                if let Some(Frame::List { index, started, .. }) = stack.last_mut() {
                    *index += 1;
                    *started = false;
                }
            }
            c if c.is_alphabetic() || c == '_' => {
                let start = (line, col);
                let mut j = i;
                while j < chars.len() && (chars[j].is_alphanumeric() || chars[j] == '_') {
                    j += 1;
                }
                let ident: String = chars[i..j].iter().collect();
                let mut k = j;
                while k < chars.len() && chars[k].is_whitespace() {
                    k += 1;
                }
                if chars.get(k) == Some(&':') {
                    if let Some(Frame::Record { key, .. }) = stack.last_mut() {
                        *key = Some(ident);
                        out.push((path_of(&stack), start));
                    }
                }
                for &ch in &chars[i..j] {
                    advance(ch, &mut line, &mut col);
                }
                i = j;
                continue;
            }
            _ => {}
        }
        if i < chars.len() {
            advance(chars[i], &mut line, &mut col);
        }
        i += 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locates_nested_fields() {
        let text = "Project(\n  particles: [\n    (center: (0.0, 1.0, 0.0), radius: 1.0, density: 1.0),\n    (center: (0.0, 1.0, 0.0), radius: -1.0, density: 1.0),\n  ],\n)";
        assert_eq!(locate_field(text, "particles[1].radius"), Some((4, 31)));
        assert_eq!(locate_field(text, "particles[0].center"), Some((3, 6)));
        assert_eq!(locate_field(text, "grid.min"), None);
    }
}

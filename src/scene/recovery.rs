//! Crash recovery files. While a project has unsaved changes the editor writes it here when
//! an edit ends and every few seconds during a long one (atomically, like a save, on a
//! [`RecoveryWriter`]'s thread); a clean save or exit removes the file. At the next
//! start, any file left behind means the editor did not exit cleanly, and it offers to
//! restore the work.
//!
//! Files live in `$FOGSMITH_STATE_DIR`, else `$XDG_STATE_HOME/fogsmith/recovery`, else
//! `~/.local/state/fogsmith/recovery`. Each is named after the project it protects (a hash
//! of its path, or of the process id for an untitled project), so several editors never
//! overwrite each other's. Many particles go to a sidecar beside the file, as in a saved
//! project (see [`sidecar`](super::sidecar)).

use super::io::{remove_stale_sidecars, write_atomic, ProjectError};
use super::sidecar::{self, ParticleFile, SIDECAR_MIN_PARTICLES};
use super::Project;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a recovery file holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Recovery {
    /// The project file the work belongs to; None for an untitled project.
    pub original: Option<PathBuf>,
    /// Seconds since the Unix epoch when it was written.
    pub saved_unix: u64,
    pub project: Project,
}

/// The folder recovery files go to (see the module doc).
pub fn state_dir() -> PathBuf {
    if let Some(dir) = std::env::var_os("FOGSMITH_STATE_DIR") {
        return PathBuf::from(dir);
    }
    let base = std::env::var_os("XDG_STATE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state")))
        .unwrap_or_else(std::env::temp_dir);
    base.join("fogsmith").join("recovery")
}

/// The recovery file for `original` (or for this process's untitled project) in `dir`.
pub fn recovery_path(dir: &Path, original: Option<&Path>) -> PathBuf {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    match original {
        Some(p) => std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf()).hash(&mut h),
        None => ("untitled", std::process::id()).hash(&mut h),
    }
    dir.join(format!("{:016x}.recovery.ron", h.finish()))
}

/// Writes `project` as the recovery file of `original` at `path` (from [`recovery_path`]),
/// creating its folder, atomically.
pub fn write_recovery(path: &Path, original: Option<&Path>, project: &Project) -> Result<(), ProjectError> {
    let io_err = |source| ProjectError::Io { path: path.to_owned(), source };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io_err)?;
    }
    let saved_unix = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let dir = path.parent().unwrap_or(Path::new(""));
    let (project, written) = if project.particles.len() >= SIDECAR_MIN_PARTICLES {
        let (bytes, crc32) = sidecar::encode(&project.particles);
        let file = sidecar::sidecar_name(path, crc32);
        write_atomic(&dir.join(&file), &bytes, false)
            .map_err(|source| ProjectError::Io { path: dir.join(&file), source })?;
        let count = project.particles.len() as u64;
        let head = Project {
            particle_file: Some(ParticleFile { file: file.clone(), count, crc32 }),
            ..project.without_particles()
        };
        (head, Some(file))
    } else {
        (project.clone(), None)
    };
    let rec = Recovery { original: original.map(Path::to_path_buf), saved_unix, project };
    let text = ron::ser::to_string_pretty(&rec, ron::ser::PrettyConfig::new())
        .map_err(|e| ProjectError::Serialize(e.to_string()))?;
    write_atomic(path, text.as_bytes(), false).map_err(io_err)?;
    remove_stale_sidecars(path, dir, [written, None]);
    Ok(())
}

/// Reads the particles of a recovery file's project from its sidecar, if it names one.
fn read_particles(path: &Path, rec: &mut Recovery) -> Result<(), ProjectError> {
    let Some(file) = rec.project.particle_file.take() else { return Ok(()) };
    let at = path.parent().unwrap_or(Path::new("")).join(&file.file);
    let bytes = std::fs::read(&at).map_err(|source| ProjectError::Io { path: at.clone(), source })?;
    rec.project.particles =
        sidecar::decode(&bytes, &file).map_err(|message| ProjectError::Sidecar { path: at.clone(), message })?;
    Ok(())
}

/// Every readable recovery file in `dir` with its path and particles, newest first.
/// Unreadable ones are reported as errors rather than dropped, so nothing is lost silently.
pub fn find_recoveries(dir: &Path) -> Vec<Result<(PathBuf, Recovery), ProjectError>> {
    list_recoveries(dir)
        .into_iter()
        .map(|found| {
            let (path, mut rec) = found?;
            read_particles(&path, &mut rec)?;
            Ok((path, rec))
        })
        .collect()
}

/// [`find_recoveries`] without reading particle sidecars: a project with many particles
/// still names its sidecar (`particle_file`, with the count), so listing what is left is
/// quick however large the work; [`restore_recovery`] reads the rest.
pub fn list_recoveries(dir: &Path) -> Vec<Result<(PathBuf, Recovery), ProjectError>> {
    let Ok(entries) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut out: Vec<Result<(PathBuf, Recovery), ProjectError>> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| p.to_string_lossy().ends_with(".recovery.ron"))
        .map(|path| {
            let text =
                std::fs::read_to_string(&path).map_err(|source| ProjectError::Io { path: path.clone(), source })?;
            let rec: Recovery = ron::from_str(&text).map_err(|e| ProjectError::Syntax {
                path: path.clone(),
                line: e.position.line,
                col: e.position.col,
                message: e.code.to_string(),
            })?;
            Ok((path, rec))
        })
        .collect();
    out.sort_by_key(|r| std::cmp::Reverse(r.as_ref().map_or(0, |(_, rec)| rec.saved_unix)));
    out
}

/// The project of the recovery file at `path`, as [`list_recoveries`] found it: its
/// particles read from the sidecar it names, then checked as every loaded project is
/// (migrated and validated once), telling `progress` each step as a load does.
pub fn restore_recovery(
    path: &Path,
    rec: Recovery,
    progress: &mut dyn FnMut(&str, f64),
) -> Result<Project, ProjectError> {
    progress("reading", 0.0);
    let text = std::fs::read_to_string(path).map_err(|source| ProjectError::Io { path: path.to_owned(), source })?;
    super::io::complete_load(rec.project, &text, path, progress)
}

/// Removes a recovery file once its work is saved or deliberately discarded.
pub fn remove_recovery(path: &Path) -> Result<(), ProjectError> {
    remove_stale_sidecars(path, path.parent().unwrap_or(Path::new("")), [None, None]);
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            Err(ProjectError::Io { path: path.to_owned(), source: e })
        }
        _ => Ok(()),
    }
}

/// A request to the writer thread.
enum Request {
    Write { path: PathBuf, original: Option<PathBuf>, project: Box<Project> },
    Remove(PathBuf),
}

impl Request {
    fn path(&self) -> &Path {
        match self {
            Request::Write { path, .. } | Request::Remove(path) => path,
        }
    }
}

/// Writes and removes recovery files on one background thread, in the order asked, so the
/// UI never waits on the disk. Of several requests for one file waiting together only the
/// last is carried out: a newer state always wins over an older one, and a removal is never
/// undone by a write queued before it.
pub struct RecoveryWriter {
    requests: Option<std::sync::mpsc::Sender<Request>>,
    errors: std::sync::mpsc::Receiver<ProjectError>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Default for RecoveryWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl RecoveryWriter {
    pub fn new() -> Self {
        let (requests, rx) = std::sync::mpsc::channel::<Request>();
        let (error_tx, errors) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("fogsmith-recovery".into())
            .spawn(move || {
                while let Ok(first) = rx.recv() {
                    let mut batch = vec![first];
                    batch.extend(rx.try_iter());
                    let paths: Vec<PathBuf> = batch.iter().map(|r| r.path().to_owned()).collect();
                    for (i, request) in batch.into_iter().enumerate() {
                        if paths[i + 1..].contains(&paths[i]) {
                            continue;
                        }
                        let result = match request {
                            Request::Write { path, original, project } => {
                                write_recovery(&path, original.as_deref(), &project)
                            }
                            Request::Remove(path) => remove_recovery(&path),
                        };
                        if let Err(e) = result {
                            if error_tx.send(e).is_err() {
                                return;
                            }
                        }
                    }
                }
            })
            .ok();
        Self { requests: thread.as_ref().map(|_| requests), errors, thread }
    }

    /// Queues writing `project` as the recovery file of `original` at `path` (from
    /// [`recovery_path`]).
    pub fn write(&self, path: &Path, original: Option<&Path>, project: Project) -> Result<(), ProjectError> {
        self.send(Request::Write {
            path: path.to_owned(),
            original: original.map(Path::to_owned),
            project: Box::new(project),
        })
    }

    /// Queues removing the recovery file at `path`.
    pub fn remove(&self, path: &Path) -> Result<(), ProjectError> {
        self.send(Request::Remove(path.to_owned()))
    }

    fn send(&self, request: Request) -> Result<(), ProjectError> {
        let path = request.path().to_owned();
        let stopped = || ProjectError::Io {
            path: path.clone(),
            source: std::io::Error::other("the recovery writer thread could not be started or has stopped"),
        };
        self.requests.as_ref().ok_or_else(stopped)?.send(request).map_err(|_| stopped())
    }

    /// Errors of requests carried out since the last call.
    pub fn errors(&self) -> Vec<ProjectError> {
        self.errors.try_iter().collect()
    }

    /// Carries out every queued request, then stops the thread (also done on drop).
    pub fn finish(&mut self) {
        self.requests = None;
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

impl Drop for RecoveryWriter {
    fn drop(&mut self) {
        self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Particle;
    use glam::Vec3;

    #[test]
    fn many_particles_recover_through_a_sidecar() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = Project {
            particles: (0..SIDECAR_MIN_PARTICLES)
                .map(|i| Particle::new(Vec3::splat(i as f32 * 1e-4), 0.5, 2.0))
                .collect(),
            ..Project::default()
        };
        p.ensure_unique_ids();
        let path = recovery_path(dir.path(), None);
        write_recovery(&path, None, &p).unwrap();
        p.particles[7].radius = 0.25;
        write_recovery(&path, None, &p).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2, "the file and its newest sidecar");
        assert_eq!(find_recoveries(dir.path())[0].as_ref().unwrap().1.project, p);
        // Listed quickly, with the particles left in the sidecar, then restored with the
        // steps of a load.
        let (listed, rec) = list_recoveries(dir.path()).pop().unwrap().unwrap();
        assert!(rec.project.particles.is_empty());
        assert_eq!(rec.project.particle_file.as_ref().map(|f| f.count), Some(SIDECAR_MIN_PARTICLES as u64));
        let mut steps = Vec::new();
        let restored = restore_recovery(&listed, rec, &mut |step, _| steps.push(step.to_owned())).unwrap();
        assert_eq!(restored, p);
        assert_eq!(steps, ["reading", "reading particles", "validating"]);
        remove_recovery(&path).unwrap();
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0, "both go");
    }

    #[test]
    fn write_find_remove() {
        let dir = tempfile::tempdir().unwrap();
        let mut p = Project::default();
        p.particles.push(Particle::new(Vec3::ONE, 0.5, 2.0));
        let original = dir.path().join("fog.ron");
        let path = recovery_path(dir.path(), Some(&original));
        write_recovery(&path, Some(&original), &p).unwrap();
        let found = find_recoveries(dir.path());
        assert_eq!(found.len(), 1);
        let (fp, rec) = found[0].as_ref().unwrap();
        assert_eq!(fp, &path);
        assert_eq!(rec.project, p);
        assert_eq!(rec.original.as_deref(), Some(original.as_path()));
        remove_recovery(&path).unwrap();
        assert!(find_recoveries(dir.path()).is_empty());
        std::fs::write(dir.path().join("bad.recovery.ron"), "not ron").unwrap();
        assert!(find_recoveries(dir.path())[0].is_err(), "a damaged file is reported, not dropped");
    }

    /// The writer carries out requests in order: the newest state of a file wins, and a
    /// removal queued after writes leaves no file.
    #[test]
    fn writer_keeps_the_newest_state_and_honours_removal() {
        let dir = tempfile::tempdir().unwrap();
        let original = dir.path().join("fog.ron");
        let mut writer = RecoveryWriter::new();
        let mut p = Project::default();
        for i in 0..20 {
            p.particles.push(Particle::new(Vec3::splat(i as f32), 0.5, 2.0));
            writer.write(&recovery_path(dir.path(), Some(&original)), Some(&original), p.clone()).unwrap();
        }
        writer.finish();
        let found = find_recoveries(dir.path());
        assert_eq!(found.len(), 1);
        assert_eq!(found[0].as_ref().unwrap().1.project, p, "the last state queued is the one on disk");
        let path = found[0].as_ref().unwrap().0.clone();

        let mut writer = RecoveryWriter::new();
        writer.write(&recovery_path(dir.path(), Some(&original)), Some(&original), Project::default()).unwrap();
        writer.remove(&path).unwrap();
        writer.finish();
        assert!(find_recoveries(dir.path()).is_empty(), "a removal after a write leaves no file");

        let blocked = dir.path().join("a-file");
        std::fs::write(&blocked, "").unwrap();
        let mut writer = RecoveryWriter::new();
        writer.write(&recovery_path(&blocked, Some(&original)), Some(&original), p).unwrap();
        writer.finish();
        let errors = writer.errors();
        assert_eq!(errors.len(), 1, "a failed write is reported: {errors:?}");
    }
}

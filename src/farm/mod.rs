//! Render-farm jobs: a frame sequence split into chunks that a scheduler runs as independent
//! tasks, written in the schedulers' own formats ([`openjd`]: Open Job Description, which
//! AWS Deadline Cloud runs; [`slurm`]: a Slurm job array). Fogsmith ships no scheduler.
//!
//! A job is a bundle folder: the project, every file it references (under `assets/`), the
//! job files and `farm.json`, the description `fogsmith farm status` reads. Every path in it
//! is relative to the bundle, so the bundle runs wherever it is copied. Each task is one
//! `fogsmith export --frames A-B … --resume` command line, which a user can also run by hand:
//! it skips the frames whose files are complete ([`check`]) and bakes the rest, so a failed
//! or preempted task is simply run again. A last step writes the sequence's USD stage.

pub mod check;
pub mod openjd;
pub mod slurm;

use crate::export::sequence::{FramePattern, FrameSet};
use crate::scene::Project;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The extensions of each frame's files: the grids and the linear render.
pub const FRAME_FILES: [&str; 2] = ["vdb", "exr"];

/// The manifest file in every bundle.
pub const MANIFEST: &str = "farm.json";

/// A frame sequence split into tasks. Paths are relative to the bundle.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct FarmJob {
    /// A name for the scheduler's queue: the project's file stem.
    pub name: String,
    /// The project file, inside the bundle.
    pub project: String,
    /// The frames, as `--frames` takes them.
    pub frames: String,
    /// Frames per task.
    pub chunk: u32,
    /// Each frame's files without extension, with a frame number: `out/fog.####`.
    pub output: String,
    /// The sequence's USD stage.
    pub stage: String,
    /// The memory one task needs, in MiB (see [`task_memory_mib`]).
    pub memory_mib: u64,
    /// CPU cores per task.
    pub cpus: u32,
}

impl FarmJob {
    /// The frames of the job.
    pub fn frame_set(&self) -> Result<FrameSet, String> {
        FrameSet::parse(&self.frames).map_err(|e| e.0)
    }

    /// The `--frames` value of each task: `chunk` frames each, in order, written as ranges.
    pub fn chunks(&self) -> Result<Vec<String>, String> {
        let set = self.frame_set()?;
        Ok(set.frames().chunks(self.chunk.max(1) as usize).map(ranges_text).collect())
    }

    /// The file of `frame` with `ext`.
    pub fn frame_file(&self, frame: i32, ext: &str) -> PathBuf {
        FramePattern::new(Path::new(&format!("{}.{ext}", self.output))).path(frame)
    }

    /// A task's arguments after the executable: bake `frames`, skipping complete ones.
    pub fn task_args(&self, frames: &str) -> Vec<String> {
        let mut args = vec!["export".into(), self.project.clone(), "--frames".into(), frames.into()];
        for (flag, ext) in [("--vdb", "vdb"), ("--exr-render", "exr")] {
            args.extend([flag.to_string(), format!("{}.{ext}", self.output)]);
        }
        args.extend(["--resume".into(), "--quiet".into()]);
        args
    }

    /// The last step's arguments: every frame's VDB is complete, so this only writes the stage.
    pub fn stage_args(&self, frames: &str) -> Vec<String> {
        let mut args = vec!["export".into(), self.project.clone(), "--frames".into(), frames.into()];
        args.extend(["--vdb".into(), format!("{}.vdb", self.output), "--usd".into(), self.stage.clone()]);
        args.extend(["--resume".into(), "--quiet".into()]);
        args
    }

    /// The folders the outputs go into, relative to the bundle.
    pub fn output_dirs(&self) -> Vec<PathBuf> {
        let mut dirs: Vec<PathBuf> = [Path::new(&self.output), Path::new(&self.stage)]
            .iter()
            .filter_map(|p| p.parent())
            .filter(|d| !d.as_os_str().is_empty())
            .map(Path::to_path_buf)
            .collect();
        dirs.dedup();
        dirs
    }
}

/// `1,2,3,5,7,8` → `1-3,5,7-8`.
pub fn ranges_text(frames: &[i32]) -> String {
    let mut parts = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let mut j = i;
        while j + 1 < frames.len() && frames[j + 1] == frames[j] + 1 {
            j += 1;
        }
        parts.push(if i == j { frames[i].to_string() } else { format!("{}-{}", frames[i], frames[j]) });
        i = j + 1;
    }
    parts.join(",")
}

/// The stage beside a frame pattern: `out/fog.####` → `out/fog.usda`.
pub fn stage_for(output: &str) -> String {
    let mut text = output.to_string();
    for token in frame_tokens(output) {
        text = text.replacen(&token, "", 1);
    }
    let trimmed = text.trim_end_matches(['.', '_', '-']);
    let name = if trimmed.is_empty() || trimmed.ends_with('/') { format!("{trimmed}sequence") } else { trimmed.into() };
    format!("{}.usda", name.replace("//", "/").replace("..", ".").replace("__", "_"))
}

/// The frame placeholders of a pattern as written: `####`, `%04d`, `$F4` (the spellings
/// [`FramePattern`] reads).
fn frame_tokens(text: &str) -> Vec<String> {
    let bytes = text.as_bytes();
    let digits = |from: usize| bytes[from.min(bytes.len())..].iter().take_while(|b| b.is_ascii_digit()).count();
    let mut tokens = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        let len = match bytes[i] {
            b'#' => bytes[i..].iter().take_while(|&&b| b == b'#').count(),
            b'%' if bytes.get(i + 1 + digits(i + 1)) == Some(&b'd') => digits(i + 1) + 2,
            b'$' if bytes.get(i + 1) == Some(&b'F') => digits(i + 2) + 2,
            _ => 0,
        };
        if len > 0 {
            tokens.push(text[i..i + len].to_string());
        }
        i += len.max(1);
    }
    tokens
}

/// The host memory one task needs, in MiB: the grids on the adapter (on a CPU adapter they
/// are host memory too), their read-back copies and the grids built for the VDB, the image
/// and its read-back, a quarter more for allocator slack, and a fixed part for the process
/// and the driver.
pub fn task_memory_mib(project: &Project, width: u32, height: u32) -> u64 {
    let cells = project.grid.cell_count();
    let lights = project.lights.len().max(1) as u64;
    let pixels = width as u64 * height as u64;
    let device = cells * 4 * (1 + 3 * lights) + pixels * 56 + project.particles.len() as u64 * 64;
    let host = 2 * cells * 4 * (1 + lights) + pixels * 16;
    let fixed = 512 << 20;
    ((device + host) * 5 / 4 + fixed).div_ceil(1 << 20)
}

/// Single-quotes `s` for a POSIX shell.
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty() && s.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_./=:,+".contains(&b)) {
        return s.to_string();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_become_ranges_and_chunks() {
        assert_eq!(ranges_text(&[1, 2, 3, 5, 7, 8]), "1-3,5,7-8");
        let job = FarmJob {
            name: "fog".into(),
            project: "fog.ron".into(),
            frames: "1-25".into(),
            chunk: 10,
            output: "out/fog.####".into(),
            stage: "out/fog.usda".into(),
            memory_mib: 1024,
            cpus: 4,
        };
        assert_eq!(job.chunks().unwrap(), ["1-10", "11-20", "21-25"]);
        assert_eq!(job.frame_file(7, "vdb"), Path::new("out/fog.0007.vdb"));
    }

    #[test]
    fn the_stage_is_named_after_the_pattern() {
        assert_eq!(stage_for("out/fog.####"), "out/fog.usda");
        assert_eq!(stage_for("out/fog_%04d"), "out/fog.usda");
        assert_eq!(stage_for("cache/$F4/fog"), "cache/fog.usda");
        assert_eq!(stage_for("out/####"), "out/sequence.usda");
    }

    #[test]
    fn memory_grows_with_cells_times_lights() {
        let mut p = Project::default();
        p.grid.resolution = glam::UVec3::splat(256);
        p.lights = vec![crate::scene::Light::new(glam::Vec3::ONE, 1.0, glam::Vec3::ONE); 8];
        assert_eq!(task_memory_mib(&p, 1920, 1080), 4130);
    }

    #[test]
    fn shell_quoting_keeps_patterns_literal() {
        assert_eq!(shell_quote("out/fog.####.vdb"), "'out/fog.####.vdb'");
        assert_eq!(shell_quote("1-10"), "1-10");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
    }
}

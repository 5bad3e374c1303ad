//! `fogsmith farm`: write a sequence's job for a render farm (Open Job Description bundle or
//! Slurm job array, see [`crate::farm`]) and report which frames of a job exist.
//!
//! Everything a job needs is checked before any job file is written: the chunk size, the
//! frames against the animation, the output pattern, and the files the project references.

use crate::export::sequence::FramePattern;
use crate::farm::check::{file_state, FileState};
use crate::farm::{self, FarmJob, FRAME_FILES, MANIFEST};
use crate::scene::{io::save_project, load_project};
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand)]
pub enum FarmCommand {
    /// Write an Open Job Description bundle (template.yaml, the project and its files) for
    /// AWS Deadline Cloud or `openjd run`.
    Openjd(JobArgs),
    /// Write a Slurm job array (frames.sbatch), its stage job (stage.sbatch) and submit.sh.
    Slurm(JobArgs),
    /// Report which frames of a job are done, missing or damaged.
    Status {
        /// The job's bundle folder.
        bundle: PathBuf,
        /// Print one JSON object on stdout.
        #[arg(long)]
        json: bool,
    },
}

#[derive(clap::Args)]
pub struct JobArgs {
    /// The project file (.ron), animated.
    pub project: PathBuf,
    /// Frames to bake: 1-240, or a list such as 1-10,15.
    #[arg(long, allow_hyphen_values = true)]
    pub frames: String,
    /// Frames per task.
    #[arg(long, default_value_t = 10)]
    pub chunk: u32,
    /// The bundle folder to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Each frame's files inside the bundle, with a frame number (####, %04d or $F4);
    /// .vdb and .exr are appended.
    #[arg(long, default_value = "out/fog.####")]
    pub output: String,
    /// CPU cores per task.
    #[arg(long, default_value_t = 4)]
    pub cpus: u32,
}

pub fn run(command: FarmCommand) -> Result<(), Box<dyn std::error::Error>> {
    match command {
        FarmCommand::Openjd(args) => {
            let job = write_bundle(&args)?;
            let template = args.out.join("template.yaml");
            crate::export::write_text(&template, &farm::openjd::template(&job))?;
            eprintln!(
                "wrote {} ({} tasks of up to {} frames, {} MiB each); submit with: deadline bundle submit {}",
                template.display(),
                job.chunks()?.len(),
                job.chunk,
                job.memory_mib,
                args.out.display()
            );
            Ok(())
        }
        FarmCommand::Slurm(args) => {
            let job = write_bundle(&args)?;
            let files = [
                ("frames.sbatch", farm::slurm::frames_script(&job)?),
                ("stage.sbatch", farm::slurm::stage_script(&job)),
                ("submit.sh", farm::slurm::submit_script(&job)),
            ];
            for (name, text) in &files {
                let path = args.out.join(name);
                crate::export::write_text(&path, text)?;
                #[cfg(unix)]
                {
                    use std::os::unix::fs::PermissionsExt;
                    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))?;
                }
            }
            eprintln!(
                "wrote {} ({} array tasks of up to {} frames, {} CPUs and {} MiB each); submit with: {}",
                args.out.join("frames.sbatch").display(),
                job.chunks()?.len(),
                job.chunk,
                job.cpus,
                job.memory_mib,
                args.out.join("submit.sh").display()
            );
            Ok(())
        }
        FarmCommand::Status { bundle, json } => status(&bundle, json),
    }
}

/// Checks everything, then writes the bundle's project, its files and the manifest.
fn write_bundle(args: &JobArgs) -> Result<FarmJob, Box<dyn std::error::Error>> {
    if args.chunk == 0 {
        return Err("--chunk 0: a task needs at least one frame; give --chunk 1 or more".into());
    }
    if args.cpus == 0 {
        return Err("--cpus 0: a task needs at least one CPU core; give --cpus 1 or more".into());
    }
    let mut project = load_project(&args.project)?;
    let (_, set) = super::frames(&project, &args.project, Some(&args.frames), "--frames")?;
    let set = set.ok_or("--frames names no frame")?;
    let mut output = args.output.clone();
    for ext in FRAME_FILES {
        if let Some(stem) = output.strip_suffix(&format!(".{ext}")) {
            output = stem.to_string();
        }
    }
    if Path::new(&output).is_absolute() || Path::new(&output).components().any(|c| c.as_os_str() == "..") {
        return Err(format!(
            "--output {output}: the outputs go inside the bundle, so the job runs wherever it is copied; \
             give a relative path such as out/fog.####"
        )
        .into());
    }
    FramePattern::new(Path::new(&output)).paths("--output", &set)?;
    let base = match &project.base_volume {
        Some(b) => {
            let dir = args.project.parent().filter(|d| !d.as_os_str().is_empty());
            let path = b.resolved_path(dir);
            if !path.is_file() {
                return Err(format!(
                    "{}: base_volume {} does not exist ({}); restore the file, or remove base_volume from the project",
                    args.project.display(),
                    b.path.display(),
                    path.display()
                )
                .into());
            }
            Some(path)
        }
        None => None,
    };
    let name = args.project.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "fog".into());
    let file = args.project.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene.ron".into());
    let job = FarmJob {
        // Open Job Description limits a job's name; the scheduler's queues show the start.
        name: name
            .chars()
            .take(48)
            .map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' { c } else { '_' })
            .collect(),
        project: file.clone(),
        frames: farm::ranges_text(set.frames()),
        chunk: args.chunk,
        stage: farm::stage_for(&output),
        output,
        memory_mib: farm::task_memory_mib(&project, project.render.width, project.render.height),
        cpus: args.cpus,
    };

    std::fs::create_dir_all(&args.out).map_err(|e| format!("--out {}: {e}", args.out.display()))?;
    for dir in job.output_dirs() {
        std::fs::create_dir_all(args.out.join(dir))?;
    }
    let target = args.out.join(&file);
    match (&base, &mut project.base_volume) {
        (Some(source), Some(volume)) => {
            let asset = Path::new("assets").join(source.file_name().ok_or("base_volume names no file")?);
            std::fs::create_dir_all(args.out.join("assets"))?;
            std::fs::copy(source, args.out.join(&asset))
                .map_err(|e| format!("copying base_volume {}: {e}", source.display()))?;
            volume.path = asset;
            save_project(&target, &project)?;
        }
        // A project with a particle sidecar is saved afresh, which writes its sidecar beside it.
        _ if project.particles.len() >= crate::scene::sidecar::SIDECAR_MIN_PARTICLES => {
            save_project(&target, &project)?
        }
        _ => {
            if std::fs::canonicalize(&args.project).ok() != std::fs::canonicalize(&target).ok() {
                std::fs::copy(&args.project, &target)
                    .map_err(|e| format!("copying {}: {e}", args.project.display()))?;
            }
        }
    }
    crate::export::write_text(&args.out.join(MANIFEST), &serde_json::to_string_pretty(&job)?)?;
    Ok(job)
}

/// The state of each frame of the job in `bundle`, and of its stage.
fn status(bundle: &Path, json: bool) -> Result<(), Box<dyn std::error::Error>> {
    let manifest = bundle.join(MANIFEST);
    let text = std::fs::read_to_string(&manifest).map_err(|e| {
        format!("{}: {e}; give the folder that `fogsmith farm openjd` or `farm slurm` wrote", manifest.display())
    })?;
    let job: FarmJob = serde_json::from_str(&text).map_err(|e| format!("{}: {e}", manifest.display()))?;
    let set = job.frame_set()?;
    let (mut done, mut missing, mut damaged) = (Vec::new(), Vec::new(), Vec::new());
    for &frame in set.frames() {
        let mut problems = Vec::new();
        let mut absent = false;
        for ext in FRAME_FILES {
            let rel = job.frame_file(frame, ext);
            match file_state(&bundle.join(&rel)) {
                FileState::Done => {}
                FileState::Missing => absent = true,
                FileState::Damaged(why) => problems.push(format!("{}: {why}", rel.display())),
            }
        }
        if !problems.is_empty() {
            damaged.push((frame, problems));
        } else if absent {
            missing.push(frame);
        } else {
            done.push(frame);
        }
    }
    let stage = match file_state(&bundle.join(&job.stage)) {
        FileState::Done => "done".to_string(),
        FileState::Missing => "missing".to_string(),
        FileState::Damaged(why) => format!("damaged: {why}"),
    };
    if json {
        let v = serde_json::json!({
            "bundle": bundle,
            "frames": job.frames,
            "done": done,
            "missing": missing,
            "damaged": damaged.iter().map(|(f, why)| serde_json::json!({"frame": f, "files": why})).collect::<Vec<_>>(),
            "stage": stage,
        });
        println!("{v}");
        return Ok(());
    }
    let list = |frames: &[i32]| if frames.is_empty() { "none".to_string() } else { farm::ranges_text(frames) };
    println!(
        "{} frames {}: {} done, {} missing, {} damaged",
        job.name,
        job.frames,
        done.len(),
        missing.len(),
        damaged.len()
    );
    println!("done: {}", list(&done));
    println!("missing: {}", list(&missing));
    for (frame, problems) in &damaged {
        println!("damaged: frame {frame}: {}", problems.join("; "));
    }
    println!("stage {}: {stage}", job.stage);
    if !missing.is_empty() || !damaged.is_empty() {
        println!("rerun the tasks of the missing and damaged frames: each bakes only what is not complete");
    }
    Ok(())
}

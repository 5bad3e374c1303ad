//! The Slurm scripts of a [`FarmJob`](super::FarmJob): `frames.sbatch`, a job array with one
//! array task per chunk; `stage.sbatch`, the USD stage; and `submit.sh`, which submits the
//! array and then the stage as a job that starts only once every array task succeeded
//! (`--dependency=afterok`). Both jobs run in the bundle's folder (`--chdir`), so every path
//! is relative to the bundle; each task logs to `logs/NAME-JOB_TASK.log`.

use super::{shell_quote, FarmJob};

/// The command line of `args`, run by `$FOGSMITH` (default `fogsmith`).
fn command(args: &[String]) -> String {
    let args: Vec<String> = args.iter().map(|a| if a.starts_with('"') { a.clone() } else { shell_quote(a) }).collect();
    format!("exec \"$FOGSMITH\" {}", args.join(" "))
}

fn resources(job: &FarmJob) -> String {
    format!("#SBATCH --cpus-per-task={}\n#SBATCH --mem={}M\n", job.cpus, job.memory_mib)
}

/// `frames.sbatch`: array task k bakes chunk k.
pub fn frames_script(job: &FarmJob) -> Result<String, String> {
    let chunks = job.chunks()?;
    let list = chunks.iter().map(|c| shell_quote(c)).collect::<Vec<_>>().join(" ");
    Ok(format!(
        "#!/bin/bash\n\
         # Bakes frames {frames} of {project}, {chunk} frames per array task (written by fogsmith farm slurm).\n\
         # Submit with ./submit.sh; rerun failed tasks with: sbatch --chdir=\"$PWD\" --array=3,7 frames.sbatch\n\
         #SBATCH --job-name={name}\n\
         #SBATCH --array=0-{last}\n\
         {resources}\
         #SBATCH --output=logs/%x-%A_%a.log\n\
         set -euo pipefail\n\
         CHUNKS=({list})\n\
         FOGSMITH=\"${{FOGSMITH:-fogsmith}}\"\n\
         frames=\"${{CHUNKS[$SLURM_ARRAY_TASK_ID]}}\"\n\
         echo \"array task $SLURM_ARRAY_TASK_ID: frames $frames on $(hostname)\"\n\
         {command}\n",
        frames = job.frames,
        project = job.project,
        chunk = job.chunk,
        name = job.name,
        last = chunks.len() - 1,
        resources = resources(job),
        command = command(&job.task_args("\"$frames\"")),
    ))
}

/// `stage.sbatch`: the sequence's USD stage from the frames' VDBs.
pub fn stage_script(job: &FarmJob) -> String {
    format!(
        "#!/bin/bash\n\
         # Writes the USD stage of frames {frames} of {project} once every frame's VDB exists.\n\
         #SBATCH --job-name={name}-stage\n\
         {resources}\
         #SBATCH --output=logs/%x-%j.log\n\
         set -euo pipefail\n\
         FOGSMITH=\"${{FOGSMITH:-fogsmith}}\"\n\
         {command}\n",
        frames = job.frames,
        project = job.project,
        name = job.name,
        resources = resources(job),
        command = command(&job.stage_args(&job.frames)),
    )
}

/// `submit.sh`: the array, then the stage after it; prints both job ids.
pub fn submit_script(job: &FarmJob) -> String {
    let dirs: Vec<String> = job.output_dirs().iter().map(|d| shell_quote(&d.to_string_lossy())).collect();
    format!(
        "#!/bin/bash\n\
         # Submits the frames of {project} as a Slurm job array and the USD stage as a job after it.\n\
         # Extra arguments go to both sbatch calls (e.g. --partition=render).\n\
         set -euo pipefail\n\
         cd \"$(dirname \"$0\")\"\n\
         mkdir -p logs {dirs}\n\
         array=$(sbatch --parsable --chdir=\"$PWD\" \"$@\" frames.sbatch)\n\
         array=\"${{array%%;*}}\"\n\
         stage=$(sbatch --parsable --chdir=\"$PWD\" --dependency=afterok:\"$array\" \"$@\" stage.sbatch)\n\
         stage=\"${{stage%%;*}}\"\n\
         echo \"frames: job $array; stage: job $stage\"\n",
        project = job.project,
        dirs = dirs.join(" "),
    )
}

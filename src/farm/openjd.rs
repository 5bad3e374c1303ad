//! The Open Job Description template of a [`FarmJob`](super::FarmJob) (specification
//! `jobtemplate-2023-09` with the `TASK_CHUNKING` extension), as AWS Deadline Cloud and
//! `openjd run` read it.
//!
//! Job parameters hold the frames, the chunk size, the output pattern, the stage, the
//! executable and the bundle's folder (a PATH whose default `.` is joined to the template's
//! folder, so the job runs wherever the bundle is). The step `BakeFrames` has one task
//! parameter of type `CHUNK[INT]` over the frames, `ChunkSize` frames per task, contiguous:
//! each task gets its frames as a range (`11-20`) and passes it to `--frames`. `WriteStage`
//! runs once all tasks succeeded.

use super::FarmJob;

/// A YAML double-quoted scalar (JSON string syntax is valid YAML).
fn q(s: &str) -> String {
    serde_json::to_string(s).unwrap_or_default()
}

/// One action's command and arguments, each argument's bundle paths under `BundleDir`.
fn action(args: &[String], paths: &[usize], indent: &str) -> String {
    let mut out = format!("{indent}command: {}\n{indent}args:\n", q("{{Param.Fogsmith}}"));
    for (k, a) in args.iter().enumerate() {
        let value = if paths.contains(&k) { format!("{{{{Param.BundleDir}}}}/{a}") } else { a.clone() };
        out.push_str(&format!("{indent}- {}\n", q(&value)));
    }
    out.push_str(&format!("{indent}cancelation:\n{indent}  mode: NOTIFY_THEN_TERMINATE\n"));
    out
}

/// The template, as YAML text.
pub fn template(job: &FarmJob) -> String {
    let mut task = job.task_args("{{Task.Param.Frame}}");
    // The project and the two outputs are bundle paths: after export, after --vdb, after --exr-render.
    task[5] = "{{Param.OutputPattern}}.vdb".into();
    task[7] = "{{Param.OutputPattern}}.exr".into();
    let mut stage = job.stage_args("{{Param.Frames}}");
    stage[5] = "{{Param.OutputPattern}}.vdb".into();
    stage[7] = "{{Param.StagePath}}".into();
    let memory = job.memory_mib;
    let cpus = job.cpus;
    format!(
        r#"specificationVersion: jobtemplate-2023-09
extensions:
- TASK_CHUNKING
name: {name}
description: {description}
parameterDefinitions:
- name: Frames
  type: STRING
  description: "Frames to bake: a range such as 1-240, or a list such as 1-10,15,20-30."
  default: {frames}
  minLength: 1
- name: ChunkSize
  type: INT
  description: "Frames per task."
  default: {chunk}
  minValue: 1
- name: OutputPattern
  type: STRING
  description: "Each frame's files, relative to the bundle, with a frame number (####, %04d or $F4); .vdb and .exr are appended."
  default: {output}
  minLength: 1
- name: StagePath
  type: STRING
  description: "The sequence's USD stage, relative to the bundle."
  default: {stage_path}
  minLength: 1
- name: Fogsmith
  type: STRING
  description: "The fogsmith executable on the workers (a name on PATH or an absolute path)."
  default: fogsmith
  minLength: 1
- name: BundleDir
  type: PATH
  objectType: DIRECTORY
  dataFlow: INOUT
  description: "The bundle's folder: the project, the files it references and the outputs."
  default: "."
steps:
- name: BakeFrames
  description: "Each task bakes its chunk of frames, skipping frames whose files are complete."
  hostRequirements:
    amounts:
    - name: amount.worker.memory
      min: {memory}
    - name: amount.worker.vcpu
      min: {cpus}
  parameterSpace:
    taskParameterDefinitions:
    - name: Frame
      type: CHUNK[INT]
      range: "{{{{Param.Frames}}}}"
      chunks:
        defaultTaskCount: "{{{{Param.ChunkSize}}}}"
        rangeConstraint: CONTIGUOUS
  script:
    actions:
      onRun:
{task_action}- name: WriteStage
  description: "Writes the sequence's USD stage once every frame's VDB exists."
  dependencies:
  - dependsOn: BakeFrames
  hostRequirements:
    amounts:
    - name: amount.worker.memory
      min: {memory}
  script:
    actions:
      onRun:
{stage_action}"#,
        name = q(&format!("Fogsmith {} frames {{{{Param.Frames}}}}", job.name)),
        description =
            q(&format!("Bakes {} frame by frame with fogsmith export (written by fogsmith farm openjd).", job.project)),
        frames = q(&job.frames),
        chunk = job.chunk,
        output = q(&job.output),
        stage_path = q(&job.stage),
        task_action = action(&task, &[1, 5, 7], "        "),
        stage_action = action(&stage, &[1, 5, 7], "        "),
    )
}

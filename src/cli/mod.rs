//! Command-line interface: the editor (no subcommand), headless rendering, export, render-farm
//! jobs, verification and adapter information.

use crate::export::image::write_image;
use crate::export::sequence::{FramePattern, FrameSet};
use crate::gpu::{FogPipeline, FrameReport, FrameRequest, GpuContext};
use crate::scene::{load_project_with, Project, Scheme};
use clap::{Parser, Subcommand};
use std::ffi::OsString;
use std::path::{Path, PathBuf};

mod export;
mod farm;
pub mod progress;
mod stress;
mod verify;

#[derive(Parser)]
#[command(
    name = "fogsmith",
    version,
    about = "Author, preview and bake volumetric fog.",
    long_about = "Author, preview and bake volumetric fog.\n\nWithout a subcommand, opens the editor on PROJECT (or on the bundled demo).",
    args_conflicts_with_subcommands = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Project to open in the editor (default: the bundled demo).
    project: Option<PathBuf>,
    /// Save a PNG of the editor window once the first preview frame is shown, then exit.
    #[arg(long, value_name = "PNG", hide = true)]
    screenshot: Option<PathBuf>,
    /// Redraw the editor continuously for SECONDS (half still, half orbiting), print the frame rates, then exit.
    #[arg(long, value_name = "SECONDS", hide = true)]
    measure_fps: Option<f32>,
    /// Paint COUNT particles as one stroke right after opening (the crash-recovery test uses
    /// it to have unsaved work without a pointer).
    #[arg(long, value_name = "COUNT", hide = true)]
    scripted_stroke: Option<usize>,
}

#[derive(Subcommand)]
enum Command {
    /// Render a project headlessly to a PNG (tone-mapped) or EXR (linear HDR) image.
    Render {
        #[command(flatten)]
        bake: BakeArgs,
        /// Output image: .png or .exr.
        #[arg(short, long)]
        output: PathBuf,
        /// Print a JSON summary on stdout.
        #[arg(long)]
        json: bool,
    },
    /// Bake a project and export its grids as OpenVDB / OpenEXR and its render as EXR.
    Export(export::ExportArgs),
    /// Compare a project's GPU bake and render against the exact CPU reference.
    Verify {
        project: PathBuf,
        /// Propagation scheme (default: the project's propagation.scheme).
        #[arg(long)]
        scheme: Option<Scheme>,
        /// Width of the compared image; the height follows the project's aspect ratio.
        #[arg(long, default_value_t = 96)]
        width: u32,
        /// Largest number of cells compared per volume; larger grids are sampled.
        #[arg(long, default_value_t = 100_000)]
        cells: usize,
        /// The frame of an animated project to compare (default: its first).
        #[arg(long, allow_hyphen_values = true)]
        frame: Option<i32>,
        /// Print one JSON object on stdout.
        #[arg(long)]
        json: bool,
        /// No progress bar on stderr (bars appear only when stderr is a terminal).
        #[arg(long)]
        quiet: bool,
    },
    /// Run the numerical stress matrix (extreme densities, radii, particle counts, light and
    /// camera placements, grid sizes) and check every result for NaN, range and accuracy.
    Stress {
        /// A reduced matrix that finishes in a few minutes on a software adapter.
        #[arg(long)]
        quick: bool,
        /// Print the results as a JSON list on stdout.
        #[arg(long)]
        json: bool,
        /// No progress bar on stderr (bars appear only when stderr is a terminal).
        #[arg(long)]
        quiet: bool,
    },
    /// Measure run time against error for every scheme, step policy and table layout, and
    /// how update time scales; writes bench.csv, bench.json and PNG plots.
    Bench {
        /// A reduced suite that finishes in about two minutes.
        #[arg(long)]
        quick: bool,
        /// Output folder.
        #[arg(long, default_value = "bench-out")]
        out: PathBuf,
        /// Suites to run (default: all but `interaction`).
        #[arg(long, value_enum, value_delimiter = ',')]
        suite: Vec<crate::bench::Suite>,
        /// Grid resolutions (longest axis) of the propagation suite, e.g. 64,128 (default: the
        /// suite's own list).
        #[arg(long, value_delimiter = ',')]
        resolution: Vec<u32>,
        /// Demo scenes of the propagation and interaction suites, e.g. cornell,street (default:
        /// cornell, cloud and street for propagation, every demo for interaction).
        #[arg(long, value_delimiter = ',')]
        scene: Vec<String>,
        /// Schemes of the propagation suite by their record label, e.g. sweep8,sweep8r,exact
        /// (default: all of giroud, sweep4, sweep4r, sweep8, sweep8r, exact and analytic).
        #[arg(long, value_delimiter = ',')]
        scheme: Vec<String>,
        /// The frame at which the animated demos named by --scene are baked by the suites that
        /// take --scene (default: each one's first frame).
        #[arg(long, allow_hyphen_values = true)]
        frame: Option<i32>,
        /// The image sampling of every suite's marches and of the editor in `interaction`
        /// (default: adaptive); `march` and `sampling` compare both whatever this says.
        #[arg(long, value_name = "SAMPLING")]
        image_sampling: Option<SamplingArg>,
        /// Print the records as JSON on stdout (progress lines go to stderr).
        #[arg(long)]
        json: bool,
        /// No progress bar on stderr (bars appear only when stderr is a terminal).
        #[arg(long)]
        quiet: bool,
    },
    /// Split a sequence into tasks for a render farm: an Open Job Description bundle or a
    /// Slurm job array, and the state of a job's frames.
    Farm {
        #[command(subcommand)]
        command: farm::FarmCommand,
    },
    /// Print the GPU adapter Fogsmith would use, its limits and memory, and with a project
    /// the GPU memory its baked resources use.
    Info {
        /// A project (.ron) to bake, reporting the GPU memory its live resources use.
        project: Option<PathBuf>,
        #[arg(long)]
        json: bool,
    },
}

/// What every command that bakes a project takes.
#[derive(clap::Args)]
pub struct BakeArgs {
    /// The project file (.ron).
    pub project: PathBuf,
    /// Image width in pixels (default: the project's render.width).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height in pixels (default: the project's render.height).
    #[arg(long)]
    pub height: Option<u32>,
    /// Propagation scheme (default: the project's propagation.scheme).
    #[arg(long)]
    pub scheme: Option<Scheme>,
    /// Override propagation.sweep_refine (true or false): `sweep` controls the error of its
    /// interpolations; false is faster and up to a few 1e-2 off in the shadows of particles a
    /// cell or two wide.
    #[arg(long, value_name = "BOOL")]
    pub sweep_refine: Option<bool>,
    /// Override propagation.sweep_tolerance, the largest transmittance error sweep_refine
    /// accepts per interpolation (1e-6..=0.1, default 5e-4).
    #[arg(long, value_name = "TOLERANCE")]
    pub sweep_tolerance: Option<f32>,
    /// How the march chooses its camera rays: `adaptive` (default) marches a lattice of rays
    /// 8 pixels apart, refines it where neighbouring rays disagree or the geometry changes,
    /// and interpolates the rest; `per-pixel` marches every pixel, for comparison.
    #[arg(long, value_name = "SAMPLING")]
    pub image_sampling: Option<SamplingArg>,
    /// The adaptive sampling's tolerance: a cell is interpolated where its corner rays differ
    /// by at most this fraction of their mean radiance plus the image's (0 < t ≤ 1, default
    /// 0.02).
    #[arg(long, value_name = "TOLERANCE")]
    pub image_tolerance: Option<f32>,
    /// Override medium.multiple_scattering: `on` uses the file's settings, or the defaults
    /// (8 orders and the tail, strength 1, 24 coarse cells) where it has none; `off` renders
    /// single scattering only.
    #[arg(long, value_name = "ON|OFF")]
    pub multiple_scattering: Option<Switch>,
    /// Frames of an animated project to bake: 7, 1-120, 1-120x4 (every 4th) or a list such
    /// as 1,5,9-12. With more than one, every output path needs a frame number: ####
    /// (padded to as many digits), %04d or $F4. Without it, an animated project bakes its
    /// first frame.
    #[arg(long, value_name = "FRAMES", allow_hyphen_values = true)]
    pub frames: Option<String>,
    /// No progress bar on stderr (bars appear only when stderr is a terminal).
    #[arg(long)]
    pub quiet: bool,
}

/// An on/off override.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Switch {
    On,
    Off,
}

/// `--image-sampling`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SamplingArg {
    /// One ray per pixel.
    PerPixel,
    /// A refined lattice of rays, the rest interpolated.
    Adaptive,
}

impl BakeArgs {
    /// The image sampling these arguments ask for.
    pub fn image_sampling(&self) -> Result<crate::gpu::ImageSampling, String> {
        sampling_of(self.image_sampling, self.image_tolerance)
    }
}

/// The image sampling of `--image-sampling` and `--image-tolerance`.
pub fn sampling_of(sampling: Option<SamplingArg>, tolerance: Option<f32>) -> Result<crate::gpu::ImageSampling, String> {
    use crate::gpu::ImageSampling;
    if let Some(t) = tolerance {
        if !(t > 0.0 && t <= 1.0) {
            return Err(format!(
                "--image-tolerance must be within 0 < t <= 1 (default {}), got {t}",
                crate::gpu::DEFAULT_SAMPLING_TOLERANCE
            ));
        }
    }
    match (sampling, tolerance) {
        (Some(SamplingArg::PerPixel), Some(_)) => {
            Err("--image-tolerance applies to --image-sampling adaptive, not per-pixel: drop one of them".into())
        }
        (Some(SamplingArg::PerPixel), None) => Ok(ImageSampling::PerPixel),
        (_, Some(tolerance)) => Ok(ImageSampling::Adaptive { tolerance }),
        (_, None) => Ok(ImageSampling::default()),
    }
}

/// A project baked and rendered on the GPU.
pub struct Baked {
    pub project: Project,
    pub pipeline: FogPipeline,
    pub report: FrameReport,
    pub request: FrameRequest,
    pub adapter: String,
}

/// A project loaded (with the command line's overrides) into one GPU pipeline that bakes its
/// frames in turn, reusing whatever a frame leaves unchanged.
pub struct Session {
    /// The project as loaded: animated when it has `animation`.
    pub project: Project,
    pub pipeline: FogPipeline,
    pub request: FrameRequest,
    pub adapter: String,
}

/// Opens the GPU and loads the project and its VDB base layer; nothing is baked yet.
pub fn open(args: &BakeArgs) -> Result<Session, Box<dyn std::error::Error>> {
    let mut bar = progress::Bar::new(args.quiet);
    let mut project =
        load_project_with(&args.project, &mut |step, fraction| bar.stage(&format!("load: {step}"), fraction))?;
    bar.finish();
    if let Some(refine) = args.sweep_refine {
        project.propagation.sweep_refine = refine;
    }
    if let Some(tolerance) = args.sweep_tolerance {
        let (range, default) = (crate::scene::SWEEP_TOLERANCE_RANGE, crate::scene::DEFAULT_SWEEP_TOLERANCE);
        if !range.contains(&tolerance) {
            return Err(format!(
                "--sweep-tolerance must be within {:e}..={} (default {default:e}), got {tolerance}",
                range.start(),
                range.end()
            )
            .into());
        }
        project.propagation.sweep_tolerance = tolerance;
    }
    match args.multiple_scattering {
        Some(Switch::On) => {
            project.medium.multiple_scattering.get_or_insert_with(Default::default);
        }
        Some(Switch::Off) => project.medium.multiple_scattering = None,
        None => {}
    }
    let mut request = FrameRequest::for_project(&project);
    request.width = args.width.unwrap_or(request.width);
    request.height = args.height.unwrap_or(request.height);
    request.scheme = args.scheme.unwrap_or(request.scheme);
    for (name, v) in [("--width", request.width), ("--height", request.height)] {
        if v == 0 || v > 16384 {
            return Err(format!("{name} must be within 1..=16384, got {v}").into());
        }
    }
    if let Some(note) = project.medium.noise.and_then(|n| n.nyquist_note(&project.grid)) {
        eprintln!("warning: medium.noise: {note}");
    }
    let sampling = args.image_sampling()?;
    let ctx = GpuContext::new_headless()?;
    let adapter = ctx.adapter_summary();
    let mut pipeline = FogPipeline::new(ctx);
    pipeline.set_image_sampling(sampling);
    // Before the base layer is resampled and uploaded: it is as large as one light's OPV.
    pipeline.check_limits(&project, request.width, request.height)?;
    let layer = crate::export::load_base_layer(&project, Some(&args.project))?;
    pipeline.set_base_layer(layer);
    Ok(Session { project, pipeline, request, adapter })
}

impl Session {
    /// Bakes and renders `still` (a frame of the project, see [`frames`]), reusing what the
    /// previous call left unchanged. `on_progress` sees the work and may stop it.
    pub fn bake(
        &mut self,
        still: &Project,
        on_progress: &mut dyn FnMut(&crate::gpu::Progress) -> bool,
    ) -> Result<FrameReport, Box<dyn std::error::Error>> {
        match self.pipeline.update_with(still, &self.request, std::time::Duration::from_millis(100), on_progress) {
            Err(crate::gpu::GpuError::Cancelled) => Err(progress::Cancelled.into()),
            other => Ok(other?),
        }
    }
}

/// The frames a command bakes, in order (`None`: a project without animation), and the
/// `--frames` list they came from.
pub type Frames = (Vec<Option<i32>>, Option<FrameSet>);

/// The frames a command bakes: with `--frames`, those of the list (the project must be
/// animated and hold them); without, the first frame of an animated project or the still.
pub fn frames(
    project: &Project,
    path: &Path,
    spec: Option<&str>,
    flag: &str,
) -> Result<Frames, Box<dyn std::error::Error>> {
    let Some(spec) = spec else {
        return Ok((vec![project.animation.map(|a| a.start)], None));
    };
    let set = FrameSet::parse(spec).map_err(|e| e.0.replace("--frames", flag))?;
    let Some(animation) = project.animation else {
        return Err(format!(
            "{flag} {set}: {} has no animation. Add a frame range to the project, e.g. \
             `animation: Some((fps: 24.0, start: 1, end: 120)),` with keyframe `tracks`, or leave out {flag}",
            path.display()
        )
        .into());
    };
    set.check_within(animation.start, animation.end).map_err(|e| e.0.replace("--frames", flag))?;
    Ok((set.frames().iter().map(|&f| Some(f)).collect(), Some(set)))
}

/// The still project of `frame` (`None`: the project itself).
pub fn still(project: &Project, frame: Option<i32>) -> Project {
    frame.map_or_else(|| project.clone(), |f| project.at_frame(f))
}

/// Loads the project and bakes it whole (its first frame when animated).
pub fn bake(args: &BakeArgs) -> Result<Baked, Box<dyn std::error::Error>> {
    let mut session = open(args)?;
    let (frames, _) = frames(&session.project, &args.project, args.frames.as_deref(), "--frames")?;
    if frames.len() > 1 {
        return Err("this command bakes one frame: give a single frame".into());
    }
    let project = still(&session.project, frames[0]);
    let mut bar = progress::Bar::new(args.quiet);
    let report = session.bake(&project, &mut |p| bar.pipeline(p))?;
    bar.finish();
    let Session { pipeline, request, adapter, .. } = session;
    Ok(Baked { project, pipeline, report, request, adapter })
}

/// Mesa's Vulkan drivers warn on every start when XDG_RUNTIME_DIR is unset (as under CI or
/// sudo): point it at a private directory. Call before any thread is started.
pub fn ensure_runtime_dir() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("fogsmith-runtime-{}", user_tag()));
    if std::fs::create_dir_all(&dir).is_ok() {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
        }
        std::env::set_var("XDG_RUNTIME_DIR", &dir);
    }
}

/// The user name or id, to keep per-user runtime directories apart.
fn user_tag() -> String {
    std::env::var("USER").or_else(|_| std::env::var("UID")).unwrap_or_else(|_| "user".into())
}

/// Runs the CLI with `args` (including the program name).
pub fn run(args: Vec<OsString>) -> Result<(), Box<dyn std::error::Error>> {
    let cli = Cli::parse_from(args);
    // The commands that bake stop cleanly at the next work item; the others end at once.
    if matches!(cli.command, Some(Command::Render { .. } | Command::Export(_) | Command::Verify { .. })) {
        progress::catch_interrupt();
    }
    match cli.command {
        None => {
            let scripted = cli.screenshot.is_some() || cli.measure_fps.is_some();
            let options = crate::editor::EditorOptions {
                screenshot: cli.screenshot,
                measure_fps: cli.measure_fps,
                recovery: !scripted,
                scripted_stroke: cli.scripted_stroke,
                state_dir: None,
                file_dialogs: None,
            };
            crate::editor::run(cli.project, options)?;
            Ok(())
        }
        Some(Command::Info { project, json }) => info(project.as_deref(), json),
        Some(Command::Verify { project, scheme, width, cells, frame, json, quiet }) => {
            verify::run(&project, scheme, width, cells, frame, json, quiet)
        }
        Some(Command::Render { bake, output, json }) => render(&bake, &output, json),
        Some(Command::Export(args)) => export::run(args),
        Some(Command::Farm { command }) => farm::run(command),
        Some(Command::Stress { quick, json, quiet }) => stress::run(quick, json, quiet),
        Some(Command::Bench { quick, out, suite, resolution, scene, scheme, frame, image_sampling, json, quiet }) => {
            if let Some(bad) = resolution.iter().find(|&&r| r == 0 || r > 1024) {
                return Err(format!("--resolution must be within 1..=1024, got {bad}").into());
            }
            use crate::bench::Suite;
            let suites = if suite.is_empty() {
                vec![Suite::Opv, Suite::March, Suite::Sun, Suite::Scaling, Suite::Kinds]
            } else {
                suite
            };
            let started = std::time::Instant::now();
            let mut bar = progress::Bar::new(quiet);
            let mut lines = 0usize;
            let options = crate::bench::BenchOptions {
                quick,
                out: out.clone(),
                suites,
                resolutions: resolution,
                scenes: scene,
                schemes: scheme,
                frame,
                image_sampling: sampling_of(image_sampling, None)?,
            };
            let records = crate::bench::run(&options, &mut |line| {
                // The suites do not know their length ahead: the bar counts measurements.
                lines += 1;
                let name = line.split_whitespace().next().unwrap_or("bench").to_string();
                bar.stage(&format!("bench {name}"), 1.0 - 1.0 / (1.0 + lines as f64 / 20.0));
                bar.suspend(|| if json { eprintln!("{line}") } else { println!("{line}") });
            })?;
            bar.finish();
            if json {
                println!("{}", serde_json::to_string_pretty(&records)?);
                return Ok(());
            }
            println!(
                "{} records in {:.0} s; wrote {}/bench.json, bench.csv and *.png",
                records.len(),
                started.elapsed().as_secs_f64(),
                out.display()
            );
            Ok(())
        }
    }
}

fn info(project: Option<&Path>, json: bool) -> Result<(), Box<dyn std::error::Error>> {
    let ctx = GpuContext::new_headless()?;
    let l = ctx.limits.clone();
    let opv = crate::gpu::OpvLayout::for_limits(&l);
    let device_memory = ctx.memory_bytes();
    // The GPU memory of a freshly created pipeline, or of one that baked `project`.
    let baked = match project {
        Some(path) => {
            let args = BakeArgs {
                project: path.to_path_buf(),
                width: None,
                height: None,
                scheme: None,
                sweep_refine: None,
                sweep_tolerance: None,
                image_sampling: None,
                image_tolerance: None,
                multiple_scattering: None,
                frames: None,
                quiet: true,
            };
            let b = bake(&args)?;
            Some((b.pipeline.memory_bytes(), b.pipeline.peak_memory_bytes()))
        }
        None => None,
    };
    let live = match baked {
        Some((live, _)) => live,
        None => crate::gpu::FogPipeline::new(ctx.clone()).memory_bytes(),
    };
    let human = crate::gpu::human_bytes;
    if json {
        let v = serde_json::json!({
            "adapter": ctx.adapter_info.name,
            "backend": format!("{:?}", ctx.adapter_info.backend),
            "device_type": format!("{:?}", ctx.adapter_info.device_type),
            "driver": ctx.adapter_info.driver,
            "driver_info": ctx.adapter_info.driver_info,
            "timestamp_queries": ctx.supports_timestamps(),
            "limits": {
                "max_texture_dimension_3d": l.max_texture_dimension_3d,
                "max_texture_dimension_2d": l.max_texture_dimension_2d,
                "max_storage_buffer_binding_size": l.max_storage_buffer_binding_size,
                "max_buffer_size": l.max_buffer_size,
                "max_storage_buffers_per_shader_stage": l.max_storage_buffers_per_shader_stage,
                "max_storage_textures_per_shader_stage": l.max_storage_textures_per_shader_stage,
                "max_sampled_textures_per_shader_stage": l.max_sampled_textures_per_shader_stage,
            },
            "device_memory_bytes": device_memory,
            "opv_textures": opv.textures,
            "opv_lights_per_texture_128": opv.per_texture(glam::UVec3::splat(128)),
            "opv_lights_128": opv.capacity_lights(glam::UVec3::splat(128)),
            "project": project,
            "gpu_memory_bytes": live,
            "gpu_memory_peak_bytes": baked.map(|b| b.1),
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("adapter: {}", ctx.adapter_summary());
        println!("driver: {} {}", ctx.adapter_info.driver, ctx.adapter_info.driver_info);
        println!("timestamp queries: {}", ctx.supports_timestamps());
        println!("max 3D texture edge: {}", l.max_texture_dimension_3d);
        println!("max 2D texture edge: {}", l.max_texture_dimension_2d);
        println!("max storage buffer binding: {} bytes", l.max_storage_buffer_binding_size);
        println!("max buffer: {} bytes", l.max_buffer_size);
        println!("max storage buffers per shader stage: {}", l.max_storage_buffers_per_shader_stage);
        println!(
            "max storage / sampled textures per shader stage: {} / {}",
            l.max_storage_textures_per_shader_stage, l.max_sampled_textures_per_shader_stage
        );
        match device_memory {
            Some(m) => println!("device memory: {} (host RAM of a CPU adapter)", human(m)),
            None => println!("device memory: not reported by the driver"),
        }
        println!(
            "optical-depth storage: {} textures per array, {} lights each at 128³ ({} lights in all; larger grids hold fewer, up to the device's memory)",
            opv.textures,
            opv.per_texture(glam::UVec3::splat(128)),
            opv.capacity_lights(glam::UVec3::splat(128))
        );
        match (project, baked) {
            (Some(p), Some((live, peak))) => {
                println!("GPU memory of {} baked: {} live, {} at peak", p.display(), human(live), human(peak))
            }
            _ => println!("GPU memory of the pipeline with no scene: {}", human(live)),
        }
    }
    Ok(())
}

fn render(args: &BakeArgs, output: &Path, json: bool) -> Result<(), Box<dyn std::error::Error>> {
    let ext = output.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("png" | "exr")) {
        return Err(crate::export::image::OutputError::Format { path: output.to_path_buf() }.into());
    }
    let mut session = open(args)?;
    let (frames, set) = frames(&session.project, &args.project, args.frames.as_deref(), "--frames")?;
    let outputs = match &set {
        Some(set) => FramePattern::new(output).paths("-o", set)?,
        None => vec![output.to_path_buf()],
    };
    let mut bar = progress::Bar::new(args.quiet);
    let mut records = Vec::new();
    for (k, (&frame, path)) in frames.iter().zip(&outputs).enumerate() {
        let project = still(&session.project, frame);
        let started = std::time::Instant::now();
        bar.frame(k, frames.len(), frame);
        let report = session.bake(&project, &mut |p| bar.pipeline(p))?;
        let image = session.pipeline.read_image()?;
        progress::check()?;
        write_image(path, &image, project.render.exposure)?;
        let seconds = started.elapsed().as_secs_f64();
        if set.is_some() && !json {
            bar.suspend(|| {
                eprintln!(
                    "frame {} ({}/{}): wrote {} in {seconds:.2} s",
                    frame.unwrap_or(0),
                    k + 1,
                    frames.len(),
                    path.display()
                )
            });
        }
        records.push((frame, path.clone(), report, seconds, project));
    }
    bar.finish();
    let request = session.request;
    let adapter = &session.adapter;
    let pipeline = &session.pipeline;
    if set.is_some() {
        if json {
            let list: Vec<_> = records
                .iter()
                .map(|(frame, path, report, seconds, _)| {
                    serde_json::json!({
                        "frame": frame,
                        "output": path,
                        "seconds": seconds,
                        "timings_ms": report.timings_ms,
                        "counters": report.counters,
                    })
                })
                .collect();
            let v = serde_json::json!({
                "project": args.project,
                "width": request.width,
                "height": request.height,
                "scheme": request.scheme.to_string(),
                "fps": session.project.animation.map(|a| a.fps),
                "frames": list,
                "adapter": adapter,
                "timing_source": if records.first().is_some_and(|r| r.2.gpu_timestamps) { "gpu_timestamps" } else { "wall_clock" },
            });
            println!("{}", serde_json::to_string(&v)?);
        } else {
            let total: f64 = records.iter().map(|r| r.3).sum();
            eprintln!(
                "rendered {} frames ({}×{}) on {adapter} in {total:.1} s",
                records.len(),
                request.width,
                request.height
            );
        }
        return Ok(());
    }
    let Some((_, _, report, _, project)) = records.pop() else { return Ok(()) };
    if json {
        let v = serde_json::json!({
            "project": args.project,
            "output": output,
            "width": request.width,
            "height": request.height,
            "lights": project.lights.len(),
            "particles": project.particles.len(),
            "grid": project.grid.resolution.to_array(),
            "scheme": request.scheme.to_string(),
            "sweep_refine": project.propagation.sweep_refine,
            "sweep_tolerance": project.propagation.sweep_tolerance,
            "image_sampling": pipeline.image_sampling().name(),
            "rays_marched": report.counters.rays_marched,
            "timings_ms": report.timings_ms,
            "timing_source": if report.gpu_timestamps { "gpu_timestamps" } else { "wall_clock" },
            "counters": report.counters,
            "adapter": adapter,
            "gpu_memory_bytes": pipeline.memory_bytes(),
            "gpu_memory_peak_bytes": pipeline.peak_memory_bytes(),
        });
        println!("{}", serde_json::to_string(&v)?);
    } else {
        let t = report.timings_ms;
        let scatter =
            if t.scatter > 0.0 { format!(", multiple scattering {:.1} ms", t.scatter) } else { String::new() };
        eprintln!(
            "rendered {} ({}×{}) on {adapter}: inject {:.1} ms, propagate {:.1} ms{scatter}, march {:.1} ms",
            output.display(),
            request.width,
            request.height,
            t.inject,
            t.propagate,
            t.march
        );
    }
    Ok(())
}

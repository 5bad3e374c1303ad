//! Loads a Fogsmith export in Bevy, as a game would, renders one frame and saves it as PNG.
//!
//! - `--density NAME.ktx2`: the extinction texture in Bevy's own `FogVolume`, placed by the
//!   `NAME.fogvolume.ron` beside it, lit by the project's lights through `VolumetricFog` and
//!   `VolumetricLight`.
//! - `--baked NAME.ktx2`: the light bake (emission RGB, extinction A) through
//!   [`baked::BakedFogMaterial`] on a cube spanning the grid box named in the texture.
//!
//! The camera, lights and image size come from the project file (`--project`), since the
//! texture and its sidecar hold only the fog. The image is linear radiance times the
//! exposure, sRGB-encoded with no tone curve (values above 1 clip), so it can be compared
//! with `fogsmith render`'s linear EXR.

mod baked;
mod export;

use bevy::asset::{AssetPlugin, LoadState};
use bevy::camera::{Exposure, Hdr};
use bevy::core_pipeline::tonemapping::{DebandDither, Tonemapping};
use bevy::image::ImageLoaderSettings;
use bevy::light::{FogVolume, VolumetricFog, VolumetricLight};
use bevy::log::{error, info};
use bevy::prelude::*;
use bevy::render::settings::{Backends, WgpuSettings};
use bevy::render::view::screenshot::{Screenshot, ScreenshotCaptured};
use bevy::render::RenderPlugin;
use bevy::window::{ExitCondition, WindowResolution};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

const USAGE: &str = "\
usage: fogsmith-bevy-viewer (--density NAME.ktx2 | --baked NAME.ktx2) --project PROJECT.ron --out SHOT.png
                            [--width W] [--height H] [--exposure E] [--background L]
                            [--fog-steps N] [--steps-per-cell N]

  --density FILE      a density texture (`fogsmith export --ktx2`), shown in Bevy's FogVolume
  --baked FILE        a light bake (`fogsmith export --bake-light --ktx2`), shown as emission
                      and absorption by the viewer's material
  --project FILE      the project exported: its camera, lights, render size and exposure
  --out FILE          the PNG to write; the viewer exits once it is written
  --width, --height   image size (default: the project's render size)
  --exposure E        factor on linear radiance before sRGB encoding (default: the project's)
  --background L      linear grey behind the fog (default 0): with the fog's own light
                      exposed away, the image is L times the fog's transmittance
  --fog-steps N       ray-march steps of Bevy's volumetric fog (default 256)
  --steps-per-cell N  steps per smallest cell of the bake's march (default 8, as Fogsmith)";

/// What the command line asks for.
#[derive(Clone, Debug)]
struct Args {
    mode: Mode,
    texture: PathBuf,
    project: PathBuf,
    out: PathBuf,
    width: Option<u32>,
    height: Option<u32>,
    exposure: Option<f32>,
    background: f32,
    fog_steps: u32,
    steps_per_cell: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Density,
    Baked,
}

fn parse_args(mut it: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut mode = None;
    let (mut project, mut out) = (None, None);
    let (mut width, mut height, mut exposure) = (None, None, None);
    let (mut fog_steps, mut steps_per_cell, mut background): (u32, f32, f32) = (256, 8.0, 0.0);
    while let Some(flag) = it.next() {
        if flag == "--help" || flag == "-h" {
            return Err(String::new());
        }
        let mut value = || it.next().ok_or_else(|| format!("{flag} needs a value"));
        fn number<T: std::str::FromStr>(flag: &str, v: String) -> Result<T, String> {
            v.parse().map_err(|_| format!("{flag}: {v:?} is not a valid number"))
        }
        match flag.as_str() {
            "--density" => mode = Some((Mode::Density, PathBuf::from(value()?))),
            "--baked" => mode = Some((Mode::Baked, PathBuf::from(value()?))),
            "--project" => project = Some(PathBuf::from(value()?)),
            "--out" => out = Some(PathBuf::from(value()?)),
            "--width" => width = Some(number(&flag, value()?)?),
            "--height" => height = Some(number(&flag, value()?)?),
            "--exposure" => exposure = Some(number(&flag, value()?)?),
            "--background" => background = number(&flag, value()?)?,
            "--fog-steps" => fog_steps = number(&flag, value()?)?,
            "--steps-per-cell" => steps_per_cell = number(&flag, value()?)?,
            _ => return Err(format!("unknown argument {flag:?}")),
        }
    }
    let (mode, texture) = mode.ok_or("give --density or --baked")?;
    let project = project.ok_or("give --project: the project whose camera and lights to use")?;
    let out = out.ok_or("give --out: the PNG to write")?;
    if width == Some(0) || height == Some(0) || fog_steps == 0 || steps_per_cell.is_nan() || steps_per_cell < 1.0 {
        return Err("sizes and step counts must be positive".into());
    }
    if exposure.is_some_and(|e: f32| !(e > 0.0 && e.is_finite())) {
        return Err("--exposure must be positive".into());
    }
    if !(0.0..=1.0).contains(&background) {
        return Err("--background must be within 0..=1".into());
    }
    Ok(Args { mode, texture, project, out, width, height, exposure, background, fog_steps, steps_per_cell })
}

/// Everything read from the files, checked before the window opens.
#[derive(Resource, Clone)]
struct Scene {
    args: Args,
    project: export::Project,
    ktx2: export::Ktx2Info,
    fog_volume: Option<export::FogVolumeFile>,
    bake: Option<export::BakeScales>,
    size: (u32, u32),
    exposure: f32,
}

fn load_scene(args: Args) -> Result<Scene, String> {
    let project = export::read_project(&args.project).map_err(|e| e.to_string())?;
    let ktx2 = export::read_ktx2(&args.texture).map_err(|e| e.to_string())?;
    let path = args.texture.display();
    let (fog_volume, bake) = match (args.mode, ktx2.format) {
        (Mode::Density, export::TexelFormat::Rgba16Float) => {
            return Err(format!("{path}: this is a light bake (RGBA16F); view it with --baked"))
        }
        (Mode::Baked, export::TexelFormat::R16Float | export::TexelFormat::R8Unorm) => {
            return Err(format!(
                "{path}: this is a density texture, not a light bake; view it with --density, or \
                 export the bake with `fogsmith export --bake-light --ktx2`"
            ))
        }
        (Mode::Density, _) => (Some(export::read_fog_volume(&args.texture).map_err(|e| e.to_string())?), None),
        (Mode::Baked, _) => (None, Some(export::read_bake_scales(&args.texture).map_err(|e| e.to_string())?)),
    };
    let size = (args.width.unwrap_or(project.render.width), args.height.unwrap_or(project.render.height));
    let exposure = args.exposure.unwrap_or(project.render.exposure);
    Ok(Scene { args, project, ktx2, fog_volume, bake, size, exposure })
}

fn main() -> ExitCode {
    let args = match parse_args(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(e) if e.is_empty() => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        Err(e) => {
            eprintln!("error: {e}\n\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    let scene = match load_scene(args) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    // The texture is an asset like any other: its folder is the asset root.
    let folder = scene.args.texture.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let folder = std::path::absolute(folder).unwrap_or_else(|_| folder.to_path_buf());
    let (width, height) = scene.size;
    let background = scene.args.background;
    let wgpu = WgpuSettings { backends: Some(Backends::from_env().unwrap_or(Backends::VULKAN)), ..default() };
    let exit = App::new()
        .add_plugins(
            DefaultPlugins
                .set(AssetPlugin { file_path: folder.to_string_lossy().into_owned(), ..default() })
                .set(WindowPlugin {
                    primary_window: Some(Window {
                        title: "Fogsmith in Bevy".into(),
                        resolution: WindowResolution::new(width, height).with_scale_factor_override(1.0),
                        resizable: false,
                        ..default()
                    }),
                    exit_condition: ExitCondition::OnPrimaryClosed,
                    ..default()
                })
                .set(RenderPlugin {
                    render_creation: wgpu.into(),
                    synchronous_pipeline_compilation: true,
                    ..default()
                }),
        )
        .add_plugins(baked::BakedFogPlugin)
        .insert_resource(ClearColor(Color::linear_rgb(background, background, background)))
        .insert_resource(scene)
        .init_resource::<Capture>()
        .add_systems(Startup, setup)
        .add_systems(Update, capture)
        .run();
    match exit {
        AppExit::Success => ExitCode::SUCCESS,
        AppExit::Error(code) => ExitCode::from(code.get()),
    }
}

/// The handle of the texture, whose load the capture waits for.
#[derive(Resource)]
struct Texture(Handle<Image>);

fn vec3(v: (f32, f32, f32)) -> Vec3 {
    Vec3::new(v.0, v.1, v.2)
}

fn setup(
    mut commands: Commands,
    scene: Res<Scene>,
    asset_server: Res<AssetServer>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<baked::BakedFogMaterial>>,
) {
    let name = scene.args.texture.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // The texels are linear (the DFD says so), but Bevy's image loader decodes 8-bit KTX2
    // formats as sRGB unless told otherwise, which would bend an R8 density texture.
    let texture: Handle<Image> =
        asset_server.load_builder().with_settings(|s: &mut ImageLoaderSettings| s.is_srgb = false).load(name);
    commands.insert_resource(Texture(texture.clone()));

    let cam = &scene.project.camera;
    // Bevy's exposure is 2^−ev100 / 1.2; this ev100 gives the requested linear factor.
    let ev100 = -(1.2 * scene.exposure).log2();
    let camera = commands
        .spawn((
            Camera3d::default(),
            Hdr,
            Tonemapping::None,
            DebandDither::Disabled,
            Msaa::Off,
            Exposure { ev100 },
            Projection::Perspective(PerspectiveProjection { fov: cam.fov_y_deg.to_radians(), near: 0.01, ..default() }),
            Transform::from_translation(vec3(cam.position)).looking_at(vec3(cam.target), vec3(cam.up)),
        ))
        .id();

    match (&scene.fog_volume, &scene.bake) {
        (Some(fog), _) => {
            commands.entity(camera).insert(VolumetricFog {
                ambient_intensity: 0.0,
                jitter: 0.0,
                step_count: scene.args.fog_steps,
                ..default()
            });
            let t = &fog.transform;
            let p = &fog.fog_volume;
            commands.spawn((
                Transform {
                    translation: vec3(t.translation),
                    rotation: Quat::from_xyzw(t.rotation.0, t.rotation.1, t.rotation.2, t.rotation.3).normalize(),
                    scale: vec3(t.scale),
                },
                FogVolume {
                    density_texture: Some(texture),
                    density_factor: p.density_factor,
                    absorption: p.absorption,
                    scattering: p.scattering,
                    scattering_asymmetry: p.scattering_asymmetry,
                    ..default()
                },
            ));
            spawn_lights(&mut commands, &scene.project.lights);
        }
        (None, Some(scales)) => {
            let k = &scene.ktx2;
            let (min, max) = (Vec3::from_array(k.grid_min), Vec3::from_array(k.grid_max));
            let cells = (max - min) / UVec3::from_array(k.resolution).as_vec3();
            commands.spawn((
                Mesh3d(meshes.add(Cuboid::new(1.0, 1.0, 1.0))),
                MeshMaterial3d(materials.add(baked::BakedFogMaterial {
                    params: baked::BakedFogParams {
                        box_min: min,
                        emission_scale: scales.emission_scale,
                        box_max: max,
                        extinction_scale: scales.extinction_scale,
                        step: cells.min_element() / scene.args.steps_per_cell,
                    },
                    texture,
                })),
                Transform { translation: (min + max) * 0.5, scale: max - min, ..default() },
            ));
        }
        (None, None) => unreachable!("load_scene gives a density or a bake"),
    }
}

/// Fogsmith's lights in Bevy's units: a sun's irradiance (W/m²) as illuminance, a point or
/// spot light's intensity I (W/sr) as 4π·I "lumens" (Bevy divides by 4π), so one watt reads
/// as one lumen throughout and the exposure is the same as Fogsmith's. Bevy's fog takes only
/// lights with shadow maps enabled (the fog casts none, so they change nothing else).
fn spawn_lights(commands: &mut Commands, lights: &[export::Light]) {
    for light in lights.iter().filter(|l| !l.hidden) {
        let color = Color::linear_rgb(light.color.0, light.color.1, light.color.2);
        let lumens = 4.0 * std::f32::consts::PI * light.intensity;
        let at = Transform::from_translation(vec3(light.position));
        match light.kind {
            export::LightKind::Directional { direction } => {
                let d = vec3(direction).normalize_or(Vec3::NEG_Y);
                let up = if d.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
                commands.spawn((
                    DirectionalLight { color, illuminance: light.intensity, shadow_maps_enabled: true, ..default() },
                    Transform::IDENTITY.looking_to(d, up),
                    VolumetricLight,
                ));
            }
            export::LightKind::Point => {
                commands.spawn((
                    PointLight { color, intensity: lumens, range: 1000.0, shadow_maps_enabled: true, ..default() },
                    at,
                    VolumetricLight,
                ));
            }
            export::LightKind::Spot { direction, angle_deg, blend } => {
                let d = vec3(direction).normalize_or(Vec3::NEG_Y);
                let up = if d.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
                let outer = angle_deg.to_radians();
                commands.spawn((
                    SpotLight {
                        color,
                        intensity: lumens,
                        range: 1000.0,
                        outer_angle: outer,
                        inner_angle: outer * (1.0 - blend.clamp(0.0, 1.0)),
                        shadow_maps_enabled: true,
                        ..default()
                    },
                    at.looking_to(d, up),
                    VolumetricLight,
                ));
            }
        }
    }
}

/// Frames rendered since the texture loaded, and screenshots asked for.
#[derive(Resource, Default)]
struct Capture {
    frames_since_load: u32,
    requested: u32,
    pending: bool,
}

/// Frames to render once the texture is in, so that its upload, the pipelines and the shadow
/// maps are all in place before the shot.
const SETTLE_FRAMES: u32 = 4;
/// Screenshots taken before accepting a black one (an empty scene is black too).
const BLACK_RETRIES: u32 = 3;

fn capture(
    mut commands: Commands,
    texture: Res<Texture>,
    asset_server: Res<AssetServer>,
    scene: Res<Scene>,
    mut state: ResMut<Capture>,
    mut exit: MessageWriter<AppExit>,
) {
    match asset_server.load_state(&texture.0) {
        LoadState::Failed(e) => {
            error!("{}: Bevy could not load the texture: {e}", scene.args.texture.display());
            exit.write(AppExit::error());
            return;
        }
        LoadState::Loaded => {}
        _ => return,
    }
    state.frames_since_load += 1;
    if state.pending || state.frames_since_load < SETTLE_FRAMES * (state.requested + 1) {
        return;
    }
    state.pending = true;
    state.requested += 1;
    let out = scene.args.out.clone();
    let last_try = state.requested > BLACK_RETRIES;
    commands.spawn(Screenshot::primary_window()).observe(
        move |shot: On<ScreenshotCaptured>, mut state: ResMut<Capture>, mut exit: MessageWriter<AppExit>| {
            state.pending = false;
            let image = match shot.image.clone().try_into_dynamic() {
                Ok(i) => i.to_rgb8(),
                Err(e) => {
                    error!("cannot read the screenshot back: {e}");
                    exit.write(AppExit::error());
                    return;
                }
            };
            if image.as_raw().iter().all(|&v| v == 0) && !last_try {
                return;
            }
            match image.save_with_format(&out, image::ImageFormat::Png) {
                Ok(()) => {
                    info!("wrote {}", out.display());
                    exit.write(AppExit::Success);
                }
                Err(e) => {
                    error!("{}: cannot write the screenshot ({e}); pass an --out in a writable folder", out.display());
                    exit.write(AppExit::error());
                }
            }
        },
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(line: &str) -> Result<Args, String> {
        parse_args(line.split_whitespace().map(String::from))
    }

    #[test]
    fn the_command_line_names_what_is_missing_or_wrong() {
        let a = parse("--baked b.ktx2 --project p.ron --out s.png --width 320 --exposure 2").unwrap();
        assert_eq!((a.mode, a.width, a.height, a.exposure), (Mode::Baked, Some(320), None, Some(2.0)));
        assert!(parse("--project p.ron --out s.png").unwrap_err().contains("--density or --baked"));
        assert!(parse("--density d.ktx2 --out s.png").unwrap_err().contains("--project"));
        assert!(parse("--density d.ktx2 --project p.ron").unwrap_err().contains("--out"));
        assert!(parse("--density d.ktx2 --project p.ron --out s.png --width x").unwrap_err().contains("--width"));
        assert!(parse("--density d.ktx2 --project p.ron --out s.png --steps-per-cell NaN").is_err());
        assert!(parse("--density d.ktx2 --project p.ron --out s.png --exposure 0").is_err());
        assert!(parse("--density d.ktx2 --bogus").unwrap_err().contains("--bogus"));
    }
}

//! Reading what `fogsmith export` writes for Bevy: the KTX2 texture's header and key/value
//! data, the `NAME.fogvolume.ron` beside it, and the project's camera and lights.
//!
//! Every failure is an [`Error`] that names the file and says what to do, so a wrong file
//! stops the viewer before a window opens.

use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};

/// A file the viewer cannot use, with the fix.
#[derive(Debug)]
pub struct Error {
    pub path: PathBuf,
    pub problem: String,
    pub fix: String,
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}; {}", self.path.display(), self.problem, self.fix)
    }
}

impl std::error::Error for Error {}

fn error(path: &Path, problem: impl Into<String>, fix: impl Into<String>) -> Error {
    Error { path: path.to_path_buf(), problem: problem.into(), fix: fix.into() }
}

/// The texel formats Fogsmith writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexelFormat {
    /// Extinction in 1/m (`--ktx2`).
    R16Float,
    /// Extinction / `fogsmith.scale` (`--ktx2-format r8`).
    R8Unorm,
    /// Emission in RGB, extinction in A (`--bake-light --ktx2`).
    Rgba16Float,
}

/// What the KTX2 file says about itself.
#[derive(Clone, Debug)]
pub struct Ktx2Info {
    pub format: TexelFormat,
    pub resolution: [u32; 3],
    /// The grid box in metres, Y-up (`fogsmith.grid_min`, `fogsmith.grid_max`).
    pub grid_min: [f32; 3],
    pub grid_max: [f32; 3],
}

/// Reads the header and key/value data of a Fogsmith KTX2 texture.
pub fn read_ktx2(path: &Path) -> Result<Ktx2Info, Error> {
    let bytes = std::fs::read(path).map_err(|e| {
        error(path, format!("cannot read the texture ({e})"), "pass the .ktx2 file that `fogsmith export --ktx2` wrote")
    })?;
    let reader = ktx2::Reader::new(&bytes[..]).map_err(|e| {
        error(path, format!("not a KTX2 file ({e})"), "pass the .ktx2 file that `fogsmith export --ktx2` wrote")
    })?;
    let header = reader.header();
    let format = match header.format {
        Some(ktx2::Format::R16_SFLOAT) => TexelFormat::R16Float,
        Some(ktx2::Format::R8_UNORM) => TexelFormat::R8Unorm,
        Some(ktx2::Format::R16G16B16A16_SFLOAT) => TexelFormat::Rgba16Float,
        other => {
            return Err(error(
                path,
                format!(
                    "texel format {other:?} is not one Fogsmith writes (R16_SFLOAT, R8_UNORM, R16G16B16A16_SFLOAT)"
                ),
                "export it again with `fogsmith export --ktx2`",
            ))
        }
    };
    if header.pixel_depth < 1 || header.supercompression_scheme.is_some() || header.level_count > 1 {
        return Err(error(
            path,
            "not one uncompressed 3D level",
            "export it again with `fogsmith export --ktx2` (the viewer reads Fogsmith's uncompressed 3D textures)",
        ));
    }
    let mut grid_min = None;
    let mut grid_max = None;
    for (key, value) in reader.key_value_data() {
        let text = String::from_utf8_lossy(value);
        let text = text.trim_end_matches('\0');
        match key {
            "fogsmith.grid_min" => grid_min = Some(parse_vec3(path, key, text)?),
            "fogsmith.grid_max" => grid_max = Some(parse_vec3(path, key, text)?),
            _ => {}
        }
    }
    let (Some(grid_min), Some(grid_max)) = (grid_min, grid_max) else {
        return Err(error(
            path,
            "has no fogsmith.grid_min / fogsmith.grid_max key, so its box is unknown",
            "export it again with a current `fogsmith export --ktx2`",
        ));
    };
    // Both corners are finite (parse_vec3), so `<=` also catches an empty box.
    if (0..3).any(|i| grid_max[i] <= grid_min[i]) {
        return Err(error(path, "its grid box is empty", "export a project whose grid has a positive size"));
    }
    Ok(Ktx2Info {
        format,
        resolution: [header.pixel_width, header.pixel_height.max(1), header.pixel_depth.max(1)],
        grid_min,
        grid_max,
    })
}

fn parse_vec3(path: &Path, key: &str, text: &str) -> Result<[f32; 3], Error> {
    let v: Vec<f32> = text.split_whitespace().filter_map(|s| s.parse().ok()).collect();
    match v[..] {
        [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok([x, y, z]),
        _ => Err(error(path, format!("key {key} = {text:?} is not three numbers"), "export the texture again")),
    }
}

/// `NAME.fogvolume.ron` of a density texture: the `Transform` and `FogVolume` to spawn.
#[derive(Clone, Debug, Deserialize)]
pub struct FogVolumeFile {
    pub transform: TransformFile,
    pub fog_volume: FogVolumeParams,
}

#[derive(Clone, Debug, Deserialize)]
pub struct TransformFile {
    pub translation: (f32, f32, f32),
    pub rotation: (f32, f32, f32, f32),
    pub scale: (f32, f32, f32),
}

#[derive(Clone, Debug, Deserialize)]
pub struct FogVolumeParams {
    pub density_factor: f32,
    pub absorption: f32,
    pub scattering: f32,
    pub scattering_asymmetry: f32,
}

/// `NAME.fogvolume.ron` of a light bake: texel · scale = the value.
#[derive(Clone, Copy, Debug, Deserialize)]
pub struct BakeScales {
    pub emission_scale: f32,
    pub extinction_scale: f32,
}

/// The sidecar `fogsmith export` writes beside `ktx2`.
pub fn sidecar_path(ktx2: &Path) -> PathBuf {
    ktx2.with_extension("fogvolume.ron")
}

fn read_ron<T: for<'de> Deserialize<'de>>(path: &Path, what: &str, fix: &str) -> Result<T, Error> {
    let text =
        std::fs::read_to_string(path).map_err(|e| error(path, format!("cannot read {what} ({e})"), fix.to_string()))?;
    ron::from_str(&text).map_err(|e| error(path, format!("is not {what} ({e})"), fix.to_string()))
}

/// The density texture's sidecar.
pub fn read_fog_volume(ktx2: &Path) -> Result<FogVolumeFile, Error> {
    read_ron(
        &sidecar_path(ktx2),
        "the FogVolume sidecar of a density texture",
        "keep the NAME.fogvolume.ron that `fogsmith export --ktx2` writes beside NAME.ktx2",
    )
}

/// The light bake's sidecar.
pub fn read_bake_scales(ktx2: &Path) -> Result<BakeScales, Error> {
    let path = sidecar_path(ktx2);
    let scales: BakeScales = read_ron(
        &path,
        "the sidecar of a light bake",
        "keep the NAME.fogvolume.ron that `fogsmith export --bake-light --ktx2` writes beside NAME.ktx2",
    )?;
    if !(scales.emission_scale > 0.0 && scales.extinction_scale > 0.0) {
        return Err(error(&path, "its scales are not positive", "export the bake again"));
    }
    Ok(scales)
}

/// The parts of a Fogsmith project the viewer uses: where the camera looks from, the lights
/// that light Bevy's `FogVolume`, and the image size and exposure.
#[derive(Clone, Debug, Deserialize)]
#[serde(rename = "Project")]
pub struct Project {
    pub camera: Camera,
    #[serde(default)]
    pub lights: Vec<Light>,
    #[serde(default)]
    pub render: Render,
}

#[derive(Clone, Debug, Deserialize)]
pub struct Camera {
    pub position: (f32, f32, f32),
    pub target: (f32, f32, f32),
    #[serde(default = "up")]
    pub up: (f32, f32, f32),
    #[serde(default = "fov")]
    pub fov_y_deg: f32,
}

fn up() -> (f32, f32, f32) {
    (0.0, 1.0, 0.0)
}

fn fov() -> f32 {
    40.0
}

#[derive(Clone, Debug, Deserialize)]
pub struct Light {
    pub position: (f32, f32, f32),
    /// W/sr; W/m² for a sun.
    pub intensity: f32,
    #[serde(default)]
    pub kind: LightKind,
    #[serde(default = "white")]
    pub color: (f32, f32, f32),
    #[serde(default)]
    pub hidden: bool,
}

fn white() -> (f32, f32, f32) {
    (1.0, 1.0, 1.0)
}

#[derive(Clone, Copy, Debug, Default, Deserialize)]
pub enum LightKind {
    #[default]
    Point,
    Spot {
        direction: (f32, f32, f32),
        angle_deg: f32,
        blend: f32,
    },
    Directional {
        direction: (f32, f32, f32),
    },
}

#[derive(Clone, Debug, Deserialize)]
pub struct Render {
    #[serde(default = "width")]
    pub width: u32,
    #[serde(default = "height")]
    pub height: u32,
    #[serde(default = "one")]
    pub exposure: f32,
}

impl Default for Render {
    fn default() -> Self {
        Self { width: width(), height: height(), exposure: one() }
    }
}

fn width() -> u32 {
    640
}

fn height() -> u32 {
    360
}

fn one() -> f32 {
    1.0
}

/// Reads the camera, lights and render size of a project file.
pub fn read_project(path: &Path) -> Result<Project, Error> {
    read_ron(path, "a Fogsmith project", "pass the project (.ron) the texture was exported from")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../projects").join(name)
    }

    #[test]
    fn every_demo_project_gives_its_camera_and_lights() {
        let cloud = read_project(&demo("cloud.ron")).unwrap();
        assert_eq!(cloud.camera.position, (0.0, 1.0, 7.5));
        assert_eq!(cloud.camera.fov_y_deg, 45.0);
        assert_eq!((cloud.render.width, cloud.render.height, cloud.render.exposure), (640, 360, 1.0));
        assert!(matches!(cloud.lights[0].kind, LightKind::Directional { .. }));
        assert!(matches!(cloud.lights[1].kind, LightKind::Point));
        for name in ["cornell.ron", "room.ron", "street.ron", "street-wind.ron"] {
            read_project(&demo(name)).unwrap_or_else(|e| panic!("{e}"));
        }
    }

    #[test]
    fn bad_files_name_themselves_and_the_fix() {
        let e = read_ktx2(&demo("cloud.ron")).unwrap_err();
        assert!(e.path.ends_with("cloud.ron") && e.problem.contains("not a KTX2 file"), "{e}");
        let e = read_fog_volume(Path::new("/nonexistent/fog.ktx2")).unwrap_err();
        assert!(e.path.ends_with("fog.fogvolume.ron") && e.fix.contains("fogsmith export --ktx2"), "{e}");
        assert!(parse_vec3(Path::new("x"), "k", "1 2").is_err());
        assert_eq!(parse_vec3(Path::new("x"), "k", "1 -2.5 3e1").unwrap(), [1.0, -2.5, 30.0]);
    }
}

//! The extinction as a KTX2 3D texture for game engines, with a Bevy `FogVolume` snippet.
//!
//! # Texture
//!
//! One uncompressed 3D image (no array layers, one face, one mip level, no supercompression)
//! of `res.x × res.y × res.z` texels in the volume's own order: x fastest, then y, then z, so
//! texel (i, j, k) is cell (i, j, k) and texture coordinate w = 0 is the grid's min z. Formats:
//!
//! - [`Ktx2Format::R16f`] (`VK_FORMAT_R16_SFLOAT`): the extinction in 1/m as half floats
//!   (rounded to nearest even; values beyond ±65504 are refused).
//! - [`Ktx2Format::R8`] (`VK_FORMAT_R8_UNORM`): `round(255 · σ / scale)` with scale = the largest
//!   extinction (1 for an empty volume); σ = texel · scale, where the texel reads as 0..1.
//!
//! The data format descriptor is the basic one for these formats (RGBSDA model, BT.709
//! primaries, linear transfer). Key/value data, sorted by key: `KTXorientation` = `ruo` (x
//! right, y up, z out of the screen), `KTXwriter`, and `fogsmith.grid_min`,
//! `fogsmith.grid_max` (metres, Y-up), `fogsmith.quantity` (`extinction 1/m`) and
//! `fogsmith.scale` (the factor from texel value to extinction: 1 for R16F).
//!
//! # Light bake
//!
//! With a bake ([`write_baked_ktx2`]) the texture is `VK_FORMAT_R16G16B16A16_SFLOAT`: the
//! emission (W·m⁻³·sr⁻¹) in RGB and the extinction (1/m) in A, each stored divided by a scale
//! recorded as `fogsmith.emission_scale` and `fogsmith.extinction_scale` (1 unless the values
//! exceed half precision; then a power of two).
//!
//! # Bevy
//!
//! Bevy's `FogVolume` is a unit cube centred on its entity's origin, sampled with
//! `uvw = local + ½`, and its extinction is `density_factor · texel · (absorption +
//! scattering)`. So [`fog_volume_snippet`] gives the entity a translation at the grid's centre
//! and a scale of its size (Bevy is Y-up, metres, like Fogsmith), `density_factor` = the
//! texture's scale, `scattering` = albedo, `absorption` = 1 − albedo and
//! `scattering_asymmetry` = the Henyey–Greenstein g.

use super::{write_bytes_atomic, ExportError};
use crate::scene::{Medium, Volume, Volume3};
use std::path::Path;

/// `VK_FORMAT_R8_UNORM`.
pub const VK_FORMAT_R8_UNORM: u32 = 9;
/// `VK_FORMAT_R16_SFLOAT`.
pub const VK_FORMAT_R16_SFLOAT: u32 = 76;

/// The twelve bytes every KTX2 file starts with.
pub(crate) const IDENTIFIER: [u8; 12] = [0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A];

/// Texel format of the KTX2 export.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum, serde::Serialize, serde::Deserialize)]
pub enum Ktx2Format {
    /// 16-bit float: the extinction in 1/m.
    #[default]
    R16f,
    /// 8-bit unsigned normalized, times the scale in the key/value data.
    R8,
}

/// What [`write_ktx2`] wrote.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ktx2Info {
    pub format: Ktx2Format,
    /// Extinction = texel value (0..1 for R8) · scale.
    pub scale: f32,
    pub bytes: u64,
}

/// Writes `volume` as a KTX2 3D texture (see the module doc), atomically.
pub fn write_ktx2(path: &Path, volume: &Volume, format: Ktx2Format) -> Result<Ktx2Info, ExportError> {
    let (bytes, info) = encode_ktx2(path, volume, format)?;
    write_bytes_atomic(path, &bytes)?;
    Ok(info)
}

/// The file [`write_ktx2`] writes, in memory; `path` only names errors.
pub fn encode_ktx2(path: &Path, volume: &Volume, format: Ktx2Format) -> Result<(Vec<u8>, Ktx2Info), ExportError> {
    let grid = volume.grid;
    if volume.data.len() as u64 != grid.cell_count() {
        return Err(ExportError::invalid(path, "the volume's data does not match its grid", "pass a complete volume"));
    }
    if let Some(n) = volume.data.iter().position(|v| !v.is_finite() || *v < 0.0) {
        return Err(ExportError::invalid(
            path,
            format!(
                "cell {:?} has extinction {}, which a density texture cannot hold",
                grid.cell_of(n),
                volume.data[n]
            ),
            "export a volume whose extinction is finite and >= 0",
        ));
    }
    let (vk_format, type_size, scale, texels): (u32, u32, f32, Vec<u8>) = match format {
        Ktx2Format::R16f => {
            super::vdb::check_half_range(
                path,
                "the extinction",
                &volume.data,
                "use --ktx2-format r8, which stores a scale",
            )?;
            let t = volume.data.iter().flat_map(|v| half::f16::from_f32(*v).to_le_bytes()).collect();
            (VK_FORMAT_R16_SFLOAT, 2, 1.0, t)
        }
        Ktx2Format::R8 => {
            let max = volume.data.iter().fold(0.0f32, |m, v| m.max(*v));
            let scale = if max > 0.0 { max } else { 1.0 };
            let t = volume.data.iter().map(|v| r8_texel(*v, scale)).collect();
            (VK_FORMAT_R8_UNORM, 1, scale, t)
        }
    };
    let dfd = basic_dfd(format);
    let kv = vec![("fogsmith.quantity".into(), "extinction 1/m".into()), ("fogsmith.scale".into(), format!("{scale}"))];
    let out = container(&grid, vk_format, type_size, &dfd, kv, &texels);
    let info = Ktx2Info { format, scale, bytes: out.len() as u64 };
    Ok((out, info))
}

/// A KTX2 file of one uncompressed 3D level of `grid`'s size: the header, the level index,
/// `dfd`, the key/value data (orientation, writer, the grid box and `extra`, sorted by key)
/// and `texels`.
fn container(
    grid: &crate::scene::GridSpec,
    vk_format: u32,
    type_size: u32,
    dfd: &[u8],
    extra: Vec<(String, String)>,
    texels: &[u8],
) -> Vec<u8> {
    let r = grid.resolution;
    let g = |v: glam::Vec3| format!("{} {} {}", v.x, v.y, v.z);
    let mut kv: Vec<(String, String)> = vec![
        ("KTXorientation".into(), "ruo".into()),
        ("KTXwriter".into(), format!("fogsmith {}", env!("CARGO_PKG_VERSION"))),
        ("fogsmith.grid_max".into(), g(grid.max)),
        ("fogsmith.grid_min".into(), g(grid.min)),
    ];
    kv.extend(extra);
    kv.sort_by(|a, b| a.0.as_bytes().cmp(b.0.as_bytes()));
    let mut kvd = Vec::new();
    for (k, v) in &kv {
        let len = k.len() + 1 + v.len() + 1;
        kvd.extend_from_slice(&(len as u32).to_le_bytes());
        kvd.extend_from_slice(k.as_bytes());
        kvd.push(0);
        kvd.extend_from_slice(v.as_bytes());
        kvd.push(0);
        while kvd.len() % 4 != 0 {
            kvd.push(0);
        }
    }

    // Header (48) + index (32) + one level (24), then the DFD, the key/value data and the
    // level, which starts on a multiple of 4 (lcm of the texel size and 4).
    let dfd_offset = 48 + 32 + 24;
    let kvd_offset = dfd_offset + dfd.len();
    let mut level_offset = kvd_offset + kvd.len();
    level_offset = level_offset.div_ceil(4) * 4;
    let mut out = Vec::with_capacity(level_offset + texels.len());
    out.extend_from_slice(&IDENTIFIER);
    for v in [vk_format, type_size, r.x, r.y, r.z, 0, 1, 1, 0] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for v in [dfd_offset as u32, dfd.len() as u32, kvd_offset as u32, kvd.len() as u32] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(&0u64.to_le_bytes()); // no supercompression global data
    out.extend_from_slice(&0u64.to_le_bytes());
    for v in [level_offset as u64, texels.len() as u64, texels.len() as u64] {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out.extend_from_slice(dfd);
    out.extend_from_slice(&kvd);
    out.resize(level_offset, 0);
    out.extend_from_slice(texels);
    out
}

/// `VK_FORMAT_R16G16B16A16_SFLOAT`.
pub const VK_FORMAT_R16G16B16A16_SFLOAT: u32 = 97;

/// What [`write_baked_ktx2`] wrote: value = texel · scale, per quantity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BakedKtx2Info {
    /// Emission (RGB) in W·m⁻³·sr⁻¹ = texel · `emission_scale`.
    pub emission_scale: f32,
    /// Extinction (A) in 1/m = texel · `extinction_scale`.
    pub extinction_scale: f32,
    pub bytes: u64,
}

/// The factor that brings `max` within half precision: 1 when it fits, else the power of two
/// at or above max / 65504.
pub fn half_scale(max: f32) -> f32 {
    let limit = half::f16::MAX.to_f32();
    if max <= limit {
        1.0
    } else {
        (max / limit).log2().ceil().exp2()
    }
}

/// Writes the light bake as one RGBA16F 3D texture, atomically: emission in RGB, extinction in
/// A, each divided by its scale (key/value data `fogsmith.emission_scale`,
/// `fogsmith.extinction_scale`; see [`half_scale`]); the rest of the layout as [`write_ktx2`].
pub fn write_baked_ktx2(path: &Path, ev: &Volume, emission: &Volume3) -> Result<BakedKtx2Info, ExportError> {
    let (bytes, info) = encode_baked_ktx2(path, ev, emission)?;
    write_bytes_atomic(path, &bytes)?;
    Ok(info)
}

/// The file [`write_baked_ktx2`] writes, in memory; `path` only names errors.
pub fn encode_baked_ktx2(
    path: &Path,
    ev: &Volume,
    emission: &Volume3,
) -> Result<(Vec<u8>, BakedKtx2Info), ExportError> {
    let grid = ev.grid;
    if emission.grid != grid || ev.data.len() as u64 != grid.cell_count() || emission.data.len() != ev.data.len() {
        return Err(ExportError::invalid(path, "the extinction and emission grids differ", "bake both on one grid"));
    }
    let bad = ev.data.iter().chain(emission.data.iter().flatten()).position(|v| !v.is_finite() || *v < 0.0);
    if let Some(n) = bad {
        return Err(ExportError::invalid(
            path,
            format!("value {n} of the bake is negative or not finite"),
            "bake a scene whose extinction and lights are finite and >= 0",
        ));
    }
    let extinction_scale = half_scale(ev.max_value().max(0.0));
    let emission_scale = half_scale(emission.max_value());
    let half = |v: f32| half::f16::from_f32(v).to_le_bytes();
    let texels: Vec<u8> = ev
        .data
        .iter()
        .zip(&emission.data)
        .flat_map(|(&s, e)| {
            [
                half(e[0] / emission_scale),
                half(e[1] / emission_scale),
                half(e[2] / emission_scale),
                half(s / extinction_scale),
            ]
        })
        .flatten()
        .collect();
    let kv = vec![
        ("fogsmith.emission_scale".into(), format!("{emission_scale}")),
        ("fogsmith.extinction_scale".into(), format!("{extinction_scale}")),
        ("fogsmith.quantity".into(), "emission W/(m3 sr) in RGB, extinction 1/m in A".into()),
    ];
    let out = container(&grid, VK_FORMAT_R16G16B16A16_SFLOAT, 2, &rgba16f_dfd(), kv, &texels);
    let bytes = out.len() as u64;
    Ok((out, BakedKtx2Info { emission_scale, extinction_scale, bytes }))
}

/// The basic data format descriptor of RGBA16F: four signed float samples of 16 bits.
fn rgba16f_dfd() -> Vec<u8> {
    let mut words: Vec<u32> = vec![24 + 16 * 4 + 4, 0, 2 | ((24 + 16 * 4) << 16), 1 | (1 << 8) | (1 << 16), 0, 8, 0];
    for (c, channel) in [0u32, 1, 2, 15].into_iter().enumerate() {
        words.extend([(c as u32 * 16) | (15 << 16) | ((channel | 0xC0) << 24), 0, 0xBF80_0000, 0x3F80_0000]);
    }
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// The R8 texel of extinction `v` for `scale`: round(255 · v / scale), clamped to 0..=255.
pub fn r8_texel(v: f32, scale: f32) -> u8 {
    (v / scale * 255.0).round().clamp(0.0, 255.0) as u8
}

/// The basic data format descriptor of a one-channel R16F or R8 texture.
fn basic_dfd(format: Ktx2Format) -> Vec<u8> {
    let (bytes, bits, qualifiers, lower, upper): (u32, u32, u32, u32, u32) = match format {
        // FLOAT | SIGNED; bounds −1.0 and 1.0 as f32 bits.
        Ktx2Format::R16f => (2, 16, 0x80 | 0x40, 0xBF80_0000, 0x3F80_0000),
        Ktx2Format::R8 => (1, 8, 0, 0, 255),
    };
    let words: [u32; 11] = [
        44,                                  // dfdTotalSize
        0,                                   // vendor 0 (Khronos), descriptor type 0 (basic)
        2 | (40 << 16),                      // version 2, block size 24 + 16 · 1 sample
        1 | (1 << 8) | (1 << 16),            // model RGBSDA, primaries BT.709, transfer linear, flags 0
        0,                                   // texel block 1×1×1×1
        bytes,                               // bytesPlane0
        0,                                   // bytesPlane4..7
        (bits - 1) << 16 | qualifiers << 24, // bit offset 0, length, channel R + qualifiers
        0,                                   // sample position
        lower,
        upper,
    ];
    words.iter().flat_map(|w| w.to_le_bytes()).collect()
}

/// A Bevy `FogVolume` and `Transform` matching the texture (see the module doc), as RON with a
/// comment on how to spawn it. `texture` is the path an `AssetServer` loads the KTX2 file from.
pub fn fog_volume_snippet(volume: &Volume, medium: &Medium, info: &Ktx2Info, texture: &str) -> String {
    let g = volume.grid;
    let c = (g.min + g.max) * 0.5;
    let s = g.max - g.min;
    let albedo = medium.albedo.clamp(0.0, 1.0);
    format!(
        "// A Bevy FogVolume for {texture}, written by Fogsmith. Extinction = density_factor · texel ·\n\
         // (absorption + scattering) = the exported extinction in 1/m. Spawn it as\n\
         //   commands.spawn((\n\
         //       Transform {{ translation: Vec3::new({cx}, {cy}, {cz}), scale: Vec3::new({sx}, {sy}, {sz}), ..default() }},\n\
         //       FogVolume {{\n\
         //           // Linear texels: Bevy decodes 8-bit KTX2 as sRGB unless told otherwise.\n\
         //           density_texture: Some(asset_server.load_builder()\n\
         //               .with_settings(|s: &mut ImageLoaderSettings| s.is_srgb = false).load({texture:?})),\n\
         //           density_factor: {df},\n\
         //           absorption: {ab},\n\
         //           scattering: {sc},\n\
         //           scattering_asymmetry: {g},\n\
         //           ..default()\n\
         //       }},\n\
         //   ));\n\
         // The project's base fog outside the grid ({base} 1/m) is not part of the volume.\n\
         (\n\
         \x20   density_texture: {texture:?},\n\
         \x20   transform: (\n\
         \x20       translation: ({cx}, {cy}, {cz}),\n\
         \x20       rotation: (0.0, 0.0, 0.0, 1.0),\n\
         \x20       scale: ({sx}, {sy}, {sz}),\n\
         \x20   ),\n\
         \x20   fog_volume: (\n\
         \x20       density_factor: {df},\n\
         \x20       absorption: {ab},\n\
         \x20       scattering: {sc},\n\
         \x20       scattering_asymmetry: {g},\n\
         \x20   ),\n\
         )\n",
        cx = fmt(c.x),
        cy = fmt(c.y),
        cz = fmt(c.z),
        sx = fmt(s.x),
        sy = fmt(s.y),
        sz = fmt(s.z),
        df = fmt(info.scale),
        ab = fmt(1.0 - albedo),
        sc = fmt(albedo),
        g = fmt(medium.anisotropy),
        base = medium.base_extinction,
    )
}

/// The note written beside a baked texture instead of the Bevy snippet: Bevy's `FogVolume`
/// reads one density channel and lights it itself, so the bake needs the engine's own shader.
pub fn baked_texture_note(info: &BakedKtx2Info) -> String {
    format!(
        "// A Fogsmith light bake: an RGBA16F 3D texture, texel (i, j, k) = cell (i, j, k).\n\
         // RGB: emission in W/(m3 sr) = texel * {e}; A: extinction in 1/m = texel * {a}.\n\
         // Render it as emission and absorption with no lights: along a view ray,\n\
         // L += T * rgb / a * (1 - exp(-a * step)), T *= exp(-a * step).\n\
         // Bevy's FogVolume reads one density channel and adds its own lighting, so it cannot\n\
         // show the bake as it is; use a custom volume material.\n\
         (emission_scale: {e}, extinction_scale: {a})\n",
        e = fmt(info.emission_scale),
        a = fmt(info.extinction_scale),
    )
}

/// A float RON and Rust both read as a float (always with a decimal point).
fn fmt(v: f32) -> String {
    let s = format!("{v}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

//! Writing rendered images: tone-mapped PNG and linear HDR EXR.
//!
//! Tone mapping (PNG and the editor's display): each linear channel L becomes
//! `1 − exp(−exposure · L)`, an exponential shoulder that never clips and maps small
//! radiance linearly, then the sRGB transfer curve is applied and the result quantised to 8
//! bits. The same operator runs in `shaders/march.wgsl`.

use crate::gpu::Image;
use crate::scene::io::write_atomic;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    #[error("{path}: unsupported output format; use a .png (tone-mapped) or .exr (linear HDR) file name")]
    Format { path: PathBuf },
    #[error("{path}: could not write the image: {message}")]
    Write { path: PathBuf, message: String },
}

/// The display transform described in the module doc, per channel.
pub fn tonemap(linear: f32, exposure: f32) -> f32 {
    let l = 1.0 - (-exposure * linear.max(0.0)).exp();
    if l <= 0.0031308 {
        l * 12.92
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    }
}

/// Writes `image` to `path`, choosing PNG or EXR from the extension. Atomic.
pub fn write_image(path: &Path, image: &Image, exposure: f32) -> Result<(), OutputError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let werr = |message: String| OutputError::Write { path: path.to_owned(), message };
    match ext.as_deref() {
        Some("png") => {
            let bytes = encode_png(image, exposure).map_err(werr)?;
            write_atomic(path, &bytes, false).map_err(|e| werr(e.to_string()))
        }
        Some("exr") => {
            crate::export::exr::write_render_exr(path, image.width as usize, image.height as usize, &image.rgba, false)
                .map_err(|e| werr(e.to_string()))
        }
        _ => Err(OutputError::Format { path: path.to_owned() }),
    }
}

fn encode_png(image: &Image, exposure: f32) -> Result<Vec<u8>, String> {
    let mut pixels = Vec::with_capacity(image.rgba.len() * 3);
    for p in &image.rgba {
        for c in &p[..3] {
            pixels.push((tonemap(*c, exposure) * 255.0 + 0.5).clamp(0.0, 255.0) as u8);
        }
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&pixels, image.width, image.height, image::ExtendedColorType::Rgb8)
        .map_err(|e| e.to_string())?;
    Ok(out)
}

use image::ImageEncoder;

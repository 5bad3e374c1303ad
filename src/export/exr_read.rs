//! Reading an EXR back (the farm's completeness check) without trusting its header's sizes.
//!
//! The exr crate allocates every channel of every layer at the size its data window claims
//! before it reads a pixel, so one changed byte in a window (a corner moved by 2²⁸) asks for
//! tens of gigabytes, and the allocation failure aborts the process. So the headers are read
//! first, on their own, and the pixels they claim are checked against the file: an
//! uncompressed file must hold them; a compressed one cannot expand by more than
//! [`MAX_EXPANSION`] (zlib's limit is about 1032:1, and no EXR codec beats it by 2×); and no
//! file may claim more than [`MAX_EXR_BYTES`] of pixels. Only then does the crate read it.

use exr::meta::attribute::{LevelMode, SampleType};
use exr::meta::{BlockDescription, MetaData};
use std::io::Cursor;

/// Most bytes of pixels (every channel, layer and level) an EXR read back may hold: 4 GiB.
pub const MAX_EXR_BYTES: u128 = 1 << 32;

/// Most pixel bytes a compressed EXR may claim per byte of file.
pub const MAX_EXPANSION: u128 = 2048;

/// The bytes of pixels the headers of `bytes` claim, checked against the file's length and
/// [`MAX_EXR_BYTES`]; the error says which layer claims what.
pub fn exr_pixel_bytes(bytes: &[u8]) -> Result<u128, String> {
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(|e| format!("its header: {e}"))?;
    let mut total = 0u128;
    let mut compressed = false;
    for (n, h) in meta.headers.iter().enumerate() {
        if h.deep {
            return Err(format!("layer {n} holds deep data, which no Fogsmith output does"));
        }
        let (w, ht) = (h.layer_size.0 as u128, h.layer_size.1 as u128);
        let levels = match &h.blocks {
            BlockDescription::Tiles(t) => match t.level_mode {
                LevelMode::Singular => 1,
                LevelMode::MipMap => 2,
                LevelMode::RipMap => 4,
            },
            BlockDescription::ScanLines => 1,
        };
        let mut layer = 0u128;
        for c in &h.channels.list {
            let sample = match c.sample_type {
                SampleType::F16 => 2,
                SampleType::F32 | SampleType::U32 => 4,
            };
            let (sx, sy) = (c.sampling.0.max(1) as u128, c.sampling.1.max(1) as u128);
            layer = layer.saturating_add((w / sx).saturating_mul(ht / sy).saturating_mul(sample));
        }
        let layer = layer.saturating_mul(levels);
        let file = bytes.len() as u128;
        let window = h.data_window();
        let describe = || {
            format!(
                "layer {n}'s data window ({}, {}) to ({}, {}) claims {layer} bytes of pixels",
                window.position.0,
                window.position.1,
                window.position.0 as i64 + w as i64 - 1,
                window.position.1 as i64 + ht as i64 - 1
            )
        };
        if layer > MAX_EXR_BYTES {
            return Err(format!("{}, more than {MAX_EXR_BYTES} this check reads", describe()));
        }
        compressed |= h.compression != exr::compression::Compression::Uncompressed;
        let room = if compressed { file.saturating_mul(MAX_EXPANSION) } else { file };
        total = total.saturating_add(layer);
        if total > room {
            return Err(format!("{}, more than its {file}-byte file can hold", describe()));
        }
    }
    Ok(total)
}

/// Reads every layer, channel and level of an EXR in memory, once [`exr_pixel_bytes`] has
/// found its headers' sizes possible.
pub fn read_exr_back(bytes: &[u8]) -> Result<(), String> {
    use exr::prelude::{ReadChannels, ReadLayers};
    exr_pixel_bytes(bytes)?;
    exr::prelude::read()
        .no_deep_data()
        .all_resolution_levels()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_buffered(Cursor::new(bytes))
        .map(drop)
        .map_err(|e| e.to_string())
}

//! Whether an output file is complete: its checksum sidecar (`NAME.crc32`, written after the
//! file is in place) when there is one, else the file read back by its own format, with every
//! size its header claims checked against the file before anything is allocated: a damaged
//! file is reported damaged (and baked again), never an abort.
//!
//! A farm task reruns after a failure or preemption; it must skip exactly the frames whose
//! files are whole. Exports already move files into place only once written, so a killed task
//! leaves no half-written target, but a file can still be truncated later (a full disk, a
//! copy cut short), and the sidecar catches that without parsing the file.

use std::path::{Path, PathBuf};

/// What is found at an output path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FileState {
    Done,
    Missing,
    /// The file is there but truncated or unreadable; the reason says which.
    Damaged(String),
}

/// The sidecar of `path`: `fog.0001.vdb` → `fog.0001.vdb.crc32`.
pub fn sidecar(path: &Path) -> PathBuf {
    let mut name = path.file_name().map(|n| n.to_os_string()).unwrap_or_default();
    name.push(".crc32");
    path.with_file_name(name)
}

fn sidecar_text(bytes: &[u8]) -> String {
    format!("crc32 {:08x} bytes {}\n", crc32fast::hash(bytes), bytes.len())
}

/// Writes the sidecar of `path` from the file as it is now (through a temporary file, so a
/// sidecar is never half written).
pub fn write_sidecar(path: &Path) -> std::io::Result<()> {
    let bytes = std::fs::read(path)?;
    let target = sidecar(path);
    let temp = target.with_extension("crc32.partial");
    std::fs::write(&temp, sidecar_text(&bytes))?;
    std::fs::rename(&temp, &target)
}

/// Removes the temporaries a killed export left beside `target` (staged copies and
/// half-written sidecars), before the frame is written again.
pub fn remove_leftovers(target: &Path) {
    let dir = match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let (Some(stem), Some(name)) = (target.file_stem(), target.file_name()) else { return };
    let staged = format!(".{}.fogsmith-partial", stem.to_string_lossy());
    let sidecar = format!("{}.crc32.partial", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries.flatten() {
        let n = entry.file_name().to_string_lossy().into_owned();
        if n.starts_with(&staged) || n.starts_with(&sidecar) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// The state of the file at `path`.
pub fn file_state(path: &Path) -> FileState {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return FileState::Missing,
        Err(e) => return FileState::Damaged(format!("cannot be read: {e}")),
    };
    if let Ok(expected) = std::fs::read_to_string(sidecar(path)) {
        let size = expected.split_whitespace().nth(3).and_then(|s| s.parse::<usize>().ok());
        return if sidecar_text(&bytes) == expected {
            FileState::Done
        } else if size.is_some_and(|n| bytes.len() < n) {
            FileState::Damaged(format!("truncated: {} of {} bytes", bytes.len(), size.unwrap_or(0)))
        } else {
            FileState::Damaged(format!("its checksum differs from {}", sidecar(path).display()))
        };
    }
    match read_back(path, &bytes) {
        Ok(()) => FileState::Done,
        Err(e) => FileState::Damaged(format!("does not read back: {e}")),
    }
}

/// Parses the file by its extension: every grid of a VDB (float and vec3s, float or half), a
/// NanoVDB file's segments and grid headers, every layer of an EXR (its header's sizes checked
/// against the file first), a KTX2's header and level index, a PNG's pixels, a USD stage's text.
fn read_back(path: &Path, bytes: &[u8]) -> Result<(), String> {
    if bytes.is_empty() {
        return Err("the file is empty".into());
    }
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("vdb") => crate::export::vdb_read::check_vdb_bytes(path, bytes).map_err(|e| e.to_string()),
        Some("nvdb") => crate::export::nanovdb::check_nanovdb_bytes(bytes),
        Some("exr") => crate::export::exr_read::read_exr_back(bytes),
        Some("ktx2") => check_ktx2(bytes),
        Some("png") => image::load_from_memory(bytes).map(drop).map_err(|e| e.to_string()),
        Some("usda") => match std::str::from_utf8(bytes) {
            Ok(text) if text.starts_with("#usda") && text.matches('{').count() == text.matches('}').count() => Ok(()),
            _ => Err("not a complete USD text stage".into()),
        },
        _ => Ok(()),
    }
}

/// A KTX2 file's header, descriptor ranges and level index lie within the file, and for the
/// uncompressed formats Fogsmith writes, each level holds exactly its texels.
fn check_ktx2(bytes: &[u8]) -> Result<(), String> {
    use crate::export::ktx::{IDENTIFIER, VK_FORMAT_R16G16B16A16_SFLOAT, VK_FORMAT_R16_SFLOAT, VK_FORMAT_R8_UNORM};
    const HEADER: usize = 80;
    if bytes.len() < HEADER || bytes[..12] != IDENTIFIER {
        return Err(format!("not a KTX2 file ({} bytes without its 80-byte header)", bytes.len()));
    }
    let u32_at = |at: usize| u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]]) as u64;
    let u64_at = |at: usize| u32_at(at) | (u32_at(at + 4) << 32);
    let (format, width, height, depth) = (u32_at(12), u32_at(20), u32_at(24), u32_at(28));
    let (layers, faces, levels, scheme) = (u32_at(32), u32_at(36), u32_at(40).max(1), u32_at(44));
    let len = bytes.len() as u64;
    let index_end = HEADER as u64 + levels * 24;
    if index_end > len {
        return Err(format!("its level index ({levels} levels) runs past the end of the {len}-byte file"));
    }
    let within = |what: &str, offset: u64, size: u64| match offset.checked_add(size) {
        Some(end) if size == 0 || (offset >= index_end && end <= len) => Ok(()),
        _ => Err(format!("its {what} (bytes {offset} + {size}) lies outside the {len}-byte file")),
    };
    within("data format descriptor", u32_at(48), u32_at(52))?;
    within("key/value data", u32_at(56), u32_at(60))?;
    within("supercompression data", u64_at(64), u64_at(72))?;
    let texel = match u32::try_from(format).unwrap_or(0) {
        VK_FORMAT_R8_UNORM => Some(1),
        VK_FORMAT_R16_SFLOAT => Some(2),
        VK_FORMAT_R16G16B16A16_SFLOAT => Some(8),
        _ => None,
    };
    for level in 0..levels {
        let at = HEADER + level as usize * 24;
        let (offset, size) = (u64_at(at), u64_at(at + 8));
        within(&format!("level {level}"), offset, size)?;
        if let (Some(texel), 0) = (texel, scheme) {
            let side = |n: u64| n.checked_shr(level as u32).unwrap_or(0).max(1);
            let expected = [side(width), side(height), side(depth), layers.max(1), faces.max(1), texel]
                .iter()
                .try_fold(1u64, |a, &b| a.checked_mul(b));
            if expected != Some(size) {
                let need = expected.map_or("more than 2^64".to_string(), |n| n.to_string());
                return Err(format!(
                    "level {level} holds {size} bytes, its {width}×{height}×{depth} texels need {need}"
                ));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sidecar_tells_a_whole_file_from_a_truncated_or_altered_one() {
        let dir = std::env::temp_dir().join(format!("fogsmith-check-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.bin");
        assert_eq!(file_state(&path), FileState::Missing);
        std::fs::write(&path, b"0123456789").unwrap();
        write_sidecar(&path).unwrap();
        assert_eq!(file_state(&path), FileState::Done);
        std::fs::write(&path, b"01234").unwrap();
        assert_eq!(file_state(&path), FileState::Damaged("truncated: 5 of 10 bytes".into()));
        std::fs::write(&path, b"0123456780").unwrap();
        assert!(matches!(file_state(&path), FileState::Damaged(m) if m.contains("checksum differs")));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! Particle sidecar files: a project's particles in binary, beside its RON file.
//!
//! RON costs a parse of every digit of every particle, so a project with many particles
//! keeps its settings, lights and tracks in RON and its particles in
//! `<project file name>.<checksum>.particles` (`bench --suite scale` measures both). The RON
//! names the file with its particle count and checksum, so a project never reads particles
//! written for another save. Each save writes a new sidecar before the RON that names it
//! and then removes the sidecars that neither the new file nor its `.bak` name: a failed
//! save leaves the previous project and its particles as they were.
//!
//! Layout, little-endian: a 40-byte header (magic `FOGPARTS`, format, record size, count,
//! name bytes, CRC-32 of everything after the header, reserved), one 28-byte record per
//! particle (id, centre x y z, radius, density as f32 bits, flags: 1 hidden, 2 noise), then
//! the names: for each named particle its index, byte length and UTF-8 bytes.

use super::Particle;
use glam::Vec3;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Projects with at least this many particles save them in a sidecar.
pub const SIDECAR_MIN_PARTICLES: usize = 10_000;

/// The version a project file with a sidecar carries: builds that do not read sidecars
/// refuse it instead of loading it without particles. Otherwise it is version 3.
pub const SIDECAR_PROJECT_VERSION: u32 = 4;

const MAGIC: &[u8; 8] = b"FOGPARTS";
const FORMAT: u32 = 1;
const HEADER: usize = 40;
const RECORD: usize = 28;
const HIDDEN: u32 = 1;
const NOISE: u32 = 2;

/// Where a project file's particles are: written into the RON by saving, consumed by
/// loading (a loaded project holds its particles and no reference).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParticleFile {
    /// The sidecar's file name, relative to the project file's directory.
    pub file: PathBuf,
    pub count: u64,
    /// CRC-32 of the sidecar after its header.
    pub crc32: u32,
}

/// The sidecar bytes of `particles` and their checksum.
pub fn encode(particles: &[Particle]) -> (Vec<u8>, u32) {
    let named: Vec<(usize, &str)> =
        particles.iter().enumerate().filter_map(|(i, p)| p.name.as_deref().map(|n| (i, n))).collect();
    let names_bytes: usize = 4 + named.iter().map(|(_, n)| 8 + n.len()).sum::<usize>();
    let mut out = Vec::with_capacity(HEADER + particles.len() * RECORD + names_bytes);
    out.extend_from_slice(&[0; HEADER]);
    for p in particles {
        let flags = if p.hidden { HIDDEN } else { 0 } | if p.noise { NOISE } else { 0 };
        for word in [
            p.id,
            p.center.x.to_bits(),
            p.center.y.to_bits(),
            p.center.z.to_bits(),
            p.radius.to_bits(),
            p.density.to_bits(),
            flags,
        ] {
            out.extend_from_slice(&word.to_le_bytes());
        }
    }
    out.extend_from_slice(&(named.len() as u32).to_le_bytes());
    for (i, name) in named {
        out.extend_from_slice(&(i as u32).to_le_bytes());
        out.extend_from_slice(&(name.len() as u32).to_le_bytes());
        out.extend_from_slice(name.as_bytes());
    }
    let crc = crc32(&out[HEADER..]);
    let mut header = Vec::with_capacity(HEADER);
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&FORMAT.to_le_bytes());
    header.extend_from_slice(&(RECORD as u32).to_le_bytes());
    header.extend_from_slice(&(particles.len() as u64).to_le_bytes());
    header.extend_from_slice(&(names_bytes as u64).to_le_bytes());
    header.extend_from_slice(&crc.to_le_bytes());
    header.extend_from_slice(&0u32.to_le_bytes());
    out[..HEADER].copy_from_slice(&header);
    (out, crc)
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = flate2::Crc::new();
    crc.update(bytes);
    crc.sum()
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("four bytes"))
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().expect("eight bytes"))
}

/// The particles of sidecar `bytes`, checked against what the project file expects; the
/// error says what is wrong, without the file's name.
pub fn decode(bytes: &[u8], expected: &ParticleFile) -> Result<Vec<Particle>, String> {
    let fix = "restore it from a backup, or open the project's .bak, which names the previous one";
    if bytes.len() < HEADER || &bytes[..8] != MAGIC {
        return Err(format!("not a Fogsmith particle file (it holds {} bytes without the header); {fix}", bytes.len()));
    }
    let (format, record, count) = (u32_at(bytes, 8), u32_at(bytes, 12) as usize, u64_at(bytes, 16));
    if format != FORMAT || record != RECORD {
        return Err(format!(
            "particle file format {format} with {record}-byte records; this build reads format {FORMAT} ({RECORD}-byte records), so a newer Fogsmith wrote it"
        ));
    }
    let names_bytes = u64_at(bytes, 24);
    let want = (HEADER as u64)
        .checked_add(count.saturating_mul(RECORD as u64))
        .and_then(|n| n.checked_add(names_bytes))
        .unwrap_or(u64::MAX);
    if bytes.len() as u64 != want {
        let what = if (bytes.len() as u64) < want { "truncated" } else { "longer than its header says" };
        return Err(format!(
            "{what}: it holds {} bytes, its header announces {want} ({count} particles); {fix}",
            bytes.len()
        ));
    }
    let crc = crc32(&bytes[HEADER..]);
    if crc != u32_at(bytes, 32) || crc != expected.crc32 {
        return Err(format!(
            "damaged: its checksum is {crc:08x}, the header says {:08x} and the project file {:08x}; {fix}",
            u32_at(bytes, 32),
            expected.crc32
        ));
    }
    if count != expected.count {
        return Err(format!("holds {count} particles, the project file expects {}; {fix}", expected.count));
    }
    let count = count as usize;
    let f = |b: &[u8], at: usize| f32::from_bits(u32_at(b, at));
    let mut particles: Vec<Particle> = bytes[HEADER..HEADER + count * RECORD]
        .chunks_exact(RECORD)
        .map(|r| {
            let flags = u32_at(r, 24);
            Particle {
                id: u32_at(r, 0),
                center: Vec3::new(f(r, 4), f(r, 8), f(r, 12)),
                radius: f(r, 16),
                density: f(r, 20),
                name: None,
                hidden: flags & HIDDEN != 0,
                noise: flags & NOISE != 0,
            }
        })
        .collect();
    let names = &bytes[HEADER + count * RECORD..];
    let bad_names = || format!("its names section is damaged; {fix}");
    if names.len() < 4 {
        return Err(bad_names());
    }
    let mut at = 4;
    for _ in 0..u32_at(names, 0) {
        if at + 8 > names.len() {
            return Err(bad_names());
        }
        let (index, len) = (u32_at(names, at) as usize, u32_at(names, at + 4) as usize);
        let text = names.get(at + 8..at + 8 + len).ok_or_else(bad_names)?;
        let name = std::str::from_utf8(text).map_err(|_| bad_names())?;
        particles.get_mut(index).ok_or_else(bad_names)?.name = Some(name.to_owned());
        at += 8 + len;
    }
    if at != names.len() {
        return Err(bad_names());
    }
    Ok(particles)
}

/// The sidecar name for the project file `path` and checksum `crc`.
pub fn sidecar_name(path: &Path, crc: u32) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    PathBuf::from(format!("{name}.{crc:08x}.particles"))
}

/// Whether `file` is a sidecar name of the project file named `project_name`.
pub fn is_sidecar_of(project_name: &str, file: &str) -> bool {
    file.strip_prefix(project_name)
        .and_then(|rest| rest.strip_prefix('.'))
        .and_then(|rest| rest.strip_suffix(".particles"))
        .is_some_and(|hex| hex.len() == 8 && hex.bytes().all(|b| b.is_ascii_hexdigit()))
}

/// The sidecar a project file's text names, if any, without parsing the rest.
pub fn named_in(text: &str) -> Option<PathBuf> {
    let at = text.find("particle_file:")?;
    let rest = &text[at..];
    let open = rest.find('"')? + 1;
    let close = rest[open..].find('"')? + open;
    Some(PathBuf::from(&rest[open..close]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_flags_round_trip() {
        let mut a = Particle::new(Vec3::new(1.0, -2.0, f32::MIN_POSITIVE), 0.25, 3.0);
        a.id = 7;
        a.name = Some("puff ☁".into());
        a.hidden = true;
        let mut b = Particle::new(Vec3::ZERO, 1e-30, 0.0);
        b.noise = false;
        let (bytes, crc) = encode(&[a.clone(), b.clone()]);
        let expected = ParticleFile { file: "x".into(), count: 2, crc32: crc };
        assert_eq!(decode(&bytes, &expected).unwrap(), vec![a, b]);
        let mut damaged = bytes.clone();
        damaged[HEADER + 5] ^= 1;
        assert!(decode(&damaged, &expected).unwrap_err().starts_with("damaged"));
        assert!(decode(&bytes[..bytes.len() - 1], &expected).unwrap_err().starts_with("truncated"));
    }

    #[test]
    fn recognises_only_its_own_names() {
        assert!(is_sidecar_of("a.ron", "a.ron.0123abcd.particles"));
        assert!(!is_sidecar_of("a.ron", "b.ron.0123abcd.particles"));
        assert!(!is_sidecar_of("a.ron", "a.ron.0123abc.particles"));
        assert!(!is_sidecar_of("a.ron", "a.ron.bak"));
        assert_eq!(
            named_in("x\n    particle_file: Some((file: \"a.ron.01.particles\", count: 3))"),
            Some("a.ron.01.particles".into())
        );
    }
}

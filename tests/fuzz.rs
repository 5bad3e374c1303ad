//! Structure-aware mutation fuzzing of every file Fogsmith reads back: VDB (float, half and
//! vec3 grids, uncompressed and zip), project files of every version (1 to 4, with the
//! particle sidecar of version 4), the sidecar itself, EXR and KTX2 outputs and the farm
//! bundle's `farm.json`, each as the farm check or the loader reads it.
//!
//! Seeds are the files under `tests/corpus/` and files written here; each case applies one
//! to three edits that keep most of the structure (a count, size or offset set to an edge
//! value, a float set to NaN, infinity or a huge value, a truncation, bytes inserted, deleted
//! or duplicated; for text, a number, token or line), so the readers go deep. Every case must
//! end in a one-line error or a valid result, without a panic or an abort: a global allocator
//! here refuses any single allocation over [`MAX_ALLOCATION`] (the process would abort, and
//! the test fail) and the peak of live memory is reported. Edits that only change the length
//! of a binary file (bytes inserted, deleted, duplicated or cut off), and any change to a
//! checksummed sidecar, must be refused or read back the same: otherwise the volume would
//! differ silently. A truncated VDB, EXR, KTX2 or sidecar must be refused.
//!
//! A fixed seed and a few hundred cases run in `cargo test`; `scripts/fuzz.sh` runs longer
//! (`FOGSMITH_FUZZ_SEED`, `FOGSMITH_FUZZ_CASES` per reader). Failing inputs are written to
//! `target/fuzz-failures/` to be minimised into `tests/corpus/damaged/`.

use fogsmith::export::vdb::{encode_vdb, VdbCompression, VdbGrid, VdbOptions};
use fogsmith::export::vdb_read::{list_vdb_grids, read_vdb_grid_from_bytes};
use fogsmith::farm::check::{file_state, FileState};
use fogsmith::farm::FarmJob;
use fogsmith::scene::io::to_ron_string;
use fogsmith::scene::sidecar::{decode, ParticleFile};
use fogsmith::scene::{parse_project, GridSpec, Particle, Volume, Volume3};
use glam::{UVec3, Vec3};
use std::alloc::{GlobalAlloc, Layout, System};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Largest single allocation a case may make: a reader that trusts a size from the file
/// asks for more and aborts the run.
const MAX_ALLOCATION: usize = 1 << 30;
/// Most memory the run may hold at once, for readers that grow without bound in small steps.
const MAX_LIVE: usize = 3 << 30;

struct Counting;
static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call forwards to the system allocator with the caller's layout; only the
// counters are added, and an over-large request returns null as a failed allocation does.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > MAX_ALLOCATION {
            eprintln!("fuzz: refused an allocation of {} bytes", layout.size());
            return std::ptr::null_mut();
        }
        let live = LIVE.fetch_add(layout.size(), Ordering::Relaxed) + layout.size();
        if live > MAX_LIVE {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            eprintln!("fuzz: refused to hold more than {MAX_LIVE} bytes");
            return std::ptr::null_mut();
        }
        PEAK.fetch_max(live, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// The mutations' draws, fixed per seed: the project's seeded xorshift64* (`fogsmith::rng`).
struct Rng(fogsmith::rng::XorShiftStar);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0.next_u64()
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.below(items.len())]
    }
}

/// What a reader made of a file: refused with a message, or read, with a digest of what it read.
enum Outcome {
    Refused(String),
    Read(u64),
}

#[derive(Clone, Copy, PartialEq)]
enum Kind {
    /// Binary, self-describing: edits that only change the length must be refused or read the same.
    Binary,
    /// Binary with a checksum: every change must be refused or read the same.
    Checksummed,
    /// Text: a truncation must be refused or read the same.
    Text,
}

/// A reader under test: the outcome of one file's bytes.
type Reader = Box<dyn Fn(&[u8]) -> Outcome>;

struct Target {
    name: &'static str,
    /// The extension of its files in `tests/corpus/`.
    ext: &'static str,
    kind: Kind,
    /// Every byte is needed: a truncated file must be refused.
    whole: bool,
    seeds: Vec<(String, Vec<u8>)>,
    read: Reader,
}

fn hash(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ *b as u64).wrapping_mul(0x0100_0000_01b3))
}

fn corpus_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/corpus")
}

/// The seeds of `tests/corpus/` with extension `ext`, or (`damaged`) the minimised damaged
/// inputs of `tests/corpus/damaged/`, each of which must be refused.
fn corpus_files(ext: &str, damaged: bool) -> Vec<(String, Vec<u8>)> {
    let dir = if damaged { corpus_dir().join("damaged") } else { corpus_dir() };
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == ext))
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect();
    out.sort();
    out
}

fn corpus(ext: &str) -> Vec<(String, Vec<u8>)> {
    corpus_files(ext, false)
}

fn grid() -> GridSpec {
    GridSpec { min: Vec3::new(-1.0, 0.0, -1.0), max: Vec3::new(1.0, 1.0, 1.0), resolution: UVec3::new(20, 9, 11) }
}

fn volumes() -> (Volume, Volume3) {
    let g = grid();
    let n = g.cell_count() as usize;
    let d = Volume::new(g, (0..n).map(|i| if i % 11 < 4 { 0.0 } else { (i % 13) as f32 * 0.3 }).collect());
    let e = Volume3::new(g, (0..n).map(|i| [(i % 5) as f32 * 0.7, (i % 3) as f32, 0.25]).collect());
    (d, e)
}

/// A digest of every grid a VDB holds, or the first error: float grids through the importer,
/// every grid through the farm check.
fn read_vdb(dir: &Path, bytes: &[u8]) -> Outcome {
    let path = dir.join("case.vdb");
    std::fs::write(&path, bytes).unwrap();
    if let FileState::Damaged(why) = file_state(&path) {
        return Outcome::Refused(why);
    }
    let grids = match list_vdb_grids(&path) {
        Ok(g) => g,
        Err(e) => return Outcome::Refused(e.to_string()),
    };
    let mut digest = Vec::new();
    for g in grids.iter().filter(|g| g.importable) {
        match read_vdb_grid_from_bytes(&path, bytes, Some(&g.name)) {
            Ok(grid) => {
                digest.extend(grid.active_voxel_count().to_le_bytes());
                digest.extend((grid.leaf_count() as u64).to_le_bytes());
                if let Some((lo, hi)) = grid.active_bbox() {
                    digest.extend(lo.iter().chain(&hi).flat_map(|c| c.to_le_bytes()));
                    for x in (lo[0]..=hi[0]).step_by(3) {
                        for y in (lo[1]..=hi[1]).step_by(2) {
                            for z in lo[2]..=hi[2] {
                                digest.extend(grid.value_at([x, y, z]).to_bits().to_le_bytes());
                            }
                        }
                    }
                }
                let voxels = grid.metadata.iter().find(|(n, t, _)| n == "file_voxel_count" && t == "int64");
                if let Some(v) = voxels.and_then(|(_, _, v)| <[u8; 8]>::try_from(v.as_slice()).ok()) {
                    if i64::from_le_bytes(v) as u64 != grid.active_voxel_count() {
                        return Outcome::Read(u64::MAX);
                    }
                }
            }
            Err(e) => return Outcome::Refused(e.to_string()),
        }
    }
    Outcome::Read(hash(&digest))
}

fn vdb_target(dir: PathBuf) -> Target {
    let mut seeds = corpus("vdb");
    let (d, e) = volumes();
    let grids = [VdbGrid::from_volume("density", &d), VdbGrid::from_volume3("emission", &e)];
    for compression in [VdbCompression::None, VdbCompression::Zip] {
        for half in [false, true] {
            let opts = VdbOptions { compression, half, ..VdbOptions::default() };
            let (bytes, _) = encode_vdb(Path::new("bake.vdb"), &grids, &opts).unwrap();
            seeds.push((format!("bake-{compression:?}-half-{half}.vdb"), bytes));
        }
    }
    Target {
        name: "vdb",
        ext: "vdb",
        kind: Kind::Binary,
        whole: true,
        seeds,
        read: Box::new(move |b: &[u8]| read_vdb(&dir, b)),
    }
}

/// The farm's structural check of a NanoVDB file (a resume's test for files without a
/// checksum sidecar), on files the writer makes: a damaged file must be told damaged.
fn nvdb_target(dir: PathBuf) -> Target {
    let (d, e) = volumes();
    let grids = [VdbGrid::from_volume("density", &d), VdbGrid::from_volume3("emission", &e)];
    let (bytes, _) =
        fogsmith::export::nanovdb::encode_nanovdb(Path::new("bake.nvdb"), &grids, &VdbOptions::default()).unwrap();
    let (one, _) =
        fogsmith::export::nanovdb::encode_nanovdb(Path::new("fog.nvdb"), &grids[..1], &VdbOptions::default()).unwrap();
    Target {
        seeds: vec![("bake.nvdb".into(), bytes), ("fog.nvdb".into(), one)],
        ..file_state_target("nvdb", "nvdb", dir)
    }
}

fn file_state_target(name: &'static str, ext: &'static str, dir: PathBuf) -> Target {
    let path = dir.join(format!("case.{ext}"));
    Target {
        name,
        ext,
        kind: Kind::Binary,
        whole: true,
        seeds: corpus(ext),
        read: Box::new(move |b: &[u8]| {
            std::fs::write(&path, b).unwrap();
            match file_state(&path) {
                FileState::Damaged(why) => Outcome::Refused(why),
                FileState::Missing => Outcome::Refused("missing".into()),
                FileState::Done => Outcome::Read(0),
            }
        }),
    }
}

fn particles(n: usize) -> Vec<Particle> {
    (0..n)
        .map(|i| {
            let center = Vec3::new((i % 17) as f32 * 0.1 - 0.8, (i % 7) as f32 * 0.1, (i % 5) as f32 * 0.2 - 0.4);
            let mut p = Particle::new(center, 0.05 + (i % 3) as f32 * 0.01, 1.0 + (i % 4) as f32);
            p.id = i as u32;
            p.name = (i % 1000 == 0).then(|| format!("p{i}"));
            p
        })
        .collect()
}

/// Project texts of versions 1 to 4; version 4's sidecar is written into `dir`, where every
/// case is parsed.
fn project_target(dir: PathBuf) -> Target {
    let mut seeds: Vec<(String, Vec<u8>)> = corpus("ron");
    let base = parse_project(std::str::from_utf8(&seeds[0].1).unwrap(), &corpus_dir().join(&seeds[0].0)).unwrap();
    let v3 = to_ron_string(&base).unwrap();
    seeds.push(("v2.ron".into(), v3.replace("version: 3", "version: 2").into_bytes()));
    seeds.push(("v3.ron".into(), v3.into_bytes()));
    let path = dir.join("big.ron");
    let mut big = base.clone();
    big.particles = particles(10_000);
    fogsmith::scene::io::save_project(&path, &big).unwrap();
    seeds.push(("v4.ron".into(), std::fs::read(&path).unwrap()));
    let origin = path.clone();
    Target {
        name: "project",
        ext: "ron",
        kind: Kind::Text,
        whole: false,
        seeds,
        read: Box::new(move |b: &[u8]| {
            let Ok(text) = std::str::from_utf8(b) else { return Outcome::Refused("not UTF-8".into()) };
            match parse_project(text, &origin) {
                Ok(p) => Outcome::Read(hash(to_ron_string(&p).unwrap().as_bytes())),
                Err(e) => Outcome::Refused(e.to_string()),
            }
        }),
    }
}

fn sidecar_target() -> Target {
    let list = particles(10_000);
    let (bytes, crc32) = fogsmith::scene::sidecar::encode(&list);
    let expected = ParticleFile { file: PathBuf::from("p.particles"), count: list.len() as u64, crc32 };
    Target {
        name: "sidecar",
        ext: "particles",
        kind: Kind::Checksummed,
        whole: true,
        seeds: vec![("particles".into(), bytes)],
        read: Box::new(move |b: &[u8]| match decode(b, &expected) {
            Ok(p) => Outcome::Read(hash(format!("{p:?}").as_bytes())),
            Err(e) => Outcome::Refused(e),
        }),
    }
}

fn farm_json_target() -> Target {
    let job = FarmJob {
        name: "shot".into(),
        project: "shot.ron".into(),
        frames: "1-24x2,30,40-48".into(),
        chunk: 4,
        output: "out/fog.####".into(),
        stage: "out/fog.usda".into(),
        memory_mib: 2048,
        cpus: 4,
    };
    Target {
        name: "farm.json",
        ext: "json",
        kind: Kind::Text,
        whole: false,
        seeds: vec![("farm.json".into(), serde_json::to_string_pretty(&job).unwrap().into_bytes())],
        read: Box::new(|b: &[u8]| {
            let job: FarmJob = match serde_json::from_slice(b) {
                Ok(j) => j,
                Err(e) => return Outcome::Refused(e.to_string()),
            };
            let result = job.frame_set().and_then(|set| {
                let chunks = job.chunks()?;
                let files: Vec<_> = set.frames().iter().map(|&f| job.frame_file(f, "vdb")).collect();
                Ok(format!("{chunks:?} {files:?} {:?}", job.task_args(&chunks.join(","))))
            });
            match result {
                Ok(text) => Outcome::Read(hash(text.as_bytes())),
                Err(e) => Outcome::Refused(e),
            }
        }),
    }
}

const U32S: [u32; 12] = [0, 1, 2, 3, 0x7f, 0xff, 0x1_0000, 0x7fff_ffff, 0x8000_0000, 0xffff_ffff, 1 << 28, 4096];
const FLOATS: [f32; 7] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 3.0e38, -1.0, 0.0, 65536.0];
const NUMBERS: [&str; 11] =
    ["NaN", "inf", "-inf", "-1", "0", "1e39", "4294967296", "-2147483649", "99999999999999999999", "0.0", "2147483647"];

/// What an edit did to the file's length.
#[derive(Clone, Copy, PartialEq)]
enum Length {
    Kept,
    Changed,
    Truncated,
}

/// One edit of a binary file.
fn edit_binary(rng: &mut Rng, b: &mut Vec<u8>) -> Length {
    if b.len() < 8 {
        b.push(rng.next() as u8);
        return Length::Changed;
    }
    let len = b.len();
    match rng.below(8) {
        0 => {
            b.truncate(rng.below(len));
            Length::Truncated
        }
        1 | 2 => {
            // A count, size or offset: most are small little-endian integers.
            let small: Vec<usize> = (0..len - 4)
                .filter(|&i| {
                    let v = u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
                    v > 0 && v < 1 << 20
                })
                .collect();
            let at = if small.is_empty() { rng.below(len - 4) } else { *rng.pick(&small) };
            let old = u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
            let value = match rng.below(4) {
                0 => old.wrapping_add(1),
                1 => old.wrapping_sub(1),
                2 => len as u32,
                _ => *rng.pick(&U32S),
            };
            b[at..at + 4].copy_from_slice(&value.to_le_bytes());
            Length::Kept
        }
        3 => {
            let at = rng.below(len / 4 - 1) * 4;
            b[at..at + 4].copy_from_slice(&rng.pick(&FLOATS).to_le_bytes());
            Length::Kept
        }
        4 => {
            let at = rng.below(len);
            b[at] ^= 1 << rng.below(8);
            Length::Kept
        }
        5 => {
            let at = rng.below(len);
            let n = 1 + rng.below(16);
            let bytes: Vec<u8> = (0..n).map(|_| rng.next() as u8).collect();
            b.splice(at..at, bytes);
            Length::Changed
        }
        6 => {
            let at = rng.below(len);
            let n = (1 + rng.below(32)).min(len - at);
            b.drain(at..at + n);
            Length::Changed
        }
        _ => {
            let from = rng.below(len);
            let n = (1 + rng.below(64)).min(len - from);
            let piece = b[from..from + n].to_vec();
            let at = rng.below(len);
            b.splice(at..at, piece);
            Length::Changed
        }
    }
}

/// One edit of text.
fn edit_text(rng: &mut Rng, b: &mut Vec<u8>) -> Length {
    let text = String::from_utf8_lossy(b).into_owned();
    let numbers: Vec<(usize, usize)> = {
        let mut out = Vec::new();
        let bytes = text.as_bytes();
        let mut i = 0;
        while i < bytes.len() {
            if bytes[i].is_ascii_digit() {
                let start = i;
                while i < bytes.len() && (bytes[i].is_ascii_digit() || bytes[i] == b'.' || bytes[i] == b'e') {
                    i += 1;
                }
                out.push((start, i));
            } else {
                i += 1;
            }
        }
        out
    };
    let lines: Vec<(usize, usize)> = {
        let mut out = Vec::new();
        let mut start = 0;
        for (i, c) in text.char_indices() {
            if c == '\n' {
                out.push((start, i + 1));
                start = i + 1;
            }
        }
        out
    };
    let mut truncated = false;
    let new = match rng.below(7) {
        0 if !numbers.is_empty() => {
            let (a, z) = *rng.pick(&numbers);
            format!("{}{}{}", &text[..a], rng.pick(&NUMBERS), &text[z..])
        }
        1 if !lines.is_empty() => {
            let (a, z) = *rng.pick(&lines);
            format!("{}{}", &text[..a], &text[z..])
        }
        2 if !lines.is_empty() => {
            let (a, z) = *rng.pick(&lines);
            format!("{}{}{}", &text[..z], &text[a..z], &text[z..])
        }
        3 => text.replacen(&format!("version: {}", 1 + rng.below(4)), &format!("version: {}", rng.below(7)), 1),
        4 => {
            let at = text.char_indices().map(|(i, _)| i).nth(rng.below(text.chars().count())).unwrap_or(0);
            format!(
                "{}{}{}",
                &text[..at],
                rng.pick(&["(", ")", ",", "[", "]", "\"", ":", "Some(", "{", "}"]),
                &text[at..]
            )
        }
        5 if !numbers.is_empty() => {
            let (a, _) = *rng.pick(&numbers);
            format!("{}{}", &text[..a], &text[a..].replacen(|c: char| c.is_ascii_digit(), "9999999", 1))
        }
        _ => {
            truncated = true;
            let at = text.char_indices().map(|(i, _)| i).nth(rng.below(text.chars().count())).unwrap_or(0);
            text[..at].to_string()
        }
    };
    *b = new.into_bytes();
    if truncated {
        Length::Truncated
    } else {
        Length::Kept
    }
}

fn env(name: &str) -> Option<u64> {
    std::env::var(name).ok().and_then(|v| v.parse().ok())
}

#[test]
fn every_reader_survives_mutated_files() {
    let seed = env("FOGSMITH_FUZZ_SEED").unwrap_or(53);
    let cases = env("FOGSMITH_FUZZ_CASES").unwrap_or(100) as usize;
    let scratch = tempfile::tempdir().unwrap();
    let sub = |n: &str| {
        let d = scratch.path().join(n);
        std::fs::create_dir_all(&d).unwrap();
        d
    };
    let targets = vec![
        vdb_target(sub("vdb")),
        project_target(sub("project")),
        sidecar_target(),
        file_state_target("exr", "exr", sub("exr")),
        file_state_target("ktx2", "ktx2", sub("ktx2")),
        nvdb_target(sub("nvdb")),
        farm_json_target(),
    ];
    let failures_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/fuzz-failures");
    let mut failures = Vec::new();
    let started = std::time::Instant::now();
    for target in &targets {
        assert!(!target.seeds.is_empty(), "{}: no seeds", target.name);
        let mut rng = Rng(fogsmith::rng::XorShiftStar::new(seed ^ hash(target.name.as_bytes())));
        let (mut refused, mut read, mut changed, mut peak) = (0, 0, 0, 0usize);
        let originals: Vec<u64> = target
            .seeds
            .iter()
            .map(|(name, b)| match (target.read)(b) {
                Outcome::Read(d) => d,
                Outcome::Refused(e) => panic!("{}: seed {name} does not read: {e}", target.name),
            })
            .collect();
        for (name, bytes) in corpus_files(target.ext, true) {
            if let Ok(Outcome::Read(_)) = catch_unwind(AssertUnwindSafe(|| (target.read)(&bytes))) {
                failures.push(format!("{}: tests/corpus/damaged/{name} reads", target.name));
            }
        }
        for case in 0..cases {
            let s = rng.below(target.seeds.len());
            let (seed_name, original) = &target.seeds[s];
            let mut bytes = original.clone();
            // Whether the result must be refused or read the same, and whether it must be refused.
            let mut only_truncated = true;
            let mut only_resized = true;
            for _ in 0..1 + rng.below(3) {
                let sized = match target.kind {
                    Kind::Text => edit_text(&mut rng, &mut bytes),
                    _ => edit_binary(&mut rng, &mut bytes),
                };
                only_truncated &= sized == Length::Truncated;
                only_resized &= sized != Length::Kept;
            }
            let strict = match target.kind {
                Kind::Checksummed => true,
                Kind::Binary => only_resized,
                Kind::Text => only_truncated,
            };
            let must_refuse = target.whole && only_truncated;
            if bytes == *original {
                continue;
            }
            let base = LIVE.load(Ordering::Relaxed);
            PEAK.store(base, Ordering::Relaxed);
            let result = catch_unwind(AssertUnwindSafe(|| (target.read)(&bytes)));
            peak = peak.max(PEAK.load(Ordering::Relaxed).saturating_sub(base));
            let problem = match result {
                Err(panic) => {
                    let msg = panic
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()));
                    Some(format!("panicked: {}", msg.unwrap_or_default()))
                }
                Ok(Outcome::Refused(e)) => {
                    refused += 1;
                    (e.contains('\n') || e.is_empty()).then(|| format!("error is not one line: {e:?}"))
                }
                Ok(Outcome::Read(d)) => {
                    read += 1;
                    if d != originals[s] {
                        changed += 1;
                    }
                    if must_refuse {
                        Some("accepted a truncated file".to_string())
                    } else if d == u64::MAX {
                        Some("read a tree that disagrees with its file_voxel_count".to_string())
                    } else if strict && d != originals[s] {
                        Some("accepted a change that reads as a different result".to_string())
                    } else {
                        None
                    }
                }
            };
            if let Some(problem) = problem {
                std::fs::create_dir_all(&failures_dir).unwrap();
                let file = failures_dir.join(format!("{}-seed{seed}-case{case}-{seed_name}", target.name));
                std::fs::write(&file, &bytes).unwrap();
                failures.push(format!(
                    "{} case {case} (from {seed_name}): {problem}; input in {}",
                    target.name,
                    file.display()
                ));
            }
        }
        println!(
            "{:>9}: {cases} cases from {} seeds: {refused} refused, {read} read ({changed} read differently), peak {:.1} MB",
            target.name,
            target.seeds.len(),
            peak as f64 / 1e6
        );
        assert!(peak < 1 << 30, "{}: a case held {peak} bytes", target.name);
    }
    println!("seed {seed}: {:.1} s", started.elapsed().as_secs_f64());
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

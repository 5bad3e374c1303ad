//! Render-farm jobs against the real schedulers: `openjd check` and `openjd run` of the Open
//! Job Description bundle (openjd-cli in the test venv, ./setup.sh), the Slurm job array on a
//! single-node cluster started here (munged, slurmctld, slurmd), each checked bit for bit
//! against a local `fogsmith export --frames`; a task killed halfway and run again; `farm
//! status`; and every refusal, before any job file is written. A missing validator or
//! cluster fails the test: none is skipped.

mod common;

use fogsmith::scene::animation::{Animation, Channel, Interp, Key, KeyValue, Object, Prop, Track};
use fogsmith::scene::{io::save_project, Project};
use glam::Vec3;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

const FRAMES: &str = "1-4";

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_fogsmith")
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A small animated scene: frames 1-4, a light that moves and a particle that grows.
fn animated() -> Project {
    let mut p = common::small_scene(16, &[Vec3::new(1.6, 1.2, 0.5)]);
    p.render.width = 24;
    p.render.height = 16;
    p.ensure_unique_ids();
    p.animation = Some(Animation { fps: 24.0, start: 1, end: 6 });
    let key = |frame, value| Key { frame, value, interp: Interp::Linear };
    let light = p.lights[0].position;
    p.tracks = vec![
        Track {
            on: Channel(Object::Light(p.lights[0].id), Prop::Position),
            keys: vec![key(1, KeyValue::Vec3(light)), key(6, KeyValue::Vec3(light + Vec3::new(-0.8, 0.3, 0.0)))],
        },
        Track {
            on: Channel(Object::Particle(p.particles[0].id), Prop::Radius),
            keys: vec![key(1, KeyValue::Float(0.3)), key(6, KeyValue::Float(0.45))],
        },
    ];
    p
}

fn fogsmith(args: &[&str]) -> Output {
    Command::new(bin()).args(args).output().unwrap()
}

fn ok(out: Output, what: &str) -> Output {
    assert!(
        out.status.success(),
        "{what} failed ({}):\n{}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn openjd() -> PathBuf {
    let path = root().join(".venv/bin/openjd");
    assert!(
        path.exists(),
        "this test needs openjd-cli in the project's test venv ({}), which is missing: run ./setup.sh",
        path.display()
    );
    path
}

/// The project saved in `dir`, and a local export of its frames into `dir/local`.
fn project_and_local_export(dir: &Path) -> (PathBuf, PathBuf) {
    let project = dir.join("shot.ron");
    save_project(&project, &animated()).unwrap();
    let local = dir.join("local");
    std::fs::create_dir(&local).unwrap();
    ok(
        fogsmith(&[
            "export",
            s(&project),
            "--frames",
            FRAMES,
            "--vdb",
            s(&local.join("fog.####.vdb")),
            "--exr-render",
            s(&local.join("fog.####.exr")),
            "--usd",
            s(&local.join("fog.usda")),
            "--quiet",
        ]),
        "local export",
    );
    (project, local)
}

/// Every file of the local export is in `out` with the same bytes.
fn assert_same_files(local: &Path, out: &Path) {
    let mut names: Vec<_> = std::fs::read_dir(local).unwrap().map(|e| e.unwrap().file_name()).collect();
    names.sort();
    assert_eq!(names.len(), 9, "4 VDBs, 4 EXRs and the stage: {names:?}");
    for name in names {
        let (a, b) = (std::fs::read(local.join(&name)).unwrap(), std::fs::read(out.join(&name)));
        let b = b.unwrap_or_else(|e| panic!("{}: {e}", out.join(&name).display()));
        assert!(a == b, "{name:?} differs between the job and a local export --frames {FRAMES}");
    }
}

fn status(bundle: &Path) -> Value {
    let out = ok(fogsmith(&["farm", "status", s(bundle), "--json"]), "farm status");
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The bundle passes `openjd check`, runs with `openjd run` after being moved elsewhere, and
/// writes files equal bit for bit to a local export of the same frames.
#[test]
fn openjd_bundle_checks_and_runs_bit_equal_to_a_local_export() {
    let openjd = openjd();
    let dir = common::temp_dir();
    let (project, local) = project_and_local_export(dir.path());
    let written = dir.path().join("written");
    ok(
        fogsmith(&["farm", "openjd", s(&project), "--frames", FRAMES, "--chunk", "3", "--out", s(&written)]),
        "farm openjd",
    );
    let template = std::fs::read_to_string(written.join("template.yaml")).unwrap();
    assert!(
        template.contains("type: CHUNK[INT]")
            && template.contains("default: \"1-4\"")
            && template.contains("default: 3")
    );
    assert!(!template.contains(s(dir.path())), "the template names no absolute path:\n{template}");
    // The job runs wherever the bundle is copied.
    let bundle = dir.path().join("moved");
    std::fs::rename(&written, &bundle).unwrap();
    ok(Command::new(&openjd).args(["check", s(&bundle.join("template.yaml"))]).output().unwrap(), "openjd check");
    let run = ok(
        Command::new(&openjd)
            .args(["run", s(&bundle.join("template.yaml")), "--step", "WriteStage", "--run-dependencies"])
            .args(["-p", &format!("Fogsmith={}", bin())])
            .output()
            .unwrap(),
        "openjd run",
    );
    let log = String::from_utf8_lossy(&run.stdout);
    // Chunks of 3: frames 1-3 and 4, then the stage.
    assert!(log.contains("Chunks run: 3") || log.matches("Running command").count() == 3, "{log}");
    assert_same_files(&local, &bundle.join("out"));
    let v = status(&bundle);
    assert_eq!(v["done"], serde_json::json!([1, 2, 3, 4]), "{v}");
    assert_eq!(v["stage"], "done", "{v}");

    // Other frame lists, chunk sizes and output spellings pass the check too.
    for (frames, chunk, output) in [("1,3-4", "1", "out/fog_%04d"), ("2-6", "5", "cache/fog.$F4.vdb")] {
        let other = dir.path().join(format!("other-{chunk}"));
        let args = ["farm", "openjd", s(&project), "--frames", frames, "--chunk", chunk, "--output", output];
        ok(fogsmith(&[&args[..], &["--out", s(&other)]].concat()), "farm openjd");
        let check = Command::new(&openjd).args(["check", s(&other.join("template.yaml"))]).output().unwrap();
        ok(check, &format!("openjd check of {args:?}"));
    }
}

/// A task killed halfway leaves complete frames only; `farm status` reports them done and
/// the rest missing, a truncated file damaged; running the task again bakes only the frames
/// that are not complete, and the sequence ends equal to a local export.
#[test]
fn a_killed_task_runs_again_to_a_complete_sequence() {
    let openjd = openjd();
    let dir = common::temp_dir();
    let (project, local) = project_and_local_export(dir.path());
    let bundle = dir.path().join("job");
    ok(
        fogsmith(&["farm", "openjd", s(&project), "--frames", FRAMES, "--chunk", "4", "--out", s(&bundle)]),
        "farm openjd",
    );
    let out = bundle.join("out");
    // The one task's command line, as a user would run it by hand, from the bundle.
    let task = [
        "export",
        "shot.ron",
        "--frames",
        FRAMES,
        "--vdb",
        "out/fog.####.vdb",
        "--exr-render",
        "out/fog.####.exr",
        "--resume",
        "--quiet",
    ];
    let mut child =
        Command::new(bin()).args(task).current_dir(&bundle).stderr(std::process::Stdio::null()).spawn().unwrap();
    let started = Instant::now();
    while !out.join("fog.0001.exr.crc32").exists() {
        assert!(child.try_wait().unwrap().is_none(), "the task ended before it could be killed");
        assert!(started.elapsed() < Duration::from_secs(120), "frame 1 never appeared");
        std::thread::sleep(Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let v = status(&bundle);
    let done: Vec<i64> = v["done"].as_array().unwrap().iter().map(|f| f.as_i64().unwrap()).collect();
    assert!(done.starts_with(&[1]) && done.len() < 4, "{v}");
    assert_eq!(v["damaged"], serde_json::json!([]), "{v}");
    assert_eq!(v["missing"].as_array().unwrap().len(), 4 - done.len(), "{v}");
    assert_eq!(v["stage"], "missing", "{v}");
    let human = String::from_utf8(ok(fogsmith(&["farm", "status", s(&bundle)]), "status").stdout).unwrap();
    assert!(human.contains(&format!("{} done", done.len())) && human.contains("rerun"), "{human}");

    // A truncated frame is damaged, and the rerun replaces it.
    let vdb1 = out.join("fog.0001.vdb");
    let bytes = std::fs::read(&vdb1).unwrap();
    std::fs::write(&vdb1, &bytes[..bytes.len() / 2]).unwrap();
    let v = status(&bundle);
    assert_eq!(v["damaged"][0]["frame"], 1, "{v}");
    assert!(v["damaged"][0]["files"][0].as_str().unwrap().contains("truncated"), "{v}");

    let modified = |f: &i64| std::fs::metadata(out.join(format!("fog.{f:04}.vdb"))).unwrap().modified().unwrap();
    let before: Vec<_> = done[1..].iter().map(modified).collect();
    let rerun =
        ok(Command::new(bin()).args(task).arg("--json").current_dir(&bundle).output().unwrap(), "the task run again");
    let summary: Value = serde_json::from_slice(&rerun.stdout).unwrap();
    let skipped: Vec<i64> = summary["frames"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["skipped"] == true)
        .map(|f| f["frame"].as_i64().unwrap())
        .collect();
    assert_eq!(skipped, done[1..], "the frames complete and untouched: {summary}");
    assert_eq!(done[1..].iter().map(modified).collect::<Vec<_>>(), before);
    // The stage step of the job, through openjd, now only writes the stage.
    ok(
        Command::new(&openjd)
            .args(["run", s(&bundle.join("template.yaml")), "--step", "WriteStage"])
            .args(["-p", &format!("Fogsmith={}", bin())])
            .output()
            .unwrap(),
        "openjd run WriteStage",
    );
    for f in std::fs::read_dir(&out).unwrap() {
        let name = f.unwrap().file_name().into_string().unwrap();
        assert!(!name.contains("partial") && !name.ends_with(".tmp"), "a temporary file was left behind: {name}");
    }
    let v = status(&bundle);
    assert_eq!(v["done"], serde_json::json!([1, 2, 3, 4]), "{v}");
    assert_eq!(v["stage"], "done", "{v}");
    assert_same_files(&local, &out);
}

/// A chunk of 0, frames outside the animation, a still project, an output pattern without a
/// frame number and a missing base volume are each refused with the fix, before anything is
/// written; a present base volume is copied into the bundle and the copy referenced.
/// A project whose particles live in a sidecar file takes its sidecar into the bundle, and the
/// bundle's project loads back with every particle.
#[test]
fn a_bundle_carries_the_particle_sidecar() {
    let dir = common::temp_dir();
    let mut p = animated();
    let template = p.particles[0].clone();
    let n = fogsmith::scene::sidecar::SIDECAR_MIN_PARTICLES;
    p.particles = (0..n)
        .map(|i| {
            let mut q = template.clone();
            q.center += Vec3::new((i % 37) as f32, (i % 11) as f32, (i % 5) as f32) * 0.01;
            q
        })
        .collect();
    p.tracks.retain(|t| !matches!(t.on.0, Object::Particle(_)));
    p.ensure_unique_ids();
    let project = dir.path().join("many.ron");
    save_project(&project, &p).unwrap();
    let out = dir.path().join("job");
    ok(fogsmith(&["farm", "openjd", s(&project), "--frames", FRAMES, "--out", s(&out)]), "farm openjd");
    let sidecars: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".particles"))
        .collect();
    assert_eq!(sidecars.len(), 1, "the bundle holds the sidecar: {sidecars:?}");
    let back = fogsmith::scene::load_project(&out.join("many.ron")).unwrap();
    assert_eq!(back.particles, p.particles);
}

#[test]
fn bad_jobs_are_refused_before_any_file_is_written() {
    let dir = common::temp_dir();
    let project = dir.path().join("shot.ron");
    save_project(&project, &animated()).unwrap();
    let still = dir.path().join("still.ron");
    let mut p = animated();
    p.animation = None;
    p.tracks.clear();
    save_project(&still, &p).unwrap();
    let lost = dir.path().join("lost.ron");
    let mut p = animated();
    p.base_volume =
        Some(fogsmith::scene::BaseVolume { path: "caches/base.vdb".into(), grid: "density".into(), scale: 1.0 });
    save_project(&lost, &p).unwrap();
    let out = dir.path().join("job");
    let cases: [(&Path, &[&str], &str); 6] = [
        (&project, &["--chunk", "0"], "give --chunk 1 or more"),
        (&project, &["--frames", "5-9"], "outside the project's animation range 1-6"),
        (&still, &[], "has no animation"),
        (&project, &["--output", "out/fog"], "put one in the name, e.g. out/fog.####"),
        (&project, &["--output", "/tmp/fog.####"], "give a relative path"),
        (&lost, &[], "base_volume caches/base.vdb does not exist"),
    ];
    for (project, extra, expected) in cases {
        for kind in ["openjd", "slurm"] {
            let mut args = vec!["farm", kind, s(project), "--out", s(&out)];
            if !extra.contains(&"--frames") {
                args.extend(["--frames", FRAMES]);
            }
            args.extend(extra);
            let o = fogsmith(&args);
            let err = String::from_utf8_lossy(&o.stderr);
            assert!(!o.status.success() && err.contains(expected), "{args:?}: expected {expected:?}, got {err}");
            assert!(!err.contains("panicked"), "{err}");
            assert!(!out.exists(), "{args:?} wrote {}", out.display());
        }
    }

    // The base volume goes into the bundle, and the bundle's project names the copy.
    std::fs::create_dir(dir.path().join("caches")).unwrap();
    let grid = animated().grid;
    let base = fogsmith::export::vdb::VdbGrid {
        name: "density".into(),
        spec: grid,
        values: vec![0.5; grid.cell_count() as usize].into(),
        components: 1,
        background: 0.0,
        class: fogsmith::export::vdb::GridClass::FogVolume,
        metadata: Vec::new(),
    };
    let options = fogsmith::export::vdb::VdbOptions::default();
    fogsmith::export::vdb::write_vdb(&dir.path().join("caches/base.vdb"), &[base], &options).unwrap();
    ok(fogsmith(&["farm", "slurm", s(&lost), "--frames", FRAMES, "--out", s(&out)]), "farm slurm with a base volume");
    let copied = fogsmith::scene::load_project(&out.join("lost.ron")).unwrap();
    assert_eq!(copied.base_volume.unwrap().path, Path::new("assets/base.vdb"));
    assert_eq!(
        std::fs::read(out.join("assets/base.vdb")).unwrap(),
        std::fs::read(dir.path().join("caches/base.vdb")).unwrap()
    );
}

/// A single-node Slurm cluster on this machine, in a temporary folder: munged with its own
/// key and socket, slurmctld and slurmd on ports of their own. Stopped when dropped.
struct Cluster {
    dir: tempfile::TempDir,
    conf: PathBuf,
}

fn need(tool: &str) -> PathBuf {
    for dir in ["/usr/sbin", "/usr/bin", "/usr/local/sbin", "/usr/local/bin"] {
        let p = Path::new(dir).join(tool);
        if p.exists() {
            return p;
        }
    }
    panic!("the Slurm test needs {tool}, which is missing: install slurm-wlm and munge (./setup.sh)");
}

fn sh(cmd: &str, env: &[(&str, &Path)]) -> String {
    let mut c = Command::new("bash");
    c.args(["-c", cmd]);
    for (k, v) in env {
        c.env(k, v);
    }
    let o = c.output().unwrap();
    assert!(o.status.success(), "{cmd}: {}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

impl Cluster {
    fn start() -> Cluster {
        let (munged, ctld, slurmd) = (need("munged"), need("slurmctld"), need("slurmd"));
        need("sbatch");
        let dir = common::temp_dir();
        let root = dir.path().to_path_buf();
        let d = root.as_path();
        for sub in ["state", "spool", "log"] {
            std::fs::create_dir(d.join(sub)).unwrap();
        }
        let key: Vec<u8> =
            (0..1024u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8 ^ std::process::id() as u8).collect();
        std::fs::write(d.join("munge.key"), key).unwrap();
        sh(&format!("chmod 400 {}/munge.key", s(d)), &[]);
        let socket = d.join("munge.sock");
        sh(
            &format!(
                "{} --socket={} --key-file={d}/munge.key --pid-file={d}/munged.pid --log-file={d}/munged.log --seed-file={d}/munge.seed --force",
                s(&munged),
                s(&socket),
                d = s(d)
            ),
            &[],
        );
        let host = sh("hostname -s", &[]).trim().to_string();
        let user = sh("id -un", &[]).trim().to_string();
        let cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        let mem = sh("awk '/MemTotal/{print int($2/1024)}' /proc/meminfo", &[]).trim().to_string();
        let port = 20000 + (std::process::id() % 20000) as u16;
        let conf = d.join("slurm.conf");
        let d = s(d);
        std::fs::write(
            &conf,
            format!(
                "ClusterName=fogsmith-test\nSlurmctldHost={host}\nSlurmUser={user}\nSlurmdUser={user}\n\
                 AuthType=auth/munge\nAuthInfo=socket={socket}\nCredType=cred/munge\n\
                 SlurmctldPort={port}\nSlurmdPort={port2}\nStateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
                 SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
                 SlurmctldLogFile={d}/log/slurmctld.log\nSlurmdLogFile={d}/log/slurmd.log\n\
                 ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nJobAcctGatherType=jobacct_gather/none\n\
                 AccountingStorageType=accounting_storage/none\nSelectType=select/cons_tres\n\
                 SelectTypeParameters=CR_Core_Memory\nSchedulerType=sched/builtin\nReturnToService=2\nMpiDefault=none\n\
                 InactiveLimit=0\nMinJobAge=600\n\
                 NodeName={host} CPUs={cpus} RealMemory={mem} State=UNKNOWN\n\
                 PartitionName=test Nodes={host} Default=YES MaxTime=INFINITE State=UP\n",
                socket = s(&socket),
                port2 = port + 1,
            ),
        )
        .unwrap();
        let cluster = Cluster { conf: conf.clone(), dir };
        sh(&format!("{} -f {c} && {} -f {c}", s(&ctld), s(&slurmd), c = s(&conf)), &[]);
        // Up within a minute, or the test fails with the daemons' logs.
        let started = Instant::now();
        loop {
            let o = Command::new("sinfo").args(["-h", "-o", "%t"]).env("SLURM_CONF", &conf).output().unwrap();
            let state = String::from_utf8_lossy(&o.stdout).trim().to_string();
            if o.status.success() && state == "idle" {
                break;
            }
            if started.elapsed() > Duration::from_secs(60) {
                let logs = sh(&format!("tail -n 20 {d}/log/*.log {d}/munged.log"), &[]);
                panic!("the single-node Slurm cluster did not come up within a minute (sinfo: {state:?}):\n{logs}");
            }
            std::thread::sleep(Duration::from_millis(250));
        }
        cluster
    }

    fn job_state(&self, id: &str) -> String {
        let o = Command::new("scontrol").args(["show", "job", id]).env("SLURM_CONF", &self.conf).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout).into_owned();
        text.split_whitespace().find_map(|w| w.strip_prefix("JobState=")).unwrap_or("").to_string()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for daemon in ["slurmd", "slurmctld", "munged"] {
            if let Ok(pid) = std::fs::read_to_string(self.dir.path().join(format!("{daemon}.pid"))) {
                let _ = Command::new("kill").arg(pid.trim()).status();
            }
        }
    }
}

/// The Slurm job array on a single-node cluster: one array task per chunk, a log per task,
/// the stage after the array, and files equal bit for bit to a local export.
#[test]
fn slurm_job_array_runs_bit_equal_to_a_local_export() {
    let cluster = Cluster::start();
    let dir = common::temp_dir();
    let (project, local) = project_and_local_export(dir.path());
    let bundle = dir.path().join("job");
    ok(
        fogsmith(&[
            "farm",
            "slurm",
            s(&project),
            "--frames",
            FRAMES,
            "--chunk",
            "2",
            "--cpus",
            "1",
            "--out",
            s(&bundle),
        ]),
        "farm slurm",
    );
    let script = std::fs::read_to_string(bundle.join("frames.sbatch")).unwrap();
    assert!(script.contains("#SBATCH --array=0-1") && script.contains("CHUNKS=(1-2 3-4)"), "{script}");
    assert!(script.contains("#SBATCH --cpus-per-task=1") && script.contains("#SBATCH --mem="), "{script}");
    let runtime = PathBuf::from(std::env::var_os("XDG_RUNTIME_DIR").unwrap_or_else(|| dir.path().into()));
    let submitted = sh(
        &format!("{}/submit.sh", s(&bundle)),
        &[("SLURM_CONF", &cluster.conf), ("FOGSMITH", Path::new(bin())), ("XDG_RUNTIME_DIR", &runtime)],
    );
    let ids: Vec<&str> =
        submitted.split_whitespace().filter(|w| w.chars().all(|c| c.is_ascii_digit() || c == ';')).collect();
    let [array, stage] = ids[..] else { panic!("submit.sh printed {submitted:?}") };
    let array = array.trim_end_matches(';');
    let stage = stage.trim_end_matches(';');
    let started = Instant::now();
    loop {
        let state = cluster.job_state(stage);
        if state == "COMPLETED" {
            break;
        }
        let logs = || sh(&format!("tail -n 20 {}/logs/*.log || true", s(&bundle)), &[]);
        assert!(
            !["FAILED", "CANCELLED", "TIMEOUT", "OUT_OF_MEMORY"].contains(&state.as_str()),
            "stage job {state}:\n{}",
            logs()
        );
        assert!(
            started.elapsed() < Duration::from_secs(240),
            "the Slurm jobs did not finish (stage {state}):\n{}",
            logs()
        );
        std::thread::sleep(Duration::from_millis(500));
    }
    for k in 0..2 {
        let log = bundle.join(format!("logs/shot-{array}_{k}.log"));
        let text = std::fs::read_to_string(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()));
        assert!(text.contains(&format!("array task {k}: frames {}", ["1-2", "3-4"][k])), "{text}");
    }
    assert_same_files(&local, &bundle.join("out"));
    let v = status(&bundle);
    assert_eq!(v["done"], serde_json::json!([1, 2, 3, 4]), "{v}");
}

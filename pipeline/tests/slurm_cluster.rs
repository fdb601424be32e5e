//! docs/cluster.md on a real one-node Slurm cluster: Debian's slurm-wlm and munge, started as
//! root in a temporary folder by `scripts/slurm/one_node.sh` (munged, slurmctld, slurmd in the
//! background, stopped by their process ids when the test ends, failed or not).
//!
//! - The whole demo pipeline (`mesa demo --scenes 6`) through `scripts/slurm/run_all.sh` with
//!   3-task arrays: assets, lift, retrieve, place, pack, the simulated annotator, ingest, check,
//!   graph, render, tasks, then records, report and release as merge jobs, writes the tree of a
//!   local `mesa run` and `mesa release` byte for byte (job logs, run summaries under
//!   `.mesa/runs/`, the resolved configuration `mesa run` records and the remembered input
//!   digests of `.mesa/digests/`, which hold file identities, are left out).
//! - Preemption: an array task of `render` cancelled (`scancel`) after the first of its scenes,
//!   the chain going on without it, then the same submission again: done scenes are skipped and
//!   the tree is the same.
//! - Requeue: an array task of `render` requeued (`scontrol requeue`, what a preemption does to
//!   a `--requeue` job) after its first scene runs again and skips it.
//!
//! The cancelled stage must still be working on its second scene when the cancel lands (the
//! test polls every 50 ms for the first scene's marker, then cancels): `render` is the slowest
//! stage a scene, and the demo's pictures are drawn at 1536 × 1536 here (in every run, so the
//! trees compare), about 2 s a scene. `lift` (70 ms a scene) finished both scenes first.
//!
//! Without root, slurm-wlm or munge the test says SKIPPED, and fails instead when
//! `MESA_REQUIRE_TOOLS` is set, as in CI (`.ci/run` installs the packages).

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use common::copy_tree;

/// Every stage, in the order `run_all.sh` submits them.
const STAGES: [&str; 14] = [
    "assets", "lift", "retrieve", "place", "pack", "annotate", "ingest", "check", "graph",
    "render", "tasks", "records", "report", "release",
];

fn script(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scripts/slurm")
        .join(name)
}

fn mesa_bin() -> PathBuf {
    assert_cmd::cargo::cargo_bin("mesa")
}

/// A running one-node cluster; dropping it stops the daemons it started, by their pids.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
}

impl Cluster {
    fn start(dir: &Path) -> Result<Self, String> {
        let dir = dir.join("cluster");
        let out = Command::new("bash")
            .arg(script("one_node.sh"))
            .arg("start")
            .arg(&dir)
            .output()
            .map_err(|e| format!("cannot run one_node.sh: {e}"))?;
        let cluster = Self {
            conf: dir.join("slurm.conf"),
            dir,
        };
        if !out.status.success() {
            // Drop stops whatever started.
            return Err(String::from_utf8_lossy(&out.stderr).trim().to_owned());
        }
        Ok(cluster)
    }

    /// A command with this cluster's configuration.
    fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut cmd = Command::new(program);
        cmd.env("SLURM_CONF", &self.conf)
            .env("MESA", mesa_bin())
            .env_remove("SLURM_ARRAY_TASK_ID")
            .env_remove("SLURM_ARRAY_TASK_COUNT")
            .env_remove("SLURM_ARRAY_TASK_MIN")
            .env_remove("SLURM_ARRAY_JOB_ID");
        cmd
    }

    /// Runs `run_all.sh` with small-node resources, 3-task arrays and `extra` flags; its
    /// stdout, and whether it exited 0.
    fn run_all(&self, dataset: &Path, logs: &Path, extra: &[&str]) -> (String, bool) {
        let out = self
            .command("bash")
            .arg(script("run_all.sh"))
            .args(["--cpus", "1", "--mem", "1G", "--time", "00:30:00", "--logs"])
            .arg(logs)
            .args(extra)
            .arg(dataset)
            .arg("3")
            .args(STAGES)
            .output()
            .expect("run_all.sh");
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        eprintln!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
        (stdout, out.status.success())
    }

    /// Waits until none of `jobs` is pending or running.
    fn wait(&self, jobs: &[String]) {
        let started = Instant::now();
        loop {
            let out = self
                .command("squeue")
                .args(["-h", "-o", "%i", "-j"])
                .arg(jobs.join(","))
                .output()
                .expect("squeue");
            if String::from_utf8_lossy(&out.stdout).trim().is_empty() {
                return;
            }
            assert!(
                started.elapsed() < Duration::from_secs(1200),
                "jobs {jobs:?} still queued after 20 minutes"
            );
            std::thread::sleep(Duration::from_millis(500));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let status = Command::new("bash")
            .arg(script("one_node.sh"))
            .arg("stop")
            .arg(&self.dir)
            .status();
        if !matches!(status, Ok(s) if s.success()) {
            eprintln!("stopping the cluster in {} failed", self.dir.display());
        }
    }
}

/// The job ids `run_all.sh` printed, by stage.
fn job_ids(stdout: &str) -> BTreeMap<String, String> {
    stdout
        .lines()
        .filter_map(|l| l.strip_prefix("submitted "))
        .filter_map(|l| {
            let (stage, rest) = l.split_once(": job ")?;
            let job = rest.split(|c: char| !c.is_ascii_digit()).next()?;
            Some((stage.to_owned(), job.to_owned()))
        })
        .collect()
}

/// Every file of a dataset but the run summaries (`.mesa/runs/`), `mesa run`'s record of
/// its configuration and the remembered input digests (`.mesa/digests/`: inodes and times,
/// which differ between copies).
fn tree(dataset: &Path) -> BTreeMap<String, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<String, Vec<u8>>) {
        for entry in std::fs::read_dir(dir).expect("read_dir") {
            let path = entry.expect("entry").path();
            let rel = path
                .strip_prefix(root)
                .expect("prefix")
                .to_string_lossy()
                .into_owned();
            if rel == ".mesa/runs" || rel == ".mesa/digests" || rel == ".mesa/config.resolved.toml"
            {
                continue;
            }
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                out.insert(rel, std::fs::read(&path).expect("read"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dataset, dataset, &mut out);
    out
}

fn differences(a: &BTreeMap<String, Vec<u8>>, b: &BTreeMap<String, Vec<u8>>) -> Vec<String> {
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| match (a.contains_key(k), b.contains_key(k)) {
            (true, true) => format!("{k} differs"),
            (true, false) => format!("{k} only in the first"),
            _ => format!("{k} only in the second"),
        })
        .collect()
}

fn mesa(args: &[&str], dataset: &Path) {
    let out = Command::new(mesa_bin())
        .args(args)
        .arg(dataset)
        .args(if args[0] == "release" {
            vec![dataset.join("release")]
        } else {
            vec![]
        })
        .output()
        .expect("mesa");
    assert!(
        out.status.success(),
        "mesa {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The sorted scene keys `(table_type, scene_id)` of a dataset, as the runner sorts them.
fn scenes(dataset: &Path) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for table in std::fs::read_dir(dataset.join("scenes")).expect("scenes") {
        let table = table.expect("entry").path();
        for scene in std::fs::read_dir(&table).expect("table") {
            let scene = scene.expect("entry").path();
            let name = |p: &Path| p.file_name().expect("name").to_string_lossy().into_owned();
            out.push((name(&table), name(&scene)));
        }
    }
    out.sort();
    out
}

/// The stage whose array task is cancelled and requeued: the slowest a scene.
const CUT: &str = "render";

fn cut_marker(dataset: &Path, (table, id): &(String, String)) -> PathBuf {
    dataset.join(format!(".mesa/markers/{CUT}/{table}/{id}.json"))
}

#[test]
fn the_demo_through_a_real_slurm_cluster_writes_the_tree_of_a_local_run() {
    let dir = tempfile::Builder::new()
        .prefix("mesa-slurm-test")
        .tempdir()
        .expect("tempdir");
    let cluster = match Cluster::start(dir.path()) {
        Ok(cluster) => cluster,
        Err(why) => {
            assert!(
                std::env::var_os("MESA_REQUIRE_TOOLS").is_none(),
                "a one-node Slurm cluster cannot start and MESA_REQUIRE_TOOLS is set: {why}"
            );
            eprintln!("SKIPPED: the Slurm cluster test ({why})");
            return;
        }
    };
    let demo = dir.path().join("demo");
    let out = Command::new(mesa_bin())
        .args(["demo", "--scenes", "6", "--seed", "7", "-q"])
        .arg(&demo)
        .output()
        .expect("mesa demo");
    assert!(out.status.success());
    // Pictures of 1536 × 1536 in every run: render, the stage cut short, takes about 2 s a
    // scene, longer than the cancel takes to land.
    let mut toml = std::fs::read_to_string(demo.join("mesa.toml")).expect("mesa.toml");
    toml.push_str("\n[render]\nwidth_px = 1536\nheight_px = 1536\n");
    std::fs::write(demo.join("mesa.toml"), toml).expect("mesa.toml");

    // The reference: one local run, and the release.
    let started = Instant::now();
    let local = dir.path().join("local");
    copy_tree(&demo, &local);
    mesa(&["run", "--progress", "off"], &local);
    mesa(&["release", "--progress", "off"], &local);
    let expected = tree(&local);
    assert!(expected.contains_key("release/Asset_annotation.json"));
    assert!(expected.contains_key("records/sft.json"));
    assert!(expected.contains_key("assets/index/assets.json"));
    eprintln!("local run: {:.1} s", started.elapsed().as_secs_f64());

    // The whole pipeline through Slurm, 3-task arrays.
    let started = Instant::now();
    let sharded = dir.path().join("slurm");
    copy_tree(&demo, &sharded);
    let logs = dir.path().join("logs");
    let (stdout, ok) = cluster.run_all(&sharded, &logs, &["--wait"]);
    assert!(ok, "{stdout}");
    let jobs = job_ids(&stdout);
    assert_eq!(
        jobs.keys().map(String::as_str).collect::<Vec<_>>().len(),
        STAGES.len(),
        "{stdout}"
    );
    assert!(stdout.contains("follow it:  squeue -j"), "{stdout}");
    // Every assets task indexed a share; one merged the index.
    let assets_logs: Vec<String> = (0..3)
        .map(|k| {
            let log = logs.join(format!("mesa-assets-{}_{k}.out", jobs["assets"]));
            std::fs::read_to_string(&log).unwrap_or_else(|e| panic!("{}: {e}", log.display()))
        })
        .collect();
    for (k, log) in assets_logs.iter().enumerate() {
        assert!(
            log.contains(&format!("assets (shard {k}/3): 15 of 44 GLBs"))
                || log.contains(&format!("assets (shard {k}/3): 14 of 44 GLBs")),
            "{log}"
        );
    }
    assert_eq!(
        assets_logs
            .iter()
            .filter(|l| l.contains("this task merged the index"))
            .count(),
        1,
        "{assets_logs:?}"
    );
    let got = tree(&sharded);
    let diff = differences(&expected, &got);
    assert!(diff.is_empty(), "Slurm run vs local run: {diff:#?}");
    eprintln!(
        "Slurm run of {} stages: {:.1} s",
        STAGES.len(),
        started.elapsed().as_secs_f64()
    );

    // Preemption: render's task 0 is cancelled after the first of its two scenes (the asset
    // index is copied from the local run: the assets array finds every asset unchanged).
    let started = Instant::now();
    let preempted = dir.path().join("preempted");
    copy_tree(&demo, &preempted);
    copy_tree(&local.join("assets/index"), &preempted.join("assets/index"));
    let logs = dir.path().join("logs-preempted");
    let (stdout, ok) = cluster.run_all(&preempted, &logs, &[]);
    assert!(ok, "{stdout}");
    let jobs = job_ids(&stdout);
    let all: Vec<String> = jobs.values().cloned().collect();
    let keys = scenes(&preempted);
    // Task 0 of 3 owns scenes 0 and 3 of the sorted list.
    let (first, second) = (
        cut_marker(&preempted, &keys[0]),
        cut_marker(&preempted, &keys[3]),
    );
    let waited = Instant::now();
    while !first.exists() && !second.exists() {
        assert!(
            waited.elapsed() < Duration::from_secs(600),
            "{CUT}'s task 0 wrote no marker in 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let task = format!("{}_0", jobs[CUT]);
    let out = cluster
        .command("scancel")
        .arg(&task)
        .output()
        .expect("scancel");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Give the cancel time to land, then make sure it did: one of the two scenes is not done.
    cluster.wait(std::slice::from_ref(&jobs[CUT]));
    assert!(
        !(first.exists() && second.exists()),
        "{CUT}'s task 0 finished both scenes before scancel landed"
    );
    cluster.wait(&all);
    // The control: the cancelled task's scene is missing from the tree.
    let partial = tree(&preempted);
    assert!(
        !differences(&expected, &partial).is_empty(),
        "the cancelled task changed nothing"
    );
    // The same submission again: done scenes are skipped, the rest done.
    let logs_again = dir.path().join("logs-resubmitted");
    let (stdout, ok) = cluster.run_all(&preempted, &logs_again, &["--wait"]);
    assert!(ok, "{stdout}");
    let again = job_ids(&stdout);
    let cut_logs: Vec<String> = (0..3)
        .map(|k| {
            std::fs::read_to_string(logs_again.join(format!("mesa-{CUT}-{}_{k}.out", again[CUT])))
                .expect("log")
        })
        .collect();
    assert!(
        cut_logs[0].contains("2 scenes: 1 done, 1 skipped"),
        "{}",
        cut_logs[0]
    );
    for log in &cut_logs[1..] {
        assert!(log.contains("2 scenes: 0 done, 2 skipped"), "{log}");
    }
    let got = tree(&preempted);
    let diff = differences(&expected, &got);
    assert!(
        diff.is_empty(),
        "preempted and resubmitted vs local run: {diff:#?}"
    );
    eprintln!(
        "preemption and resubmission: {:.1} s",
        started.elapsed().as_secs_f64()
    );

    // Requeue (what Slurm does to a preempted task of a `--requeue` job): `scontrol requeue`
    // of render's task 0 after its first scene; the task runs again by itself and skips it.
    // The local run's tree without its pictures is the start.
    let started = Instant::now();
    let requeued = dir.path().join("requeued");
    copy_tree(&local, &requeued);
    std::fs::remove_dir_all(requeued.join(format!(".mesa/markers/{CUT}"))).expect("markers");
    for (table, id) in &keys {
        std::fs::remove_dir_all(requeued.join(format!("scenes/{table}/{id}/render")))
            .expect("pictures");
    }
    let logs = dir.path().join("logs-requeued");
    let out = cluster
        .command("bash")
        .arg(script("run_all.sh"))
        .args(["--cpus", "1", "--mem", "1G", "--time", "00:30:00", "--logs"])
        .arg(&logs)
        .arg(&requeued)
        .args(["3", CUT])
        .output()
        .expect("run_all.sh");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(out.status.success(), "{stdout}");
    let job = job_ids(&stdout)[CUT].clone();
    let (first, second) = (
        cut_marker(&requeued, &keys[0]),
        cut_marker(&requeued, &keys[3]),
    );
    let waited = Instant::now();
    while !first.exists() && !second.exists() {
        assert!(
            waited.elapsed() < Duration::from_secs(600),
            "{CUT}'s task 0 wrote no marker in 10 minutes"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = cluster
        .command("scontrol")
        .args(["requeue", &format!("{job}_0")])
        .output()
        .expect("scontrol");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let caught = !(first.exists() && second.exists());
    cluster.wait(std::slice::from_ref(&job));
    let record: serde_json::Value = serde_json::from_slice(
        &std::fs::read(requeued.join(format!(".mesa/runs/{CUT}/shard-0-of-3.json")))
            .expect("record"),
    )
    .expect("json");
    assert!(
        caught,
        "{CUT}'s task 0 finished both scenes before the requeue landed"
    );
    // The requeued run of task 0 (its record replaced the first run's) skipped the done scene.
    assert_eq!(
        (record["done"].as_u64(), record["skipped"].as_u64()),
        (Some(1), Some(1)),
        "{record}"
    );
    for key in &keys {
        let marker = std::fs::read_to_string(cut_marker(&requeued, key)).expect("marker");
        assert!(marker.contains("\"done\""), "{key:?}: {marker}");
    }
    let pictures = |dataset: &Path| {
        tree(dataset)
            .into_iter()
            .filter(|(k, _)| k.contains("/render/"))
            .collect::<BTreeMap<_, _>>()
    };
    let expected_pictures = pictures(&local);
    assert!(!expected_pictures.is_empty());
    assert!(
        pictures(&requeued) == expected_pictures,
        "requeued pictures differ"
    );
    eprintln!("requeue: {:.1} s", started.elapsed().as_secs_f64());
    drop(cluster);
}

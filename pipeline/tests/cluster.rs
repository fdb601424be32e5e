//! docs/cluster.md, run by hand: the `graph` stage over a dataset as a 3-task Slurm array (the
//! SLURM_ARRAY_* variables set as Slurm sets them) writes exactly the bytes of one run, and a
//! resubmitted array skips everything.

mod common;

use common::{gallery, snapshot};

use std::path::Path;

use assert_cmd::Command;

/// A dataset of 14 scenes whose refined layouts are the published layouts (twice over).
fn dataset(dir: &Path) {
    let tables = ["office_table", "dining_table", "bathroom_vanity"];
    for (k, record) in gallery().iter().cycle().take(14).enumerate() {
        let table = tables[k % tables.len()];
        let scene = dir.join(format!("scenes/{table}/{table}_{k:04}"));
        std::fs::create_dir_all(scene.join("refined")).expect("mkdir");
        Command::cargo_bin("mesa")
            .expect("mesa")
            .args(["convert", "--keep-order", "--to", "dataset", "-o"])
            .arg(scene.join("refined/layout.json"))
            .arg(record)
            .assert()
            .success();
    }
}

fn graph(dir: &Path, slurm: Option<(usize, usize, usize)>) -> String {
    let mut cmd = Command::cargo_bin("mesa").expect("mesa");
    cmd.args(["graph", "--progress", "lines"]).arg(dir);
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_MIN",
    ] {
        cmd.env_remove(var);
    }
    if let Some((id, count, min)) = slurm {
        cmd.env("SLURM_ARRAY_TASK_ID", id.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", count.to_string())
            .env("SLURM_ARRAY_TASK_MIN", min.to_string());
    }
    let out = cmd.output().expect("run");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stderr).expect("utf8")
}

/// N of the summary line `graph (shard i/n): M scenes: N done, ...`.
fn done_count(summary: &str) -> usize {
    summary
        .lines()
        .find(|l| l.starts_with("graph") && l.contains(" done,"))
        .and_then(|l| l.split(" scenes: ").nth(1))
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no done count in {summary}"))
}

#[test]
fn a_slurm_array_writes_the_bytes_of_one_run() {
    let single = tempfile::tempdir().expect("tempdir");
    dataset(single.path());
    let summary = graph(single.path(), None);
    assert!(summary.contains("graph: 14 scenes: 14 done"), "{summary}");
    let expected = snapshot(single.path());
    assert_eq!(
        expected
            .keys()
            .filter(|k| k.ends_with("graph/graph.txt"))
            .count(),
        14
    );

    let sharded = tempfile::tempdir().expect("tempdir");
    dataset(sharded.path());
    // `sbatch --array=1-3`: task ids 1..=3, SLURM_ARRAY_TASK_MIN = 1.
    let mut done = 0;
    for id in 1..=3 {
        let summary = graph(sharded.path(), Some((id, 3, 1)));
        let shard = format!("(shard {}/3)", id - 1);
        assert!(summary.contains(&shard), "{summary}");
        done += done_count(&summary);
    }
    assert_eq!(done, 14, "the three tasks partition the scenes");
    assert!(
        snapshot(sharded.path()) == expected,
        "3 tasks merged differ from one run"
    );

    // A resubmitted array (after a timeout, say) skips what is done.
    let again = graph(sharded.path(), Some((2, 3, 1)));
    assert_eq!(done_count(&again), 0, "{again}");
    assert!(again.contains("5 skipped"), "{again}");
}

/// A message line with a run of spaces inside it (a lost line continuation), if any.
fn spaced_line(text: &str) -> Option<&str> {
    text.lines().find(|l| l.trim_start().contains("  "))
}

/// A library of 13 synthetic GLBs (one of them broken), their annotations and one annotated
/// uid without a GLB: every kind of record the index holds.
fn asset_library(dir: &Path, mug_description: &str) {
    use mesa_stages::assets::synthetic::Mesh;
    let library = dir.join("assets/library");
    std::fs::create_dir_all(&library).expect("mkdir");
    let mut annotations = serde_json::Map::new();
    for k in 0..12 {
        let s = 0.05 + 0.01 * k as f64;
        let (uid, mesh, category) = match k % 3 {
            0 => (
                format!("box_{k:02}"),
                Mesh::cuboid([s, s / 2.0, s * 1.5]),
                "book",
            ),
            1 => (
                format!("mug_{k:02}"),
                Mesh::vessel(s / 2.0, s, 0.004, 0.006),
                "mug",
            ),
            _ => (format!("ball_{k:02}"), Mesh::sphere(s / 2.0, 6, 8), "ball"),
        };
        std::fs::write(library.join(format!("{uid}.glb")), mesh.to_glb(1.0)).expect("write");
        let description = if category == "mug" {
            mug_description.to_owned()
        } else {
            format!("A {category} of {s:.2} m.")
        };
        annotations.insert(
            uid,
            serde_json::json!({"category": category, "description": description}),
        );
    }
    std::fs::write(library.join("broken.glb"), b"glTF not really").expect("write");
    annotations.insert(
        "missing_glb".to_owned(),
        serde_json::json!({"category": "cup", "description": "No file."}),
    );
    std::fs::write(
        dir.join("assets/annotations.json"),
        serde_json::to_vec_pretty(&annotations).expect("json"),
    )
    .expect("write");
}

/// Every file under `assets/` and `.mesa/parts` (none should remain), by path.
fn asset_files(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    let mut out = std::collections::BTreeMap::new();
    for root in ["assets", ".mesa/parts"] {
        let mut stack = vec![dir.join(root)];
        while let Some(folder) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&folder) else {
                continue;
            };
            for entry in entries {
                let path = entry.expect("entry").path();
                if path.is_dir() {
                    stack.push(path);
                } else {
                    let rel = path.strip_prefix(dir).expect("prefix");
                    out.insert(
                        rel.to_string_lossy().into_owned(),
                        std::fs::read(&path).expect("read"),
                    );
                }
            }
        }
    }
    out
}

/// `mesa assets` as Slurm array task `id` of `count` (SLURM_ARRAY_TASK_MIN 1) of array job
/// `job`, or with `--shard` when `job` is None; its stderr.
fn assets_task(dir: &Path, id: usize, count: usize, job: Option<&str>) -> String {
    let mut cmd = Command::cargo_bin("mesa").expect("mesa");
    cmd.args(["assets", "--progress", "off", "--jobs", "1"])
        .arg(dir);
    for var in [
        "SLURM_ARRAY_TASK_ID",
        "SLURM_ARRAY_TASK_COUNT",
        "SLURM_ARRAY_TASK_MIN",
        "SLURM_ARRAY_JOB_ID",
    ] {
        cmd.env_remove(var);
    }
    match job {
        Some(job) => {
            cmd.env("SLURM_ARRAY_TASK_ID", (id + 1).to_string())
                .env("SLURM_ARRAY_TASK_COUNT", count.to_string())
                .env("SLURM_ARRAY_TASK_MIN", "1")
                .env("SLURM_ARRAY_JOB_ID", job);
        }
        None => {
            cmd.arg("--shard").arg(format!("{id}/{count}"));
        }
    }
    let out = cmd.output().expect("run");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    assert_eq!(spaced_line(&stderr), None, "{stderr}");
    stderr
}

#[test]
fn array_tasks_share_the_library_and_the_last_writes_the_index_of_one_task() {
    let one = tempfile::tempdir().expect("tempdir");
    asset_library(one.path(), "A white cup.");
    let out = Command::cargo_bin("mesa")
        .expect("mesa")
        .args(["assets", "--progress", "off"])
        .arg(one.path())
        .env_remove("SLURM_ARRAY_TASK_ID")
        .output()
        .expect("run");
    assert!(out.status.success());
    let expected = asset_files(one.path());
    assert!(expected.contains_key("assets/index/assets.json"));
    assert!(expected.contains_key("assets/index/text.json"));
    assert!(
        expected.keys().filter(|k| k.contains("/shapes/")).count() >= 12,
        "{:?}",
        expected.keys()
    );

    for (count, job) in [(3, Some("41")), (4, None)] {
        let sharded = tempfile::tempdir().expect("tempdir");
        asset_library(sharded.path(), "A white cup.");
        let index = sharded.path().join("assets/index/assets.json");
        // Out of order, as array tasks end: the last to finish merges.
        let order: Vec<usize> = (0..count).rev().collect();
        let mut shares = 0;
        for (k, &id) in order.iter().enumerate() {
            let stderr = assets_task(sharded.path(), id, count, job);
            let share: usize = stderr
                .split(&format!("assets (shard {id}/{count}): "))
                .nth(1)
                .and_then(|rest| rest.split(' ').next())
                .and_then(|n| n.parse().ok())
                .unwrap_or_else(|| panic!("no share in {stderr}"));
            shares += share;
            if k + 1 < count {
                assert!(
                    stderr.contains("the last task to finish merges"),
                    "{stderr}"
                );
                // The control: no index until every part is there.
                assert!(
                    !index.exists(),
                    "task {id} of {count} wrote the index early"
                );
            } else {
                assert!(stderr.contains("this task merged the index"), "{stderr}");
                assert!(stderr.contains("13 GLBs: 12 valid, 1 invalid"), "{stderr}");
            }
        }
        assert_eq!(shares, 13, "the tasks partition the library");
        let got = asset_files(sharded.path());
        assert!(
            got == expected,
            "{count} tasks differ from one: {:?}",
            got.keys()
                .chain(expected.keys())
                .filter(|k| got.get(*k) != expected.get(*k))
                .collect::<Vec<_>>()
        );
    }

    // The control of the comparison: one annotation changed gives other index bytes.
    let other = tempfile::tempdir().expect("tempdir");
    asset_library(other.path(), "A green cup.");
    for id in 0..3 {
        assets_task(other.path(), id, 3, Some("42"));
    }
    let got = asset_files(other.path());
    assert_ne!(
        got.get("assets/index/assets.json"),
        expected.get("assets/index/assets.json")
    );
    assert_ne!(
        got.get("assets/index/text.json"),
        expected.get("assets/index/text.json")
    );
}

#[test]
fn a_resubmitted_assets_array_skips_what_is_indexed_and_merges_only_its_own_parts() {
    let dir = tempfile::tempdir().expect("tempdir");
    asset_library(dir.path(), "A white cup.");
    let index = dir.path().join("assets/index/assets.json");
    // Array job 50: tasks 0 and 1 end, task 2 is cancelled before it ends.
    assets_task(dir.path(), 0, 3, Some("50"));
    assets_task(dir.path(), 1, 3, Some("50"));
    assert!(!index.exists());
    // The resubmitted array (job 51): its task 2 ends first. The parts of job 50 are not this
    // run's: no merge yet.
    let stderr = assets_task(dir.path(), 2, 3, Some("51"));
    assert!(stderr.contains("1 of 3 parts written"), "{stderr}");
    assert!(!index.exists(), "parts of another array job were merged");
    // Tasks 0 and 1 of job 51 keep what job 50 indexed; the last merges.
    let stderr = assets_task(dir.path(), 0, 3, Some("51"));
    assert!(stderr.contains("(0 indexed, 5 unchanged"), "{stderr}");
    let stderr = assets_task(dir.path(), 1, 3, Some("51"));
    assert!(stderr.contains("this task merged the index"), "{stderr}");
    assert!(index.is_file());

    let one = tempfile::tempdir().expect("tempdir");
    asset_library(one.path(), "A white cup.");
    Command::cargo_bin("mesa")
        .expect("mesa")
        .args(["assets", "--progress", "off"])
        .arg(one.path())
        .env_remove("SLURM_ARRAY_TASK_ID")
        .assert()
        .success();
    assert!(asset_files(dir.path()) == asset_files(one.path()));
}

#[test]
fn a_sharded_run_names_the_dataset_stages_it_leaves_out_in_clean_lines() {
    let dir = tempfile::tempdir().expect("tempdir");
    dataset(dir.path());
    std::fs::create_dir_all(dir.path().join("assets/library")).expect("mkdir");
    let out = Command::cargo_bin("mesa")
        .expect("mesa")
        .args(["run", "--progress", "off", "--shard", "0/2"])
        .arg(dir.path())
        .output()
        .expect("run");
    let stderr = String::from_utf8_lossy(&out.stderr);
    for stage in ["assets", "records", "report"] {
        assert!(
            stderr.contains(&format!("{stage}: not run by a shard")),
            "{stage}: {stderr}"
        );
    }
    assert!(stderr.contains("once before the shards"), "{stderr}");
    assert!(stderr.contains("once every shard is done"), "{stderr}");
    let leftover = stderr
        .lines()
        .filter(|l| l.contains("not run by a shard"))
        .find(|l| l.contains("  "));
    assert_eq!(leftover, None, "{stderr}");
}

/// `scripts/slurm/run_all.sh --dry-run` with `args`, the environment `env` (and no other
/// MESA_SLURM_* variable): its stdout and stderr, and whether it exited 0.
fn run_all_dry(args: &[&str], env: &[(&str, &str)]) -> (String, String, bool) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scripts/slurm/run_all.sh");
    let mut cmd = std::process::Command::new("bash");
    cmd.arg(script).arg("--dry-run").args(args);
    for var in [
        "MESA_SLURM_CPUS",
        "MESA_SLURM_MEM",
        "MESA_SLURM_TIME",
        "MESA_SLURM_PARTITION",
        "MESA_SLURM_ACCOUNT",
        "MESA_SLURM_SBATCH",
        "MESA_SLURM_LOGS",
        "MESA_RELEASE_OUT",
    ] {
        cmd.env_remove(var);
    }
    cmd.envs(env.iter().copied());
    let out = cmd.output().expect("bash");
    (
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
        out.status.success(),
    )
}

#[test]
fn run_all_takes_resources_from_flags_then_the_environment_with_small_node_defaults() {
    let dir = tempfile::tempdir().expect("tempdir");
    let dataset = dir.path().to_str().expect("utf8").to_owned();
    // Defaults: one CPU, 2 GB, two hours; no partition or account.
    let (out, err, ok) = run_all_dry(&[&dataset, "3", "assets", "lift", "release"], &[]);
    assert!(ok, "{err}");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), 3, "{out}");
    for line in &lines {
        assert!(
            line.contains("--cpus-per-task=1 --mem=2G --time=02:00:00"),
            "{line}"
        );
        assert!(
            !line.contains("--partition") && !line.contains("--account"),
            "{line}"
        );
    }
    assert!(lines[0].contains("--array=0-2") && lines[0].ends_with(&format!("assets {dataset}")));
    assert!(lines[1].contains("--dependency=afterany:"), "{}", lines[1]);
    // release gets its required output folder, and is one task.
    assert!(!lines[2].contains("--array"), "{}", lines[2]);
    assert!(
        lines[2].ends_with(&format!("release {dataset} {dataset}/release")),
        "{}",
        lines[2]
    );

    // The environment, and flags over it.
    let env = [
        ("MESA_SLURM_CPUS", "8"),
        ("MESA_SLURM_MEM", "3G"),
        ("MESA_SLURM_PARTITION", "small"),
        ("MESA_SLURM_ACCOUNT", "lab"),
        ("MESA_SLURM_SBATCH", "--qos=low --exclusive"),
        ("MESA_RELEASE_OUT", "/elsewhere"),
    ];
    let (out, err, ok) = run_all_dry(
        &[
            "--cpus", "2", "--time", "0:10:00", &dataset, "4", "lift", "release",
        ],
        &env,
    );
    assert!(ok, "{err}");
    for line in out.lines() {
        assert!(
            line.contains(
                "--cpus-per-task=2 --mem=3G --time=0:10:00 --partition=small --account=lab \
                 --qos=low --exclusive"
            ),
            "{line}"
        );
    }
    assert!(out.contains("--array=0-3"), "{out}");
    assert!(
        out.contains(&format!("release {dataset} /elsewhere")),
        "{out}"
    );

    // Clear errors, exit code 2.
    for (args, message) in [
        (
            vec!["--cpus", "0", dataset.as_str(), "3", "lift"],
            "--cpus \"0\" is not a positive number",
        ),
        (
            vec![dataset.as_str(), "3", "lfit"],
            "unknown stage \"lfit\"",
        ),
        (
            vec!["--memory", "1G", dataset.as_str(), "3", "lift"],
            "unknown option --memory",
        ),
        (
            vec!["/no/such/dataset", "3", "lift"],
            "/no/such/dataset: no such dataset folder",
        ),
    ] {
        let (out, err, ok) = run_all_dry(&args, &[]);
        assert!(!ok && out.is_empty(), "{args:?}: {out}");
        assert!(err.contains(message), "{args:?}: {err}");
    }
}

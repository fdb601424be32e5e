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

#[test]
fn array_tasks_other_than_0_leave_the_library_to_task_0_saying_so_in_one_clean_line() {
    let dir = tempfile::tempdir().expect("tempdir");
    std::fs::create_dir_all(dir.path().join("assets/library")).expect("mkdir");
    let assets = |id: usize| {
        Command::cargo_bin("mesa")
            .expect("mesa")
            .args(["assets", "--progress", "off"])
            .arg(dir.path())
            .env("SLURM_ARRAY_TASK_ID", id.to_string())
            .env("SLURM_ARRAY_TASK_COUNT", "3")
            .env("SLURM_ARRAY_TASK_MIN", "0")
            .output()
            .expect("run")
    };
    let index = dir.path().join("assets/index/assets.json");
    let out = assets(2);
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("indexed by array task 0 (this is task 2/3): nothing to do here"),
        "{stderr}"
    );
    assert_eq!(spaced_line(&stderr), None, "{stderr}");
    assert!(!index.exists(), "task 2 must not index the library");
    // The control: task 0 indexes it.
    let out = assets(0);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(index.is_file(), "task 0 indexes the library");
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

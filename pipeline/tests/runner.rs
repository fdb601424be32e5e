//! The runner's guarantees, with a small test stage over generated scenes: skip-done, redo on
//! change, failures that leave nothing behind, SIGKILL then resume, and byte-identical outputs
//! for any thread count or shard split.

mod common;

use common::{dead_pid, snapshot};

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use mesa_pipeline::config::{Config, ProgressMode};
use mesa_pipeline::runner::{
    run_stage, RunOptions, Scene, SceneOutput, SceneStage, Shard, StageContext,
};

/// Upper-cases `input/data.txt` into three files; fails on "FAIL", panics on "PANIC".
struct Echo {
    delay: Duration,
}

impl SceneStage for Echo {
    fn name(&self) -> &'static str {
        "echo"
    }

    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        Ok(vec![scene.rel("input/data.txt")])
    }

    fn config_digest(&self, ctx: &StageContext<'_>) -> String {
        mesa_pipeline::runner::digest_of(&ctx.config.run.seed)
    }

    fn run(&self, ctx: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let text = std::fs::read_to_string(scene.path("input/data.txt"))?;
        anyhow::ensure!(!text.contains("FAIL"), "input/data.txt asks to fail");
        assert!(!text.contains("PANIC"), "input/data.txt asks to panic");
        let mut out = SceneOutput::new();
        // Files large enough that a kill can land mid-write.
        let body = text.to_uppercase().repeat(2000);
        out.add_file("echo/a.txt", body.clone().into_bytes());
        std::thread::sleep(self.delay);
        out.add_file(
            "echo/b.txt",
            format!("{}{body}", ctx.config.run.seed).into_bytes(),
        );
        out.add_json("echo/c.json", &BTreeMap::from([("scene", scene.key())]))?;
        Ok(out)
    }
}

fn make_dataset(dir: &Path, scenes: usize) {
    let tables = ["office_table", "dining_table", "coffee_table"];
    for k in 0..scenes {
        let table = tables[k % tables.len()];
        let scene = dir.join(format!("scenes/{table}/{table}_{k:04}/input"));
        std::fs::create_dir_all(&scene).expect("mkdir");
        std::fs::write(scene.join("data.txt"), format!("scene {k}\n")).expect("write");
    }
}

fn options(jobs: usize) -> RunOptions {
    RunOptions {
        jobs,
        progress: ProgressMode::Off,
        ..RunOptions::from_config(&Config::default())
    }
}

fn run(dir: &Path, config: &Config, options: &RunOptions) -> mesa_pipeline::runner::StageSummary {
    let ctx = StageContext {
        dataset: dir,
        config,
    };
    run_stage(
        &Echo {
            delay: Duration::ZERO,
        },
        &ctx,
        options,
    )
    .expect("run")
}

fn reference(scenes: usize) -> (tempfile::TempDir, BTreeMap<String, Vec<u8>>) {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), scenes);
    let summary = run(dir.path(), &Config::default(), &options(1));
    assert_eq!(summary.done, scenes);
    let snap = snapshot(dir.path());
    (dir, snap)
}

/// Writes the first line of `input/big.txt` (a large input) to `head/line.txt`.
struct Head;

impl SceneStage for Head {
    fn name(&self) -> &'static str {
        "head"
    }

    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        Ok(vec![scene.rel("input/big.txt")])
    }

    fn config_digest(&self, _: &StageContext<'_>) -> String {
        String::new()
    }

    fn run(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        let text = std::fs::read_to_string(scene.path("input/big.txt"))?;
        let mut out = SceneOutput::new();
        out.add_file("head/line.txt", text.lines().next().unwrap_or("").into());
        Ok(out)
    }
}

#[test]
fn a_large_input_is_hashed_again_only_when_its_identity_changed() {
    use mesa_pipeline::runner::digests::{REMEMBER_FROM_BYTES, SETTLED_AFTER};
    use sha2::Digest as _;
    let sha = |bytes: &[u8]| format!("{:x}", sha2::Sha256::digest(bytes));
    let dir = tempfile::tempdir().expect("tempdir");
    let rel = "scenes/dining_table/dining_table_0000/input/big.txt";
    let input = dir.path().join(rel);
    std::fs::create_dir_all(input.parent().expect("parent")).expect("mkdir");
    let text = "abc\n".repeat(100_000);
    assert!(text.len() as u64 >= REMEMBER_FROM_BYTES);
    std::fs::write(&input, &text).expect("write");
    // Only a file that last changed SETTLED_AFTER ago is remembered.
    std::thread::sleep(SETTLED_AFTER + Duration::from_millis(300));
    let config = Config::default();
    let ctx = StageContext {
        dataset: dir.path(),
        config: &config,
    };
    let run = || run_stage(&Head, &ctx, &options(1)).expect("run");
    let marker_digest = || -> String {
        let marker: serde_json::Value = common::read_json(
            &dir.path()
                .join(".mesa/markers/head/dining_table/dining_table_0000.json"),
        );
        marker["inputs"][rel].as_str().expect("digest").to_owned()
    };
    let remembered = dir
        .path()
        .join(".mesa/digests/head/dining_table/dining_table_0000.txt");
    assert_eq!(run().done, 1);
    let saved = std::fs::read_to_string(&remembered).expect("remembered");
    assert!(saved.contains(&sha(text.as_bytes())), "{saved}");
    assert_eq!(marker_digest(), sha(text.as_bytes()));
    assert_eq!(run().skipped, 1);

    // The remembered digest is the one used: a forged one makes the scene stale (and is what
    // the marker then records), and without the file the truth is hashed again.
    let forged = "ab".repeat(32);
    std::fs::write(&remembered, saved.replace(&sha(text.as_bytes()), &forged)).expect("forge");
    assert_eq!(run().done, 1);
    assert_eq!(marker_digest(), forged);
    std::fs::remove_file(&remembered).expect("rm");
    assert_eq!(run().done, 1);
    assert_eq!(marker_digest(), sha(text.as_bytes()));
    assert_eq!(run().skipped, 1);

    // Other bytes written in place, the size and modification time kept: a new ctime, so the
    // file is hashed again and the scene redone.
    let before = std::fs::metadata(&input).expect("meta");
    let edited = "abd\n".repeat(100_000);
    std::fs::write(&input, &edited).expect("edit");
    std::fs::File::options()
        .write(true)
        .open(&input)
        .and_then(|f| f.set_modified(before.modified().expect("mtime")))
        .expect("set mtime");
    let after = std::fs::metadata(&input).expect("meta");
    {
        use std::os::unix::fs::MetadataExt as _;
        assert_eq!(
            (after.ino(), after.len(), after.modified().expect("mtime")),
            (
                before.ino(),
                before.len(),
                before.modified().expect("mtime")
            )
        );
    }
    let redone = run();
    assert_eq!((redone.done, redone.skipped), (1, 0));
    assert_eq!(marker_digest(), sha(edited.as_bytes()));
    let line = dir
        .path()
        .join("scenes/dining_table/dining_table_0000/head/line.txt");
    assert_eq!(std::fs::read_to_string(line).expect("redone"), "abd");
}

/// A line of a remembered-digests file: `first` (a digest, `digest:fingerprint` or `swept`),
/// then the identity `path` has now, then `rel`.
fn memo_line(first: &str, path: &Path, rel: &str) -> String {
    use std::os::unix::fs::MetadataExt as _;
    let m = std::fs::metadata(path).expect("stat");
    format!(
        "{first} {} {} {} {}.{:09} {}.{:09} {rel}",
        m.dev(),
        m.ino(),
        m.size(),
        m.mtime(),
        m.mtime_nsec(),
        m.ctime(),
        m.ctime_nsec()
    )
}

#[test]
fn a_forced_rerun_takes_small_inputs_and_kept_outputs_from_the_remembered_digests() {
    use mesa_pipeline::runner::digests::SETTLED_AFTER;
    use sha2::Digest as _;
    let sha = |bytes: &[u8]| format!("{:x}", sha2::Sha256::digest(bytes));
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 1);
    let scene = "scenes/office_table/office_table_0000";
    let (input, output) = (
        format!("{scene}/input/data.txt"),
        format!("{scene}/echo/a.txt"),
    );
    let config = Config::default();
    let forced = RunOptions {
        force: true,
        ..options(1)
    };
    let marker = || -> serde_json::Value {
        common::read_json(
            &dir.path()
                .join(".mesa/markers/echo/office_table/office_table_0000.json"),
        )
    };
    let digest = |kind: &str, rel: &str| marker()[kind][rel].as_str().expect("d").to_owned();
    let remembered = dir
        .path()
        .join(".mesa/digests/echo/office_table/office_table_0000.txt");
    let truth = |rel: &str| sha(&std::fs::read(dir.path().join(rel)).expect("read"));

    // A first run writes no digests file for small files (it would cost more than it saves).
    assert_eq!(run(dir.path(), &config, &options(1)).done, 1);
    assert!(!remembered.exists(), "a first run remembers no small file");
    let (truth_in, truth_out) = (truth(&input), truth(&output));
    // A forced rerun within SETTLED_AFTER of the writes remembers nothing either.
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert!(
        !remembered.exists(),
        "files written a moment ago are not remembered"
    );

    // Once the files have settled, a rerun with nothing to do still writes no digests file
    // (a skipped scene costs what it did), and a forced rerun remembers the small input and
    // the outputs that came out the same (all three of them).
    std::thread::sleep(SETTLED_AFTER + Duration::from_millis(300));
    assert_eq!(run(dir.path(), &config, &options(1)).skipped, 1);
    assert!(
        !remembered.exists(),
        "a skipped scene remembers no small file"
    );
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let saved = std::fs::read_to_string(&remembered).expect("remembered");
    // The header, the input, the three outputs and their folder, found clean.
    assert_eq!(saved.lines().count(), 6, "{saved}");
    assert!(saved.contains(&format!(" {scene}/echo/\n")), "{saved}");
    // Each digest with the fingerprint of the bytes read (module docs of runner::digests).
    assert!(saved.contains(&format!("{truth_in}:")), "{saved}");
    assert!(saved.contains(&format!("{truth_out}:")), "{saved}");
    assert_eq!(
        (digest("inputs", &input), digest("outputs", &output)),
        (truth_in.clone(), truth_out.clone())
    );

    // The remembered digests are the ones used: forged, they are what the next forced rerun's
    // marker records (the files unread by the hash).
    let (forged_in, forged_out) = ("ab".repeat(32), "cd".repeat(32));
    let forged = saved
        .replace(&truth_in, &forged_in)
        .replace(&truth_out, &forged_out);
    std::fs::write(&remembered, &forged).expect("forge");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert_eq!(
        (digest("inputs", &input), digest("outputs", &output)),
        (forged_in.clone(), forged_out.clone())
    );

    // Control: the same bytes written again in place (a new ctime) are hashed again, input
    // and output alike, and the truth comes back.
    for rel in [&input, &output] {
        let path = dir.path().join(rel);
        let bytes = std::fs::read(&path).expect("read");
        std::fs::write(&path, bytes).expect("rewrite");
    }
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert_eq!(
        (digest("inputs", &input), digest("outputs", &output)),
        (truth_in, truth_out)
    );
    let now = std::fs::read_to_string(&remembered).unwrap_or_default();
    assert!(
        !now.contains(&forged_in) && !now.contains(&forged_out),
        "{now}"
    );

    // An output folder remembered clean is not listed again while its identity holds: a dead
    // writer's leftover put there, with the folder's entry forged to its identity since, stays.
    let folder = dir.path().join(scene).join("echo");
    let leftover = folder.join(format!(".a.txt.mesa-tmp-{}-0", dead_pid()));
    std::fs::write(&leftover, b"a killed run's half").expect("leftover");
    let folder_line = |path: &Path| memo_line("swept", path, &format!("{scene}/echo/"));
    let text = std::fs::read_to_string(&remembered).expect("remembered");
    let old = text
        .lines()
        .find(|line| line.starts_with("swept "))
        .expect("the folder is remembered")
        .to_owned();
    std::fs::write(&remembered, text.replace(&old, &folder_line(&folder))).expect("forge");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert!(leftover.exists(), "an unchanged folder is not listed");

    // Control: any entry made or removed in the folder changes its identity, and the next
    // forced run lists it and sweeps the leftover.
    let other = folder.join("other");
    std::fs::write(&other, b"x").expect("other");
    std::fs::remove_file(&other).expect("rm");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert!(!leftover.exists(), "a changed folder is swept");

    // A folder left unlisted stays remembered while nothing is written in it, and is forgotten
    // once this run writes in it (an input edited, so the outputs change): the write outdated
    // the identity remembered.
    let forged = format!("mesa.digests/1\n{}\n", folder_line(&folder));
    std::fs::write(&remembered, &forged).expect("forge");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let kept = std::fs::read_to_string(&remembered).expect("remembered");
    assert!(kept.contains(&folder_line(&folder)), "{kept}");
    std::fs::write(dir.path().join(&input), "edited\n").expect("edit");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let now = std::fs::read_to_string(&remembered).unwrap_or_default();
    assert!(!now.contains("swept "), "{now}");
}

#[test]
fn a_forced_rerun_leaves_an_output_unread_while_its_identity_and_fingerprint_hold() {
    use mesa_pipeline::runner::digests::SETTLED_AFTER;
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 1);
    let scene = "scenes/office_table/office_table_0000";
    let output = format!("{scene}/echo/a.txt");
    let path = dir.path().join(&output);
    let config = Config::default();
    let forced = RunOptions {
        force: true,
        ..options(1)
    };
    let remembered = dir
        .path()
        .join(".mesa/digests/echo/office_table/office_table_0000.txt");
    let line_of = |text: &str| -> String {
        text.lines()
            .find(|line| line.ends_with(&format!(" {output}")))
            .expect("the output is remembered")
            .to_owned()
    };
    // The output's line with its identity fields replaced by those the file has now.
    let identity_now = |line: &str| -> String {
        memo_line(line.split(' ').next().expect("digest"), &path, &output)
    };

    assert_eq!(run(dir.path(), &config, &options(1)).done, 1);
    std::thread::sleep(SETTLED_AFTER + Duration::from_millis(300));
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let text = std::fs::read_to_string(&remembered).expect("remembered");
    let line = line_of(&text);
    let truth = std::fs::read(&path).expect("output");
    // Remembered with its fingerprint: the digest, a colon and 32 hex digits.
    let first = line.split(' ').next().expect("digest").to_owned();
    assert!(
        first.len() == 64 + 1 + 32 && first.as_bytes()[64] == b':',
        "{line}"
    );

    // The file changed behind the runner's back (same length), and its entry forged to the
    // new identity with the old fingerprint: a forced rerun trusts the entry and leaves the
    // file unread, so the change stays (what shows that it was not read).
    let altered: Vec<u8> = truth.iter().map(|b| b.to_ascii_lowercase()).collect();
    assert_ne!(altered, truth);
    std::fs::write(&path, &altered).expect("alter");
    std::fs::write(&remembered, text.replace(&line, &identity_now(&line))).expect("forge");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert_eq!(
        std::fs::read(&path).expect("output"),
        altered,
        "left unread"
    );

    // Control: the same forged identity with another fingerprint makes the runner read the
    // file, see that it differs from the new bytes, and write them.
    let text = std::fs::read_to_string(&remembered).expect("remembered");
    let line = line_of(&text);
    let (digest, _) = first.split_once(':').expect("colon");
    let other = identity_now(&line).replacen(&first, &format!("{digest}:{}", "0".repeat(32)), 1);
    std::fs::write(&remembered, text.replace(&line, &other)).expect("forge");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert_eq!(std::fs::read(&path).expect("output"), truth, "rewritten");

    // Control: without any forging, an output changed in place (a new identity) is read,
    // compared and rewritten.
    std::thread::sleep(SETTLED_AFTER + Duration::from_millis(300));
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    std::fs::write(&path, &altered).expect("alter");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    assert_eq!(std::fs::read(&path).expect("output"), truth, "rewritten");

    // Entries without fingerprints (as an earlier version wrote them) get them back when their
    // files are read with the identities remembered.
    std::thread::sleep(SETTLED_AFTER + Duration::from_millis(300));
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let text = std::fs::read_to_string(&remembered).expect("remembered");
    let stripped: String = text
        .lines()
        .map(|line| match line.split_once(' ') {
            Some((first, rest)) => {
                let digest = first.split(':').next().expect("digest");
                format!("{digest} {rest}\n")
            }
            None => format!("{line}\n"),
        })
        .collect();
    assert!(!stripped.contains(':'), "{stripped}");
    std::fs::write(&remembered, &stripped).expect("strip");
    assert_eq!(run(dir.path(), &config, &forced).done, 1);
    let again = std::fs::read_to_string(&remembered).expect("remembered");
    assert_eq!(line_of(&again), line_of(&text), "{again}");
}

#[test]
fn a_second_run_skips_everything_and_an_edit_redoes_exactly_that_scene() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 12);
    let config = Config::default();
    let first = run(dir.path(), &config, &options(2));
    assert_eq!((first.done, first.skipped, first.failed.len()), (12, 0, 0));
    let second = run(dir.path(), &config, &options(2));
    assert_eq!((second.done, second.skipped), (0, 12));

    let edited = dir
        .path()
        .join("scenes/dining_table/dining_table_0004/input/data.txt");
    std::fs::write(&edited, "edited\n").expect("edit");
    let third = run(dir.path(), &config, &options(2));
    assert_eq!((third.done, third.skipped), (1, 11));
    let out = std::fs::read_to_string(
        dir.path()
            .join("scenes/dining_table/dining_table_0004/echo/a.txt"),
    )
    .expect("redone");
    assert!(out.starts_with("EDITED"));

    // A deleted output is noticed and rewritten.
    std::fs::remove_file(
        dir.path()
            .join("scenes/office_table/office_table_0000/echo/b.txt"),
    )
    .expect("rm");
    let fourth = run(dir.path(), &config, &options(1));
    assert_eq!((fourth.done, fourth.skipped), (1, 11));

    // A configuration change redoes everything; --force too.
    let mut seeded = Config::default();
    seeded.run.seed = 7;
    assert_eq!(run(dir.path(), &seeded, &options(2)).done, 12);
    let forced = RunOptions {
        force: true,
        ..options(2)
    };
    assert_eq!(run(dir.path(), &seeded, &forced).done, 12);
}

#[test]
fn a_failing_scene_leaves_no_output_and_does_not_stop_the_others() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 9);
    let config = Config::default();
    assert_eq!(run(dir.path(), &config, &options(2)).done, 9);
    let bad = dir.path().join("scenes/coffee_table/coffee_table_0002");
    let panicky = dir.path().join("scenes/office_table/office_table_0003");
    std::fs::write(bad.join("input/data.txt"), "FAIL\n").expect("edit");
    std::fs::write(panicky.join("input/data.txt"), "PANIC\n").expect("edit");
    let summary = run(dir.path(), &config, &options(2));
    assert_eq!((summary.done, summary.skipped), (0, 7));
    assert_eq!(summary.failed.len(), 2);
    let (scene, chain) = &summary.failed[0];
    assert_eq!(scene, "coffee_table/coffee_table_0002");
    assert_eq!(chain, &vec!["input/data.txt asks to fail".to_owned()]);
    assert!(summary.failed[1].1[0].starts_with("internal error: input/data.txt asks to panic"));
    // Nothing of the earlier success is left to be mistaken for current output.
    assert_eq!(std::fs::read_dir(bad.join("echo")).expect("dir").count(), 0);
    assert!(!panicky.join("echo/a.txt").exists());
    let marker: serde_json::Value = serde_json::from_slice(
        &std::fs::read(
            dir.path()
                .join(".mesa/markers/echo/coffee_table/coffee_table_0002.json"),
        )
        .expect("failed marker"),
    )
    .expect("json");
    assert_eq!(marker["status"], "failed");
    assert_eq!(marker["error"][0], "input/data.txt asks to fail");
    // A failed scene is retried, and succeeds once its input is fixed.
    std::fs::write(bad.join("input/data.txt"), "fixed\n").expect("fix");
    let again = run(dir.path(), &config, &options(2));
    assert_eq!((again.done, again.failed.len()), (1, 1));
}

#[test]
fn a_missing_input_fails_that_scene_with_the_path() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 3);
    std::fs::remove_file(
        dir.path()
            .join("scenes/dining_table/dining_table_0001/input/data.txt"),
    )
    .expect("rm");
    let summary = run(dir.path(), &Config::default(), &options(1));
    assert_eq!(summary.done, 2);
    assert_eq!(summary.failed.len(), 1);
    let message = &summary.failed[0].1[0];
    assert!(
        message.contains("dining_table_0001/input/data.txt: missing input of `mesa echo`"),
        "{message}"
    );
}

#[test]
fn thread_counts_and_shard_splits_give_identical_bytes() {
    let scenes = 20;
    let (_ref_dir, expected) = reference(scenes);
    for jobs in [2, 4] {
        let dir = tempfile::tempdir().expect("tempdir");
        make_dataset(dir.path(), scenes);
        run(dir.path(), &Config::default(), &options(jobs));
        assert!(snapshot(dir.path()) == expected, "{jobs} threads differ");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), scenes);
    let mut processed = 0;
    for index in 0..3 {
        let sharded = RunOptions {
            shard: Shard { index, count: 3 },
            ..options(2)
        };
        let summary = run(dir.path(), &Config::default(), &sharded);
        processed += summary.done;
    }
    assert_eq!(processed, scenes, "the shards partition the scenes");
    assert!(
        snapshot(dir.path()) == expected,
        "3 shards merged differ from 1"
    );
}

#[test]
fn globs_select_by_table_type_or_scene_id() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 9);
    let only = |glob: &str| RunOptions {
        scenes: Some(glob.to_owned()),
        ..options(1)
    };
    assert_eq!(
        run(dir.path(), &Config::default(), &only("office_table/*")).done,
        3
    );
    // Scenes 0000-0004; the office tables among them (0000, 0003) are already done.
    let by_id = run(dir.path(), &Config::default(), &only("*_000[0-4]"));
    assert_eq!((by_id.scenes, by_id.done, by_id.skipped), (5, 3, 2));
}

/// The child side of the kill test: runs the echo stage slowly over the dataset in
/// `MESA_KILL_CHILD`. Does nothing in a normal test run.
#[test]
#[ignore = "run by kill_then_resume_is_byte_identical as a child process"]
fn kill_child() {
    let Some(dir) = std::env::var_os("MESA_KILL_CHILD") else {
        return;
    };
    let config = Config::default();
    let ctx = StageContext {
        dataset: Path::new(&dir),
        config: &config,
    };
    let stage = Echo {
        delay: Duration::from_millis(30),
    };
    run_stage(&stage, &ctx, &options(2)).expect("child run");
}

fn count_markers(dir: &Path) -> usize {
    let root = dir.join(".mesa/markers/echo");
    let Ok(tables) = std::fs::read_dir(root) else {
        return 0;
    };
    tables
        .filter_map(|t| std::fs::read_dir(t.ok()?.path()).ok())
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .filter(|e| e.file_name().to_string_lossy().ends_with(".json"))
                .count()
        })
        .sum()
}

#[test]
fn kill_then_resume_is_byte_identical() {
    let scenes = 60;
    let (_ref_dir, expected) = reference(scenes);
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), scenes);
    let exe: PathBuf = std::env::current_exe().expect("test binary");
    let mut child = Command::new(exe)
        .args([
            "--ignored",
            "--exact",
            "kill_child",
            "--nocapture",
            "--test-threads=1",
        ])
        .env("MESA_KILL_CHILD", dir.path())
        .spawn()
        .expect("spawn child");
    let started = Instant::now();
    while count_markers(dir.path()) < 10 {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "child made no progress"
        );
        if let Some(status) = child.try_wait().expect("wait") {
            panic!("child ended before it was killed: {status}");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().expect("SIGKILL");
    child.wait().expect("reap");
    let killed_at = count_markers(dir.path());
    assert!(killed_at < scenes, "the child finished before the kill");

    let summary = run(dir.path(), &Config::default(), &options(2));
    assert!(summary.skipped >= 10, "resumed: {summary:?}");
    assert_eq!(summary.done + summary.skipped, scenes);
    let got = snapshot(dir.path());
    let extra: Vec<&String> = got.keys().filter(|k| !expected.contains_key(*k)).collect();
    assert!(extra.is_empty(), "left behind after the kill: {extra:?}");
    assert!(got == expected, "outputs differ from an uninterrupted run");
}

/// Writes whether the runner handed it the bytes of `input/data.txt` it hashed (and whether
/// they are the file's), and whether it saw the input through the scene's record.
struct Handed;

impl SceneStage for Handed {
    fn name(&self) -> &'static str {
        "handed"
    }

    fn inputs(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<Vec<String>> {
        Ok(vec![scene.rel("input/data.txt")])
    }

    fn config_digest(&self, _: &StageContext<'_>) -> String {
        String::new()
    }

    fn run(&self, _: &StageContext<'_>, scene: &Scene) -> anyhow::Result<SceneOutput> {
        use mesa_pipeline::runner::scene_files;
        let path = scene.path("input/data.txt");
        let on_disk = std::fs::read(&path)?;
        let verdict = match scene_files::take(&path) {
            Some(bytes) if bytes == on_disk => "handed",
            Some(_) => "handed other bytes",
            None => "read",
        };
        let mut out = SceneOutput::new();
        out.add_file("handed/verdict.txt", verdict.into());
        Ok(out)
    }
}

fn modified_and_inode(path: &Path) -> (std::time::SystemTime, u64) {
    use std::os::unix::fs::MetadataExt as _;
    let meta = std::fs::symlink_metadata(path).expect("marker");
    (meta.modified().expect("mtime"), meta.ino())
}

/// The runner hands a stage the bytes of the small inputs it hashed for the scene, the same
/// bytes as the file; outside a scene nothing is handed (the control).
#[test]
fn the_runner_hands_the_stage_the_bytes_it_hashed() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 6);
    let config = Config::default();
    let ctx = StageContext {
        dataset: dir.path(),
        config: &config,
    };
    let summary = run_stage(&Handed, &ctx, &options(2)).expect("run");
    assert_eq!(summary.done, 6);
    let verdicts: Vec<Vec<u8>> = snapshot(dir.path())
        .into_iter()
        .filter(|(rel, _)| rel.ends_with("handed/verdict.txt"))
        .map(|(_, bytes)| bytes)
        .collect();
    assert_eq!(verdicts, vec![b"handed".to_vec(); 6]);
    let path = dir
        .path()
        .join("scenes/office_table/office_table_0000/input/data.txt");
    assert_eq!(mesa_pipeline::runner::scene_files::take(&path), None);
}

/// A forced rerun whose markers come out the same leaves them as they are (same inode, same
/// time); a marker changed on disk, or one that is a link, is written anew. The control for
/// the first: the changed one gets a new inode.
#[test]
fn a_marker_is_rewritten_only_when_its_bytes_change() {
    let dir = tempfile::tempdir().expect("tempdir");
    make_dataset(dir.path(), 3);
    let config = Config::default();
    assert_eq!(run(dir.path(), &config, &options(1)).done, 3);
    let markers = dir.path().join(".mesa/markers/echo");
    let marker = |table: &str, k: usize| markers.join(format!("{table}/{table}_{k:04}.json"));
    let (office, dining, coffee) = (
        marker("office_table", 0),
        marker("dining_table", 1),
        marker("coffee_table", 2),
    );
    let canonical = std::fs::read(&office).expect("marker");
    let before: Vec<_> = [&office, &dining, &coffee]
        .iter()
        .map(|p| modified_and_inode(p))
        .collect();
    // A marker changed on disk (still valid JSON), and one replaced by a link to a copy.
    let mut edited = canonical.clone();
    edited.extend_from_slice(b"  \n");
    std::fs::write(&office, &edited).expect("edit");
    let edited_state = modified_and_inode(&office);
    let copy = dir.path().join("dining_copy.json");
    std::fs::copy(&dining, &copy).expect("copy");
    std::fs::remove_file(&dining).expect("rm");
    std::os::unix::fs::symlink(&copy, &dining).expect("link");

    let forced = RunOptions {
        force: true,
        ..options(1)
    };
    assert_eq!(run(dir.path(), &config, &forced).done, 3);
    assert_eq!(std::fs::read(&office).expect("marker"), canonical);
    assert_ne!(modified_and_inode(&office).1, edited_state.1, "rewritten");
    let dining_meta = std::fs::symlink_metadata(&dining).expect("marker");
    assert!(dining_meta.is_file(), "the link is replaced by the marker");
    assert_eq!(modified_and_inode(&coffee), before[2], "left as it was");
}

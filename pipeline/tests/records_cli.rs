//! End-to-end tests of `mesa tasks` (template backend) and `mesa records` over a dataset of
//! the seven published layouts: every file is what LLaMA-Factory and TRL read; every output
//! and chosen text parses and gives back its layout exactly; every rejected text differs the
//! way its corruption says; the user turn has the pinned bytes; the split keeps SFT and DPO
//! scenes apart; reruns are skipped, forced reruns and other thread counts give the same
//! bytes. `mesa run` writes the records after the per-scene stages.

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use assert_cmd::Command;
use mesa_schemas::artifacts::{
    DatasetInfoEntry, DpoRecord, SftRecord, SplitArtifact, TaskRecord, TrlDpoRecord, TrlSftRecord,
};
use mesa_schemas::output::parse_model_output;
use mesa_schemas::LlmLayout;
use mesa_stages::records::collide::colliding_names;
use mesa_stages::records::corrupt::{triplet_fields, WRONG_RELATION};
use mesa_stages::records::round_layout;
use mesa_stages::tasks::reasoning::check_reasoning;
use mesa_stages::tasks::types::SceneTypes;
use serde_json::{json, Value};

fn mesa() -> Command {
    Command::cargo_bin("mesa").expect("the mesa binary")
}

fn ok(args: &[&str], dir: &Path) -> String {
    let out = mesa().args(args).arg(dir).output().expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "mesa {args:?}: {stderr}");
    stderr
}

/// A dataset of the published layouts with tasks and records built, and split ratios that give
/// every split scenes (7 scenes: 4 train, 2 dpo, 1 test).
/// The seven published layouts, with a split that gives every split a scene.
fn gallery_with_split() -> tempfile::TempDir {
    let dir = tempfile::tempdir().expect("tempdir");
    common::gallery_dataset(dir.path());
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[records.split]\ntrain = 0.6\ndpo = 0.25\ntest = 0.15\n",
    )
    .expect("config");
    dir
}

fn built() -> tempfile::TempDir {
    let dir = gallery_with_split();
    ok(&["graph", "--progress", "off"], dir.path());
    ok(&["tasks", "--progress", "off"], dir.path());
    ok(&["records", "--progress", "off"], dir.path());
    dir
}

fn read<T: serde::de::DeserializeOwned>(path: &Path) -> T {
    serde_json::from_slice(
        &std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())),
    )
    .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn lines<T: serde::de::DeserializeOwned>(path: &Path) -> Vec<T> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(|l| serde_json::from_str(l).expect("a JSON line"))
        .collect()
}

/// Each scene's layout as the records show it (the first of qa/ and refined/, in the
/// LLM form, rounded to 0.1), by scene id.
fn layouts(dir: &Path) -> BTreeMap<String, LlmLayout> {
    let mut out = BTreeMap::new();
    for table in std::fs::read_dir(dir.join("scenes")).expect("scenes") {
        for scene in std::fs::read_dir(table.expect("entry").path()).expect("table") {
            let scene = scene.expect("entry").path();
            let Some(path) = ["qa", "refined"]
                .iter()
                .map(|d| scene.join(d).join("layout.json"))
                .find(|p| p.is_file())
            else {
                continue;
            };
            let dataset: mesa_schemas::DatasetLayout = read(&path);
            let llm = mesa_schemas::convert::llm_from_dataset(&dataset).layout;
            let id = scene
                .file_name()
                .expect("id")
                .to_string_lossy()
                .into_owned();
            out.insert(id, round_layout(&llm, 1));
        }
    }
    out
}

/// The scene a record's input belongs to, by its zone and objects.
fn scene_of<'a>(layouts: &'a BTreeMap<String, LlmLayout>, layout: &LlmLayout) -> &'a str {
    layouts
        .iter()
        .find(|(_, l)| l.zone_cm == layout.zone_cm && l.objects.len() >= layout.objects.len())
        .map(|(k, _)| k.as_str())
        .expect("a scene with that zone")
}

/// Checks SFT records against the dataset: each output parses under the paper's rule and gives
/// back exactly its scene's layout and scene-graph lines; the instruction is the prompt file;
/// the input is task info with the layout's zone.
fn check_sft<'a>(dir: &Path, records: impl IntoIterator<Item = &'a SftRecord>) {
    let layouts = layouts(dir);
    let files = common::all_files(dir);
    let instruction = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/prompts/layout_generation.txt"),
    )
    .expect("the prompt file");
    let instruction = instruction.trim_end_matches('\n');
    for record in records {
        // The output parses under the paper's rule and gives back the scene's layout exactly.
        let parsed = parse_model_output(&record.output).expect("a success");
        assert!(parsed.dropped_objects.is_empty());
        let scene = scene_of(&layouts, &parsed.layout);
        assert_eq!(parsed.layout, layouts[scene], "{scene}");
        // The graph lines are those of the layout as written (rounded): graph.txt's when no
        // object sits on a band's edge.
        let graph_json = files
            .keys()
            .find(|k| k.contains(scene) && k.ends_with("graph/graph.json"))
            .expect("graph.json");
        assert_eq!(
            parsed.graph_lines,
            graph_of(&dir.join(graph_json), &parsed.layout)
        );
        // The instruction is the prompt file; the input the task info with the layout's zones.
        assert_eq!(record.instruction, instruction);
        let input: Value = serde_json::from_str(&record.input).expect("input JSON");
        assert_eq!(
            input["item_placement_zone"],
            serde_json::to_value(layouts[scene].zone_cm).expect("zone")
        );
        let keys: Vec<&str> = input
            .as_object()
            .expect("object")
            .keys()
            .map(String::as_str)
            .collect();
        assert!(keys.contains(&"Action Sequence") && keys.contains(&"Objects cluster"));
    }
}

#[test]
fn sft_records_give_back_their_layouts_and_the_user_turn_has_the_pinned_bytes() {
    let dir = built();
    let records = dir.path().join("records");
    let sft: Vec<SftRecord> = read(&records.join("sft.json"));
    let test: Vec<SftRecord> = read(&records.join("test.json"));
    let split: SplitArtifact = read(&records.join("split.json"));
    let count = |name: &str| split.scenes.values().filter(|s| *s == name).count();
    assert_eq!((count("train"), count("dpo"), count("test")), (4, 2, 1));
    assert_eq!(sft.len(), 4 * 5);
    assert_eq!(test.len(), 5);
    let instruction = std::fs::read_to_string(
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/prompts/layout_generation.txt"),
    )
    .expect("the prompt file");
    let instruction = instruction.trim_end_matches('\n');
    check_sft(dir.path(), sft.iter().chain(&test));
    // The pinned bytes of the user turn LLaMA-Factory builds from an alpaca record:
    // instruction, one line break, the input written as json.dumps(indent=2,
    // ensure_ascii=False) writes it, here rebuilt field by field.
    let record = &sft[0];
    let info: mesa_schemas::TaskInfo = serde_json::from_str(&record.input).expect("task info");
    let s = |text: &str| serde_json::to_string(text).expect("string");
    let list = |items: &[String]| {
        let inner: Vec<String> = items.iter().map(|i| format!("    {}", s(i))).collect();
        format!("[\n{}\n  ]", inner.join(",\n"))
    };
    let zone = |z: &[f64; 4]| {
        let inner: Vec<String> = z.iter().map(|v| format!("    {v:?}")).collect();
        format!("[\n{}\n  ]", inner.join(",\n"))
    };
    let mut expected_input = format!(
        "{{\n  \"Environment\": {},\n  \"item_placement_zone\": {},\n",
        s(&info.environment),
        zone(&info.zone_cm.0)
    );
    if let Some(sink) = &info.sink_zone_cm {
        expected_input.push_str(&format!("  \"sink_zone\": {},\n", zone(&sink.0)));
    }
    expected_input.push_str(&format!(
        "  \"Task\": {},\n  \"Goal\": {},\n  \"Action Sequence\": {},\n  \"Objects cluster\": {}\n}}",
        s(&info.task),
        list(&info.goal),
        list(info.action_sequence.as_deref().expect("actions")),
        list(&info.objects_cluster)
    ));
    let user_turn = format!("{}\n{}", record.instruction, record.input);
    assert_eq!(user_turn, format!("{instruction}\n{expected_input}"));
    assert!(user_turn.starts_with("You design tabletop scenes for a robot."));
    assert!(user_turn.contains("The task description:\n{\n  \"Environment\": \"A"));
    // TRL holds the same turns.
    let trl: Vec<TrlSftRecord> = lines(&records.join("trl_sft.jsonl"));
    assert_eq!(trl.len(), sft.len());
    for (t, r) in trl.iter().zip(&sft) {
        assert_eq!(t.messages.len(), 2);
        assert_eq!(
            (t.messages[0].role.as_str(), t.messages[1].role.as_str()),
            ("user", "assistant")
        );
        assert_eq!(
            t.messages[0].content,
            format!("{}\n{}", r.instruction, r.input)
        );
        assert_eq!(t.messages[1].content, r.output);
    }
    assert_eq!(
        lines::<TrlSftRecord>(&records.join("trl_test.jsonl")).len(),
        5
    );
}

/// Prompt (input, scene) → the corruptions of its rejected outputs.
type PerPrompt = BTreeMap<(String, String), BTreeSet<&'static str>>;

/// Checks DPO records against the dataset: the chosen output is the scene's; each rejected
/// output is one of the three corruptions and differs the way it says. Returns the count per
/// corruption and the corruptions of each prompt.
fn check_dpo(dir: &Path, dpo: &[DpoRecord]) -> (BTreeMap<&'static str, usize>, PerPrompt) {
    let layouts = layouts(dir);
    let mut kinds: BTreeMap<&'static str, usize> = BTreeMap::new();
    let mut per_prompt = PerPrompt::new();
    for record in dpo {
        let chosen = parse_model_output(&record.chosen).expect("chosen parses");
        let rejected = parse_model_output(&record.rejected).expect("rejected parses");
        let scene = scene_of(&layouts, &chosen.layout);
        assert_eq!(
            chosen.layout, layouts[scene],
            "the chosen layout is the scene's"
        );
        let names = |l: &LlmLayout| {
            l.objects
                .iter()
                .map(|o| o.instance.clone())
                .collect::<Vec<_>>()
        };
        let kind = if rejected.layout == chosen.layout {
            // Relation: the layout unchanged, edges removed or made wrong, nodes kept.
            assert_ne!(rejected.graph_lines, chosen.graph_lines);
            assert_eq!(rejected.reasoning, chosen.reasoning);
            let kept: BTreeSet<&String> = chosen.graph_lines.iter().collect();
            for line in rejected.graph_lines.iter().filter(|l| !kept.contains(l)) {
                let f = triplet_fields(line).expect("triplet");
                assert!(
                    WRONG_RELATION.iter().any(|(right, wrong)| *wrong == f[1]
                        && kept.contains(&format!("({}, {right}, {})", f[0], f[2]))),
                    "{line}"
                );
            }
            "relation"
        } else if names(&rejected.layout) == names(&chosen.layout) {
            // Collision: same objects, a colliding pair the chosen layout does not have.
            let before: BTreeSet<_> = colliding_names(&chosen.layout, 0.2).into_iter().collect();
            let after: BTreeSet<_> = colliding_names(&rejected.layout, 0.2).into_iter().collect();
            assert!(
                after.difference(&before).next().is_some(),
                "no new collision"
            );
            "collision"
        } else {
            // Missing object: task objects gone from the layout, the lines and the counts.
            let info: mesa_schemas::TaskInfo = serde_json::from_str(&record.input).expect("input");
            let kept: BTreeSet<String> = names(&rejected.layout).into_iter().collect();
            let gone: Vec<String> = names(&chosen.layout)
                .into_iter()
                .filter(|n| !kept.contains(n))
                .collect();
            assert!(!gone.is_empty());
            let types = SceneTypes::of_layout(&chosen.layout);
            for instance in &gone {
                let t = types
                    .types
                    .iter()
                    .find(|t| t.instances.contains(instance))
                    .expect("type");
                assert!(info
                    .objects_cluster
                    .iter()
                    .any(|w| types.matching(w).iter().any(|m| m.key == t.key)));
                assert!(rejected
                    .graph_lines
                    .iter()
                    .all(|l| !triplet_fields(l).expect("t").contains(&instance.as_str())));
            }
            let remaining = SceneTypes::of_layout(&rejected.layout);
            assert!(check_reasoning(&rejected.reasoning, &remaining, &[]).is_empty());
            "missing_object"
        };
        *kinds.entry(kind).or_default() += 1;
        per_prompt
            .entry((record.input.clone(), scene.to_owned()))
            .or_default()
            .insert(kind);
    }
    (kinds, per_prompt)
}

#[test]
fn dpo_pairs_are_chosen_outputs_against_verified_corruptions() {
    let dir = built();
    let records = dir.path().join("records");
    let dpo: Vec<DpoRecord> = read(&records.join("dpo.json"));
    assert_eq!(
        dpo.len(),
        2 * 5 * 2,
        "two rejected per prompt, 5 prompts, 2 scenes"
    );
    let (kinds, per_prompt) = check_dpo(dir.path(), &dpo);
    // Each prompt's two rejected outputs come from two different corruptions; all three occur.
    assert!(per_prompt.values().all(|k| k.len() == 2), "{per_prompt:?}");
    assert_eq!(kinds.len(), 3, "{kinds:?}");
    let trl: Vec<TrlDpoRecord> = lines(&records.join("trl_dpo.jsonl"));
    assert_eq!(trl.len(), dpo.len());
    for (t, r) in trl.iter().zip(&dpo) {
        assert_eq!(
            t.prompt[0].content,
            format!("{}\n{}", r.instruction, r.input)
        );
        assert_eq!(
            (t.chosen[0].role.as_str(), t.rejected[0].role.as_str()),
            ("assistant", "assistant")
        );
        assert_eq!(
            (&t.chosen[0].content, &t.rejected[0].content),
            (&r.chosen, &r.rejected)
        );
    }
}

#[test]
fn the_registry_and_the_split_are_what_trainers_and_people_read() {
    let dir = built();
    let records = dir.path().join("records");
    let info: BTreeMap<String, DatasetInfoEntry> = read(&records.join("dataset_info.json"));
    assert_eq!(info["mesa_dpo"].ranking, Some(true));
    assert_eq!(info["mesa_dpo"].formatting.as_deref(), Some("alpaca"));
    for (name, entry) in &info {
        assert!(
            records.join(&entry.file_name).is_file(),
            "{name}: {}",
            entry.file_name
        );
        let columns = entry.columns.as_ref().expect("columns");
        if entry.formatting.as_deref() == Some("alpaca") {
            assert_eq!(columns["prompt"], "instruction");
            assert_eq!(columns["query"], "input");
        }
    }
    // SFT and DPO never share a scene; each scene is in one split, stratified counts add up.
    let split: SplitArtifact = read(&records.join("split.json"));
    assert_eq!(split.scenes.len(), 7);
    let total: u64 = split.counts.values().flat_map(|m| m.values()).sum();
    assert_eq!(total, 7);
    let tasks_of = |name: &str| -> BTreeSet<String> {
        split
            .scenes
            .iter()
            .filter(|(_, s)| *s == name)
            .map(|(k, _)| k.rsplit('/').next().expect("id").to_owned())
            .collect()
    };
    assert!(tasks_of("train").is_disjoint(&tasks_of("dpo")));
    // Every file validates.
    let out = mesa()
        .arg("validate")
        .arg(&records)
        .output()
        .expect("validate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    let scenes = dir.path().join("scenes");
    let out = mesa()
        .arg("validate")
        .arg(&scenes)
        .output()
        .expect("validate");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    // The tasks are the template's, and say so.
    for (path, bytes) in common::all_files(dir.path()) {
        if path.ends_with("tasks/tasks.jsonl") {
            let text = String::from_utf8(bytes).expect("utf8");
            for line in text.lines() {
                let record: TaskRecord = serde_json::from_str(line).expect("record");
                assert_eq!(record.generator, "template");
                assert!(record.views.is_empty());
            }
        }
    }
}

#[test]
fn records_are_skipped_when_current_and_identical_for_any_thread_count() {
    let dir = built();
    let before = common::all_files(&dir.path().join("records"));
    let stderr = ok(&["records", "--progress", "off"], dir.path());
    assert!(stderr.contains("up to date"), "{stderr}");
    ok(
        &["records", "--progress", "off", "--force", "--jobs", "1"],
        dir.path(),
    );
    assert!(
        common::all_files(&dir.path().join("records")) == before,
        "1 thread differs"
    );
    ok(
        &["records", "--progress", "off", "--force", "--jobs", "2"],
        dir.path(),
    );
    assert!(
        common::all_files(&dir.path().join("records")) == before,
        "2 threads differ"
    );
    // A changed seed is a changed configuration: rebuilt, and the DPO corruptions change.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[run]\nseed = 5\n[records.split]\ntrain = 0.6\ndpo = 0.25\ntest = 0.15\n",
    )
    .expect("config");
    let stderr = ok(&["records", "--progress", "off"], dir.path());
    assert!(!stderr.contains("up to date"), "{stderr}");
    // Editing a scene's layout makes its tasks stale: records leave the scene out and say so.
    let layout = common::all_files(dir.path())
        .keys()
        .find(|k| k.ends_with("refined/layout.json"))
        .map(|k| dir.path().join(k))
        .expect("a layout");
    let text = std::fs::read_to_string(&layout).expect("read");
    std::fs::write(&layout, text.replacen("\"objects\"", "\"objects\" ", 1)).expect("touch");
    let out = mesa()
        .args(["records", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("rerun `mesa tasks`"), "{stderr}");
}

#[test]
fn bad_records_settings_are_usage_errors() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::gallery_dataset(dir.path());
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[records.split]\ntrain = 0.9\n",
    )
    .expect("config");
    let out = mesa()
        .arg("records")
        .arg(dir.path())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("train + dpo + test is 1.1"));
    std::fs::write(dir.path().join("mesa.toml"), "").expect("config");
    let out = mesa()
        .arg("records")
        .arg(dir.path())
        .output()
        .expect("runs");
    assert_eq!(out.status.code(), Some(1), "no tasks yet");
    assert!(String::from_utf8_lossy(&out.stderr).contains("run `mesa tasks` first"));
}

#[test]
fn mesa_run_writes_the_records_after_the_scene_stages() {
    let dir = tempfile::tempdir().expect("tempdir");
    common::gallery_dataset(dir.path());
    let out = mesa()
        .args(["run", "--progress", "off"])
        .arg(dir.path())
        .output()
        .expect("runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    // These scenes hold layouts only, no photo: lift fails each of them (and says why), the
    // stages after it work from the layouts.
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("lift: 7 scenes: 0 done, 0 skipped, 7 failed"),
        "{stderr}"
    );
    assert!(stderr.contains("graph: 7 scenes: 7 done"), "{stderr}");
    assert!(stderr.contains("tasks: 7 scenes: 7 done"), "{stderr}");
    assert!(stderr.contains("records: 7 scenes"), "{stderr}");
    let sft: Vec<SftRecord> = read(&dir.path().join("records/sft.json"));
    let dpo: Vec<DpoRecord> = read(&dir.path().join("records/dpo.json"));
    // Default ratios 0.8 / 0.1 / 0.1 of 7 scenes: 5 train, 1 dpo, 1 test.
    assert_eq!((sft.len(), dpo.len()), (25, 10));
    // With shards, records wait for `mesa records`.
    let out = mesa()
        .args(["run", "--progress", "off", "--shard", "0/2"])
        .arg(dir.path())
        .output()
        .expect("runs");
    assert!(String::from_utf8_lossy(&out.stderr).contains("records: not run by a shard"));
}

#[test]
fn llamafactory_and_trl_read_the_files() {
    // The `datasets` library as the trainers use it; required when MESA_REQUIRE_TOOLS is set
    // (as in CI), skipped loudly otherwise.
    let required = std::env::var_os("MESA_REQUIRE_TOOLS").is_some();
    let Some(python) = std::env::var_os("MESA_PYTHON") else {
        assert!(
            !required,
            "MESA_PYTHON is not set: scripts/test.sh sets it to a Python with `datasets`"
        );
        eprintln!(
            "SKIPPED: reading the records with `datasets` (set MESA_PYTHON to a Python with \
             the datasets library; scripts/test.sh does)"
        );
        return;
    };
    let dir = built();
    let records = dir.path().join("records");
    let cache = tempfile::tempdir().expect("tempdir");
    let out = std::process::Command::new(&python)
        .arg(PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/read_records.py"))
        .arg(&records)
        .env("HF_DATASETS_CACHE", cache.path())
        .env("HF_DATASETS_OFFLINE", "1")
        .output()
        .expect("python runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() && stderr.contains("No module named 'datasets'") && !required {
        eprintln!("SKIPPED: {python:?} has no `datasets` library (scripts/test.sh installs it)");
        return;
    }
    assert!(out.status.success(), "read_records.py: {stderr}");
    let summary: Value = serde_json::from_slice(&out.stdout).expect("a JSON summary");
    let sft: Vec<SftRecord> = read(&records.join("sft.json"));
    let dpo: Vec<DpoRecord> = read(&records.join("dpo.json"));
    let factory = &summary["llamafactory"];
    for (name, rows, ranking) in [
        ("mesa_sft", 20, false),
        ("mesa_test", 5, false),
        ("mesa_dpo", 20, true),
        ("mesa_sft_trl", 20, false),
        ("mesa_test_trl", 5, false),
    ] {
        assert_eq!(factory[name]["rows"], rows, "{name}");
        assert_eq!(factory[name]["ranking"], ranking, "{name}");
    }
    assert_eq!(
        factory["mesa_dpo"]["columns"],
        json!(["chosen", "input", "instruction", "rejected"])
    );
    // The user turn LLaMA-Factory builds is exactly instruction + "\n" + input.
    let turn = |r: &SftRecord| format!("{}\n{}", r.instruction, r.input);
    assert_eq!(factory["mesa_sft"]["first_user_turn"], turn(&sft[0]));
    assert_eq!(factory["mesa_sft_trl"]["first_user_turn"], turn(&sft[0]));
    assert_eq!(
        factory["mesa_dpo"]["first_user_turn"],
        format!("{}\n{}", dpo[0].instruction, dpo[0].input)
    );
    let trl = &summary["trl"];
    assert_eq!(trl["trl_sft.jsonl"]["rows"], 20);
    assert_eq!(trl["trl_dpo.jsonl"]["rows"], 20);
    assert_eq!(trl["trl_sft.jsonl"]["first_user_turn"], turn(&sft[0]));
}

#[test]
fn on_the_demo_mesa_run_writes_sft_and_dpo_records() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = mesa()
        .args(["demo", "--scenes", "6", "-q"])
        .arg(dir.path())
        .output()
        .expect("demo");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let stderr = ok(&["run", "--progress", "off"], dir.path());
    assert!(stderr.contains("tasks: 6 scenes: 6 done"), "{stderr}");
    let records = dir.path().join("records");
    let sft: Vec<SftRecord> = read(&records.join("sft.json"));
    let test: Vec<SftRecord> = read(&records.join("test.json"));
    let dpo: Vec<DpoRecord> = read(&records.join("dpo.json"));
    // 6 scenes at 0.8 / 0.1 / 0.1: 4 train, 1 dpo, 1 test; 5 template tasks each.
    assert_eq!((sft.len(), test.len(), dpo.len()), (20, 5, 10));
    check_sft(dir.path(), sft.iter().chain(&test));
    let (kinds, per_prompt) = check_dpo(dir.path(), &dpo);
    assert_eq!(kinds.values().sum::<usize>(), 10);
    assert!(per_prompt.values().all(|k| k.len() == 2), "{per_prompt:?}");
}

/// Writes `qa/check.json` for a scene's refined layout: `clean`, with one collision when not;
/// `stale` gives it the digest of another layout.
fn write_check(scene: &Path, clean: bool, stale: bool) {
    use mesa_schemas::artifacts::{CheckArtifact, CollisionPair};
    let layout = std::fs::read(scene.join("refined/layout.json")).expect("layout");
    let digest = mesa_pipeline::fsio::sha256_hex(if stale { b"another layout" } else { &layout });
    let check = CheckArtifact {
        schema: "mesa.check/1".to_owned(),
        scene_id: scene
            .file_name()
            .expect("name")
            .to_string_lossy()
            .into_owned(),
        layout: "refined/layout.json".to_owned(),
        layout_sha256: digest,
        penetration_tolerance_mm: 2.0,
        floating_tolerance_mm: 5.0,
        zone_tolerance_mm: 5.0,
        mesatask_rule_distance_cm: 5.0,
        objects: 2,
        unchecked: Vec::new(),
        collisions: if clean {
            Vec::new()
        } else {
            vec![CollisionPair {
                a: "a_0".to_owned(),
                b: "b_0".to_owned(),
                depth_mm: 12.0,
            }]
        },
        floating: Vec::new(),
        zone_violations: Vec::new(),
        pairs_total: 1,
        collision_rate: if clean { 0.0 } else { 1.0 },
        mesatask_rule_pairs: 0,
        clean,
        settle: None,
    };
    std::fs::create_dir_all(scene.join("qa")).expect("mkdir");
    std::fs::write(
        scene.join("qa/check.json"),
        mesa_schemas::json::to_sorted_pretty(&check).expect("json"),
    )
    .expect("write check");
}

#[test]
fn scenes_whose_check_failed_are_left_out_and_counted_unless_kept() {
    let dir = built();
    let scenes = dir.path().join("scenes");
    let failed = scenes.join("dining_table/dining_table_0001");
    // Controls: a clean check, and a failed check of another version of the layout.
    write_check(&failed, false, false);
    write_check(&scenes.join("office_table/office_table_0002"), true, false);
    write_check(&scenes.join("coffee_table/coffee_table_0007"), false, true);
    let stderr = ok(&["records", "--progress", "off"], dir.path());
    assert!(stderr.contains("records: 6 scenes"), "{stderr}");
    for expected in [
        "left out 1 scenes whose check failed ([records] keep_failed_check = true keeps them",
        "dining_table/dining_table_0001: qa/check.json: refined/layout.json is not clean: 1 \
         collisions, 0 floating objects, 0 zone violations, 0 objects unchecked",
    ] {
        assert!(stderr.contains(expected), "{expected}: {stderr}");
    }
    let split: SplitArtifact = read(&dir.path().join("records/split.json"));
    assert!(!split.scenes.contains_key("dining_table/dining_table_0001"));
    assert!(split.scenes.contains_key("office_table/office_table_0002"));
    assert!(split.scenes.contains_key("coffee_table/coffee_table_0007"));
    assert!(
        split.excluded["dining_table/dining_table_0001"].contains("is not clean"),
        "{:?}",
        split.excluded
    );
    // The run's record counts it.
    let run: Value = read(&dir.path().join(".mesa/runs/records/run.json"));
    assert!(run.to_string().contains("failed_check"), "{run}");

    // Kept when configured: every scene has records again.
    std::fs::write(
        dir.path().join("mesa.toml"),
        "[records]\nkeep_failed_check = true\n[records.split]\ntrain = 0.6\ndpo = 0.25\ntest = \
         0.15\n",
    )
    .expect("config");
    let stderr = ok(&["records", "--progress", "off"], dir.path());
    assert!(stderr.contains("records: 7 scenes"), "{stderr}");
    assert!(!stderr.contains("left out"), "{stderr}");
}

/// The y of an object, near the back band's edge of `zone`, whose band differs before and
/// after rounding to 0.1 cm (none when the edge falls on a rounding tie).
fn band_flipping_y(zone: [f64; 4]) -> Option<f64> {
    let back = |y: f64| (y - zone[2]) / (zone[3] - zone[2]) > 0.85;
    let edge = zone[2] + 0.85 * (zone[3] - zone[2]);
    (-49..=49)
        .map(|k| edge + f64::from(k) * 0.001)
        .find(|y| back(*y) != back(mesa_stages::records::round_to(*y, 1)))
}

/// A record teaches the scene graph of the layout it writes (rounded to 0.1 cm), not that of
/// graph/graph.txt (the unrounded layout): an object on a band's edge, where the rounding
/// flips its `is at` band, gets the band of its rounded position, so a model's graph and its
/// layout agree (`mesa eval`'s self-consistency of the dataset's own references is 1).
#[test]
fn the_records_graph_is_that_of_the_layout_they_write() {
    let dir = gallery_with_split();
    // Every scene's first object onto its zone's back edge, where rounding flips the band.
    let mut moved = 0;
    for (rel, _) in common::all_files(dir.path()) {
        if !rel.ends_with("refined/layout.json") {
            continue;
        }
        let path = dir.path().join(&rel);
        let mut layout: Value = read(&path);
        let zone: [f64; 4] =
            serde_json::from_value(layout["item_placement_zone"].clone()).expect("the zone");
        let Some(y) = band_flipping_y(zone) else {
            continue;
        };
        layout["objects"][0]["position"][1] = json!(y);
        std::fs::write(&path, serde_json::to_vec_pretty(&layout).expect("json")).expect("write");
        moved += 1;
    }
    assert!(moved >= 5, "{moved} scenes with an object on the edge");
    ok(&["graph", "--progress", "off"], dir.path());
    ok(&["tasks", "--progress", "off"], dir.path());
    ok(&["records", "--progress", "off"], dir.path());

    let records = dir.path().join("records");
    let mut outputs: Vec<String> = Vec::new();
    for file in ["sft.json", "test.json"] {
        let sft: Vec<SftRecord> = read(&records.join(file));
        outputs.extend(sft.into_iter().map(|r| r.output));
    }
    let dpo: Vec<DpoRecord> = read(&records.join("dpo.json"));
    outputs.extend(dpo.into_iter().map(|r| r.chosen));
    let files = common::all_files(dir.path());
    let mut flipped = BTreeSet::new();
    for output in &outputs {
        let parsed = parse_model_output(output).expect("a success");
        let name = &parsed.layout.objects[0].instance;
        // The scene: the one whose graph.json names the same objects in the same order.
        let (graph_json, _): (String, Value) = files
            .keys()
            .filter(|k| k.ends_with("graph/graph.json"))
            .map(|k| (k.clone(), read::<Value>(&dir.path().join(k))))
            .find(|(_, g)| {
                let names: Vec<&str> = g["nodes"]
                    .as_array()
                    .expect("nodes")
                    .iter()
                    .map(|n| n["instance"].as_str().expect("instance"))
                    .collect();
                names
                    == parsed
                        .layout
                        .objects
                        .iter()
                        .map(|o| o.instance.as_str())
                        .collect::<Vec<_>>()
            })
            .expect("the scene of the record");
        let own = graph_of(&dir.path().join(&graph_json), &parsed.layout);
        assert_eq!(parsed.graph_lines, own, "{graph_json}: {name}");
        // The control: graph.txt, of the unrounded layout, puts the moved object elsewhere.
        let txt = std::fs::read_to_string(dir.path().join(graph_json.replace(".json", ".txt")))
            .expect("graph.txt");
        let txt: Vec<String> = txt.lines().map(str::to_owned).collect();
        if txt != own {
            flipped.insert(graph_json);
        }
    }
    assert!(
        flipped.len() >= 5,
        "graph.txt differs from the records' graph in {} scenes",
        flipped.len()
    );
}

/// The scene-graph lines of `layout` with the containers of the scene's graph.json.
fn graph_of(graph_json: &Path, layout: &LlmLayout) -> Vec<String> {
    use mesa_stages::graph::{extract_graph, GraphOptions, GraphScene};
    let graph: Value = read(graph_json);
    let containers: Vec<bool> = graph["nodes"]
        .as_array()
        .expect("nodes")
        .iter()
        .map(|n| n["container"].as_bool().expect("container"))
        .collect();
    extract_graph(
        &GraphScene::from_llm(layout),
        &containers,
        &GraphOptions::default(),
    )
    .expect("graph")
    .triplet_lines()
}

//! Tasks and records against the authors' seven published records
//! (`realdata/layouts/mesatask_gallery`, read from `$MESA_SHARED/realdata`, default
//! `../../shared/realdata`; never copied into the repository).
//!
//! - Reproduction in structure: from each record's `scene_layout_json`, mesa's scene graph
//!   and the SFT output assembly give an output whose layout JSON equals the record's (key
//!   order aside) and whose scene-graph block has the record's structure; the triplet
//!   agreement is printed and held above the floors measured for SCENE_GRAPH.md's rules
//!   (the records were written by the authors' model and are not fully consistent with their
//!   own layouts, see stages/tests/graph_gallery.rs).
//! - The published reasoning paragraphs pass mesa's reasoning check, and their task infos
//!   give SFT inputs in the published field order.
//! - The template backend writes valid, deterministic tasks for every published layout, and
//!   every corruption of every task is what it says.

use std::collections::BTreeSet;
use std::path::PathBuf;

use mesa_schemas::artifacts::{GraphArtifact, TaskRecord, TASKS_SCHEMA};
use mesa_schemas::output::{parse_model_output, FINAL_ANSWER_MARKER};
use mesa_schemas::{GalleryRecord, LlmLayout, TaskInfo};
use mesa_stages::graph::{extract_graph, keyword_containers, GraphOptions, GraphScene};
use mesa_stages::records::collide::{colliding_names, Collider};
use mesa_stages::records::corrupt::{corrupt, triplet_fields, Corruption, WRONG_RELATION};
use mesa_stages::records::{dpo_pairs, round_layout, sft_record, RecordsConfig, SceneRecordsInput};
use mesa_stages::tasks::prompts::{layout_instruction, Prompts, LAYOUT_GENERATION};
use mesa_stages::tasks::reasoning::{check_reasoning, read_lists};
use mesa_stages::tasks::scene::NoChat;
use mesa_stages::tasks::types::SceneTypes;
use mesa_stages::tasks::{write_scene_tasks, SceneInput, TasksConfig};

struct Gallery {
    name: String,
    record: GalleryRecord,
    layout: LlmLayout,
    task: TaskInfo,
}

fn gallery() -> Vec<Gallery> {
    let shared = std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    let dir = shared.join("realdata/layouts/mesatask_gallery");
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (set MESA_SHARED to the shared folder)",
                dir.display()
            )
        })
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    assert_eq!(paths.len(), 7, "{}: the 7 published records", dir.display());
    paths
        .iter()
        .map(|path| {
            let text = std::fs::read_to_string(path).expect("readable");
            let record: GalleryRecord = serde_json::from_str(&text).expect("a gallery record");
            Gallery {
                name: path
                    .file_stem()
                    .expect("stem")
                    .to_string_lossy()
                    .into_owned(),
                layout: record.scene_layout_json.resolve().expect("layout"),
                task: record.input_task_description.resolve().expect("task info"),
                record,
            }
        })
        .collect()
}

/// The triplet lines, container flags and `graph.json` of a published layout.
fn graph_of(layout: &LlmLayout, name: &str) -> (Vec<String>, Vec<bool>, GraphArtifact) {
    let scene = GraphScene::from_llm(layout);
    let options = GraphOptions::default();
    let containers = keyword_containers(&scene, &options);
    let graph = extract_graph(&scene, &containers, &options).expect("graph");
    let artifact = graph.to_artifact(name, "layout.json");
    (graph.triplet_lines(), containers, artifact)
}

fn task_record(scene_id: &str, index: u32, info: TaskInfo, reasoning: &str) -> TaskRecord {
    TaskRecord {
        schema: TASKS_SCHEMA.to_owned(),
        scene_id: scene_id.to_owned(),
        task_index: index,
        generator: "published".to_owned(),
        layout: "layout.json".to_owned(),
        layout_sha256: String::new(),
        views: Vec::new(),
        table_description: info.environment.clone(),
        task_info: info,
        reasoning: reasoning.to_owned(),
    }
}

#[test]
fn outputs_assembled_from_published_layouts_reproduce_the_records() {
    let instruction = layout_instruction(LAYOUT_GENERATION).expect("instruction");
    let (mut shared, mut published_total, mut ours_total) = (0usize, 0usize, 0usize);
    let (mut node_agree, mut node_total) = (0usize, 0usize);
    println!("record  objects  published  ours  shared  nodes equal");
    for g in gallery() {
        // The published layouts already have one decimal: rounding changes nothing.
        assert_eq!(round_layout(&g.layout, 1), g.layout, "{}", g.name);
        let (lines, containers, _) = graph_of(&g.layout, &g.name);
        let input = SceneRecordsInput {
            scene_id: g.name.clone(),
            layout: g.layout.clone(),
            graph_lines: lines.clone(),
            containers,
            tasks: Vec::new(),
            collider: Collider::Boxes,
        };
        let task = task_record(&g.name, 0, g.task.clone(), &g.record.reasoning_paragraph);
        let sft = sft_record(&instruction, &input, &task).expect("an SFT record");
        // The layout JSON after the marker is the record's, key order aside.
        let json = &sft.output
            [sft.output.find(FINAL_ANSWER_MARKER).expect("marker") + FINAL_ANSWER_MARKER.len()..];
        let ours: serde_json::Value = serde_json::from_str(json).expect("layout JSON");
        let theirs = match &g.record.scene_layout_json {
            mesa_schemas::llm::InlineOrString::Inline(layout) => {
                serde_json::to_value(layout).expect("value")
            }
            mesa_schemas::llm::InlineOrString::Text(text) => {
                serde_json::from_str(text).expect("value")
            }
        };
        assert_eq!(ours, theirs, "{}: layout JSON", g.name);
        // The scene-graph block has the record's structure: a node pair per object in layout
        // order, then the edges.
        let parsed = parse_model_output(&sft.output).expect("a success");
        assert_eq!(parsed.graph_lines, lines);
        assert_eq!(parsed.reasoning, g.record.reasoning_paragraph.trim_end());
        let published = g.record.scene_graph.lines();
        let n = g.layout.objects.len();
        assert_eq!(&lines[..2 * n].len(), &published[..2 * n].len());
        for (ours, theirs) in lines[..2 * n].iter().zip(&published[..2 * n]) {
            // Same subject and predicate in the same place; the value may differ.
            let (a, b) = (
                triplet_fields(ours).expect("ours"),
                triplet_fields(theirs).expect("theirs"),
            );
            assert_eq!(a[..2], b[..2], "{}: node order", g.name);
            node_total += 1;
            node_agree += usize::from(a == b);
        }
        let ours_set: BTreeSet<&String> = lines.iter().collect();
        let theirs_set: BTreeSet<&String> = published.iter().collect();
        let common = ours_set.intersection(&theirs_set).count();
        println!(
            "{:>6}  {n:>7}  {:>9}  {:>4}  {common:>6}  {}",
            g.name,
            published.len(),
            lines.len(),
            (lines[..2 * n] == published[..2 * n]) as u8
        );
        shared += common;
        published_total += published.len();
        ours_total += lines.len();
    }
    let precision = shared as f64 / ours_total as f64;
    let recall = shared as f64 / published_total as f64;
    let nodes = node_agree as f64 / node_total as f64;
    println!(
        "triplets: precision {precision:.3} recall {recall:.3}; node lines equal {nodes:.3} \
         ({node_agree} of {node_total})"
    );
    // Floors measured with SCENE_GRAPH.md's rules (graph_gallery.rs: 0.862 / 0.884).
    assert!(precision >= 0.85 && recall >= 0.85, "{precision} {recall}");
    assert!(nodes >= 0.95, "{nodes}");
}

#[test]
fn the_reasoning_check_reads_the_published_paragraphs() {
    // Four of the seven published paragraphs have the two headed lists the issue asks of
    // ours; three (002, 003, 004) are prose only. Where the lists are there, they are read and
    // checked against the record's own layout; the authors' model did not always count right.
    let mut structured = Vec::new();
    for g in gallery() {
        let types = SceneTypes::of_layout(&g.layout);
        let text = &g.record.reasoning_paragraph;
        match read_lists(text) {
            Ok(lists) => {
                let problems = check_reasoning(text, &types, &g.task.objects_cluster);
                println!(
                    "{}: lists of {} + {} types; {} disagreements with the layout: {problems:?}",
                    g.name,
                    lists.core.len(),
                    lists.environment.len(),
                    problems.len()
                );
                assert!(!lists.core.is_empty() && !lists.environment.is_empty());
                structured.push(g.name.clone());
            }
            Err(problems) => println!("{}: prose only: {problems:?}", g.name),
        }
    }
    assert_eq!(structured, ["001", "006", "008", "009"]);
}

fn scene_input(g: &Gallery) -> SceneInput {
    let (lines, _, graph) = graph_of(&g.layout, &g.name);
    SceneInput {
        scene_id: format!("gallery_{}", g.name),
        table_type: "dining_table".to_owned(),
        layout: g.layout.clone(),
        layout_file: "layout.json".to_owned(),
        layout_sha256: "0".repeat(64),
        graph_lines: lines,
        graph,
        views: Vec::new(),
    }
}

#[test]
fn the_template_backend_writes_valid_deterministic_tasks_for_every_published_layout() {
    let prompts = Prompts::builtin().expect("prompts");
    let config = TasksConfig::default();
    for g in gallery() {
        let input = scene_input(&g);
        let first = write_scene_tasks(&input, &config, &prompts, &NoChat, 0).expect("tasks");
        let again = write_scene_tasks(&input, &config, &prompts, &NoChat, 0).expect("tasks");
        assert_eq!(first, again, "{}: deterministic", g.name);
        let other_seed = write_scene_tasks(&input, &config, &prompts, &NoChat, 1).expect("tasks");
        assert_ne!(
            first.records, other_seed.records,
            "{}: the seed matters",
            g.name
        );
        assert_eq!(first.records.len(), 5, "{}: {:?}", g.name, first.warnings);
        assert!(first.rejects.is_empty());
        let types = SceneTypes::of_layout(&g.layout);
        let tasks: BTreeSet<&str> = first
            .records
            .iter()
            .map(|r| r.task_info.task.as_str())
            .collect();
        assert_eq!(tasks.len(), 5, "{}: different tasks", g.name);
        for record in &first.records {
            assert_eq!(record.generator, "template");
            let info = &record.task_info;
            assert!(info.problems().is_empty(), "{:?}", info.problems());
            assert!(
                info.objects_cluster.len() >= 3,
                "{}: {:?}",
                g.name,
                info.objects_cluster
            );
            for written in &info.objects_cluster {
                assert!(!types.matching(written).is_empty(), "{written}");
            }
            assert_eq!(info.zone_cm, g.layout.zone_cm);
            assert_eq!(info.sink_zone_cm, g.layout.sink_zone_cm);
            let problems = check_reasoning(&record.reasoning, &types, &info.objects_cluster);
            assert!(
                problems.is_empty(),
                "{}: {problems:?}\n{}",
                g.name,
                record.reasoning
            );
        }
    }
}

#[test]
fn every_corruption_of_every_published_task_is_what_it_says() {
    let prompts = Prompts::builtin().expect("prompts");
    let records = RecordsConfig::default();
    let graph = GraphOptions::default();
    let instruction = layout_instruction(LAYOUT_GENERATION).expect("instruction");
    let mut made = [0usize; 3];
    for g in gallery() {
        let input = scene_input(&g);
        let tasks = write_scene_tasks(&input, &TasksConfig::default(), &prompts, &NoChat, 0)
            .expect("tasks")
            .records;
        let (lines, containers, _) = graph_of(&g.layout, &g.name);
        let scene = SceneRecordsInput {
            scene_id: input.scene_id.clone(),
            layout: g.layout.clone(),
            graph_lines: lines.clone(),
            containers,
            tasks: tasks.clone(),
            collider: Collider::Boxes,
        };
        let tolerance_cm = records.collision.tolerance_mm / 10.0;
        let before: BTreeSet<(String, String)> = colliding_names(&g.layout, tolerance_cm)
            .into_iter()
            .collect();
        for task in &tasks {
            let chosen =
                parse_model_output(&sft_record(&instruction, &scene, task).expect("sft").output)
                    .expect("chosen parses");
            for (k, corruption) in [
                Corruption::Collision,
                Corruption::Relation,
                Corruption::MissingObject,
            ]
            .into_iter()
            .enumerate()
            {
                let Ok(corrupted) = corrupt(corruption, &scene, task, &records, &graph, 0) else {
                    continue;
                };
                made[k] += 1;
                let rejected = parse_model_output(&corrupted.text).expect("rejected parses");
                assert!(!rejected.reasoning.is_empty());
                match corruption {
                    Corruption::Collision => {
                        let after: BTreeSet<(String, String)> =
                            colliding_names(&rejected.layout, tolerance_cm)
                                .into_iter()
                                .collect();
                        assert!(
                            after.difference(&before).next().is_some(),
                            "{}: no new colliding pair: {}",
                            g.name,
                            corrupted.detail
                        );
                        assert_eq!(rejected.reasoning, chosen.reasoning);
                        // Same objects, every one still inside the zone.
                        let names = |l: &LlmLayout| {
                            l.objects
                                .iter()
                                .map(|o| o.instance.clone())
                                .collect::<Vec<_>>()
                        };
                        assert_eq!(names(&rejected.layout), names(&chosen.layout));
                        let [x0, x1, y0, y1] = g.layout.zone_cm.0;
                        for o in &rejected.layout.objects {
                            assert!(
                                (x0..=x1).contains(&o.position_cm.0[0])
                                    && (y0..=y1).contains(&o.position_cm.0[1])
                            );
                        }
                    }
                    Corruption::Relation => {
                        assert_eq!(rejected.layout, chosen.layout, "the layout is unchanged");
                        assert_eq!(rejected.reasoning, chosen.reasoning);
                        assert_ne!(rejected.graph_lines, chosen.graph_lines);
                        // Every line of the rejected graph is a chosen line, or a chosen
                        // edge with its relation made wrong; node lines are all kept.
                        let chosen_set: BTreeSet<&String> = chosen.graph_lines.iter().collect();
                        for line in &rejected.graph_lines {
                            if chosen_set.contains(line) {
                                continue;
                            }
                            let f = triplet_fields(line).expect("triplet");
                            let replaces = WRONG_RELATION.iter().any(|(right, wrong)| {
                                *wrong == f[1]
                                    && chosen_set
                                        .contains(&format!("({}, {right}, {})", f[0], f[2]))
                            });
                            assert!(replaces, "{line} replaces no chosen edge");
                        }
                        let nodes = |lines: &[String]| -> Vec<String> {
                            lines
                                .iter()
                                .filter(|l| l.contains(", is at, ") || l.contains(", face to, "))
                                .cloned()
                                .collect()
                        };
                        assert_eq!(nodes(&rejected.graph_lines), nodes(&chosen.graph_lines));
                    }
                    Corruption::MissingObject => {
                        let kept: BTreeSet<&str> = rejected
                            .layout
                            .objects
                            .iter()
                            .map(|o| o.instance.as_str())
                            .collect();
                        let gone: Vec<&str> = chosen
                            .layout
                            .objects
                            .iter()
                            .map(|o| o.instance.as_str())
                            .filter(|i| !kept.contains(i))
                            .collect();
                        assert!(!gone.is_empty());
                        let types = SceneTypes::of_layout(&chosen.layout);
                        for instance in &gone {
                            // A task object, absent from the lines and from the counts.
                            let t = types
                                .types
                                .iter()
                                .find(|t| t.instances.iter().any(|i| i == instance))
                                .expect("type");
                            assert!(task
                                .task_info
                                .objects_cluster
                                .iter()
                                .any(|w| types.matching(w).iter().any(|m| m.key == t.key)));
                            assert!(rejected
                                .graph_lines
                                .iter()
                                .all(|l| !triplet_fields(l).expect("triplet").contains(instance)));
                        }
                        let remaining = SceneTypes::of_layout(&rejected.layout);
                        let problems = check_reasoning(&rejected.reasoning, &remaining, &[]);
                        assert!(
                            problems.is_empty(),
                            "counts follow the layout: {problems:?}"
                        );
                    }
                }
            }
            let (pairs, _) = dpo_pairs(
                &instruction,
                &scene,
                task,
                &sft_record(&instruction, &scene, task).expect("sft"),
                &records,
                &graph,
                0,
            );
            assert_eq!(pairs.len(), 2, "{}: two rejected per prompt", g.name);
            assert_ne!(pairs[0].corruption, pairs[1].corruption);
        }
    }
    println!(
        "corruptions made: collision {}, relation {}, missing object {}",
        made[0], made[1], made[2]
    );
    assert!(made.iter().all(|n| *n >= 30), "{made:?}");
}

//! The scene graph against the authors' published records (`realdata/layouts/mesatask_gallery`):
//! mesa's triplets over each record's `scene_layout_json`, with the keyword container rule,
//! compared with the record's own `scene_graph`.
//!
//! The records were written by the authors' trained model and are not all consistent with
//! their own layouts, so the rules cannot reproduce them fully; SCENE_GRAPH.md's rules give
//! precision 0.862 and recall 0.884 overall. The test prints the table and fails when either
//! drops below 0.85 (issue 8), or below the floors measured for these rules.
//!
//! The records are read from `$MESA_SHARED/realdata` (default: `../../shared/realdata` from
//! this crate), never copied into the repository.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use mesa_schemas::GalleryRecord;
use mesa_stages::graph::{extract_graph, keyword_containers, GraphOptions, GraphScene};

fn gallery_dir() -> PathBuf {
    let shared = std::env::var_os("MESA_SHARED")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared"));
    shared.join("realdata/layouts/mesatask_gallery")
}

struct Record {
    name: String,
    published: Vec<String>,
    ours: Vec<String>,
}

fn records() -> Vec<Record> {
    let dir = gallery_dir();
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| {
            panic!(
                "{}: {e} (set MESA_SHARED to the shared folder)",
                dir.display()
            )
        })
        .map(|entry| entry.expect("directory entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "json"))
        .collect();
    paths.sort();
    assert_eq!(
        paths.len(),
        7,
        "{}: expected the 7 published records",
        dir.display()
    );
    paths
        .iter()
        .map(|path| {
            let text = std::fs::read_to_string(path).expect("readable record");
            let record: GalleryRecord = serde_json::from_str(&text).expect("a gallery record");
            let layout = record.scene_layout_json.resolve().expect("an LLM layout");
            let scene = GraphScene::from_llm(&layout);
            let options = GraphOptions::default();
            let graph = extract_graph(&scene, &keyword_containers(&scene, &options), &options)
                .expect("a valid layout");
            Record {
                name: path
                    .file_stem()
                    .expect("file name")
                    .to_string_lossy()
                    .into_owned(),
                published: record.scene_graph.lines(),
                ours: graph.triplet_lines(),
            }
        })
        .collect()
}

/// The relation of a triplet line `(a, rel, b)`.
fn relation(line: &str) -> String {
    let inner = line.trim().trim_start_matches('(').trim_end_matches(')');
    inner.split(", ").nth(1).unwrap_or("?").to_owned()
}

#[derive(Default, Clone, Copy)]
struct Counts {
    ours: usize,
    published: usize,
    matched: usize,
}

impl Counts {
    fn add(&mut self, other: Counts) {
        self.ours += other.ours;
        self.published += other.published;
        self.matched += other.matched;
    }
    fn precision(&self) -> f64 {
        ratio(self.matched, self.ours)
    }
    fn recall(&self) -> f64 {
        ratio(self.matched, self.published)
    }
}

fn ratio(a: usize, b: usize) -> f64 {
    if b == 0 {
        1.0
    } else {
        a as f64 / b as f64
    }
}

/// Counts by relation (and `all`), matching triplets as sets.
fn compare(ours: &[String], published: &[String]) -> BTreeMap<String, Counts> {
    let ours: BTreeSet<&str> = ours.iter().map(String::as_str).collect();
    let published: BTreeSet<&str> = published.iter().map(|l| l.trim()).collect();
    let mut counts: BTreeMap<String, Counts> = BTreeMap::new();
    for line in &ours {
        let c = counts.entry(relation(line)).or_default();
        c.ours += 1;
        c.matched += usize::from(published.contains(line));
    }
    for line in &published {
        counts.entry(relation(line)).or_default().published += 1;
    }
    let mut all = Counts::default();
    for c in counts.values() {
        all.add(*c);
    }
    counts.insert("all".to_owned(), all);
    counts
}

#[test]
fn published_records_are_reproduced() {
    let records = records();
    let mut overall: BTreeMap<String, Counts> = BTreeMap::new();
    println!("record  ours  published  matched  precision  recall");
    for record in &records {
        let counts = compare(&record.ours, &record.published);
        let all = counts["all"];
        println!(
            "{:6}  {:4}  {:9}  {:7}  {:9.3}  {:6.3}",
            record.name,
            all.ours,
            all.published,
            all.matched,
            all.precision(),
            all.recall()
        );
        for (relation, c) in counts {
            overall.entry(relation).or_default().add(c);
        }
    }
    println!("\nrelation       ours  published  matched  precision  recall");
    for (relation, c) in &overall {
        println!(
            "{:13}  {:4}  {:9}  {:7}  {:9.3}  {:6.3}",
            relation,
            c.ours,
            c.published,
            c.matched,
            c.precision(),
            c.recall()
        );
    }
    let all = overall["all"];
    // Issue 8's bar.
    assert!(
        all.precision() >= 0.85,
        "overall precision {:.3} < 0.85",
        all.precision()
    );
    assert!(
        all.recall() >= 0.85,
        "overall recall {:.3} < 0.85",
        all.recall()
    );
    // Just under what the exact rules give (275 of 319 ours, 275 of 311 published): a drop
    // means a rule changed.
    assert!(
        all.precision() >= 0.86,
        "overall precision {:.3} < 0.86",
        all.precision()
    );
    assert!(
        all.recall() >= 0.88,
        "overall recall {:.3} < 0.88",
        all.recall()
    );
    for relation in ["is at", "face to"] {
        assert!(
            overall[relation].recall() >= 0.94,
            "{relation}: recall dropped"
        );
    }
}

/// The graph.txt of every record, pinned: a change to any rule shows here line by line.
#[test]
fn gallery_graph_text_is_stable() {
    for record in records() {
        let mut text = record.ours.join("\n");
        text.push('\n');
        insta::assert_snapshot!(format!("gallery_{}_graph_txt", record.name), text);
    }
}

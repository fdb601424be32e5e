//! `report` (SPEC 5.10): a dataset's statistics ([`compute_stats`]), its plots as SVG
//! ([`plots`], plotters' SVG backend) and one HTML page with a thumbnail, the QA flags and
//! the files of every scene ([`html`]). The facts of each scene ([`SceneFacts`]) are gathered by
//! the caller from the scene's files; everything here is a pure function of them, so the
//! report is the same for any thread count.

mod page;
mod plots;

use std::collections::BTreeMap;

use mesa_schemas::render::{
    Bin, CollisionStats, Distribution, NameCount, RateStats, ReportStats, REPORT_STATS_SCHEMA,
};

pub use page::html;
pub use plots::{plots, PlotError};

/// How many categories the statistics list.
pub const TOP_CATEGORIES: usize = 100;

/// What `qa/check.json` says of a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckFacts {
    /// The layout checked, relative to the scene folder.
    pub layout: String,
    /// Object pairs.
    pub pairs: u64,
    /// Colliding pairs.
    pub colliding: u64,
    /// The scene's collision rate.
    pub collision_rate: f64,
    /// Floating objects.
    pub floating: u64,
    /// Zone violations.
    pub zone_violations: u64,
}

/// A file of a scene the page links to.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SceneLink {
    /// The link text, like `layout`.
    pub label: String,
    /// The file, relative to the dataset folder.
    pub path: String,
}

/// What the report knows of one scene.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SceneFacts {
    /// The table type.
    pub table_type: String,
    /// The scene id.
    pub scene_id: String,
    /// The layout later stages read, relative to the scene folder; `None` without one.
    pub layout: Option<String>,
    /// The layout's objects: (instance, category).
    pub objects: Vec<(String, String)>,
    /// Relations of `graph/graph.json` by type (`is at` and `face to` count nodes).
    pub relations: BTreeMap<String, u64>,
    /// Whether the scene has a scene graph.
    pub has_graph: bool,
    /// The check of the layout checked (`qa/check.json`'s top level: the refined layout,
    /// before settling); `None`: not checked.
    pub check_before: Option<CheckFacts>,
    /// The check of the settled layout (`qa/check.json`'s `settle.after` when `mesa check
    /// --settle` wrote `qa/layout.json`).
    pub check_after: Option<CheckFacts>,
    /// Whether `mesa check --settle` ran on the scene (settled or not).
    pub settle_tried: bool,
    /// Views rendered (`front`, ...).
    pub rendered: Vec<String>,
    /// Objects not visible in the front view.
    pub hidden_in_front: Vec<String>,
    /// Whether the front render was made from another layout than the one later stages read.
    pub render_stale: bool,
    /// The thumbnail, relative to the report folder.
    pub thumbnail: Option<String>,
    /// Task records.
    pub tasks: u64,
    /// Stages whose last run failed on this scene, with the first line of the error.
    pub failed: Vec<(String, String)>,
    /// Warnings in the scene's done markers, by stage.
    pub warnings: BTreeMap<String, u64>,
    /// The scene's files worth opening.
    pub links: Vec<SceneLink>,
    /// Whether the scene entered by `mesa import`.
    pub imported: bool,
    /// Objects whose GLB the imported release does not ship: (instance, uid).
    pub missing_glbs: Vec<(String, String)>,
}

impl SceneFacts {
    /// `<table_type>/<scene_id>`.
    pub fn key(&self) -> String {
        format!("{}/{}", self.table_type, self.scene_id)
    }
}

/// The number of views a fully rendered scene has.
pub const VIEWS: usize = 5;

fn distribution(values: &[u64]) -> Distribution {
    let mut histogram = BTreeMap::new();
    for &v in values {
        *histogram.entry(v).or_insert(0) += 1;
    }
    let mut sorted = values.to_vec();
    sorted.sort_unstable();
    let median = match sorted.len() {
        0 => 0.0,
        n if n % 2 == 1 => sorted[n / 2] as f64,
        n => (sorted[n / 2 - 1] + sorted[n / 2]) as f64 / 2.0,
    };
    Distribution {
        histogram: histogram
            .into_iter()
            .map(|(value, count)| Bin { value, count })
            .collect(),
        min: sorted.first().copied().unwrap_or(0),
        max: sorted.last().copied().unwrap_or(0),
        mean: if sorted.is_empty() {
            0.0
        } else {
            sorted.iter().sum::<u64>() as f64 / sorted.len() as f64
        },
        median,
    }
}

fn rates<'a>(checks: impl Iterator<Item = &'a CheckFacts>) -> RateStats {
    let mut out = RateStats {
        scenes: 0,
        colliding_pairs: 0,
        pairs: 0,
        collision_rate: 0.0,
        mean_scene_rate: 0.0,
        scenes_with_collisions: 0,
        floating: 0,
        zone_violations: 0,
    };
    let mut rate_sum = 0.0;
    for c in checks {
        out.scenes += 1;
        out.colliding_pairs += c.colliding;
        out.pairs += c.pairs;
        rate_sum += c.collision_rate;
        out.scenes_with_collisions += u64::from(c.colliding > 0);
        out.floating += c.floating;
        out.zone_violations += c.zone_violations;
    }
    if out.pairs > 0 {
        out.collision_rate = out.colliding_pairs as f64 / out.pairs as f64;
    }
    if out.scenes > 0 {
        out.mean_scene_rate = rate_sum / out.scenes as f64;
    }
    out
}

/// The statistics of a dataset's scenes.
pub fn compute_stats(scenes: &[SceneFacts]) -> ReportStats {
    let mut table_types = BTreeMap::new();
    let mut layouts = BTreeMap::new();
    let mut categories: BTreeMap<&str, u64> = BTreeMap::new();
    let mut relations = BTreeMap::new();
    let mut failed = BTreeMap::new();
    let mut per_scene = Vec::new();
    for s in scenes {
        *table_types.entry(s.table_type.clone()).or_insert(0) += 1;
        let layout = s.layout.clone().unwrap_or_else(|| "none".to_owned());
        *layouts.entry(layout).or_insert(0) += 1;
        if s.layout.is_some() {
            per_scene.push(s.objects.len() as u64);
        }
        for (_, category) in &s.objects {
            *categories.entry(category.as_str()).or_insert(0) += 1;
        }
        for (relation, n) in &s.relations {
            *relations.entry(relation.clone()).or_insert(0) += n;
        }
        for (stage, _) in &s.failed {
            *failed.entry(stage.clone()).or_insert(0) += 1;
        }
    }
    let mut top: Vec<NameCount> = categories
        .iter()
        .map(|(name, count)| NameCount {
            name: (*name).to_owned(),
            count: *count,
        })
        .collect();
    top.sort_by(|a, b| b.count.cmp(&a.count).then_with(|| a.name.cmp(&b.name)));
    let distinct = top.len() as u64;
    top.truncate(TOP_CATEGORIES);
    let checked = scenes.iter().filter(|s| s.check_before.is_some()).count() as u64;
    // After settling: the layouts later stages read, the settled one where there is one and
    // the checked one elsewhere (as `mesa check`'s qa/summary.json counts them); only when
    // settling was tried somewhere.
    let tried = scenes.iter().any(|s| s.settle_tried);
    let after: Vec<&CheckFacts> = scenes
        .iter()
        .filter_map(|s| s.check_after.as_ref().or(s.check_before.as_ref()))
        .collect();
    ReportStats {
        schema: REPORT_STATS_SCHEMA.to_owned(),
        scenes: scenes.len() as u64,
        table_types,
        layouts,
        objects_per_scene: distribution(&per_scene),
        objects: per_scene.iter().sum(),
        categories: distinct,
        top_categories: top,
        relations,
        scenes_with_graph: scenes.iter().filter(|s| s.has_graph).count() as u64,
        collisions: CollisionStats {
            checked,
            not_checked: scenes.len() as u64 - checked,
            before: rates(scenes.iter().filter_map(|s| s.check_before.as_ref())),
            after: tried.then(|| rates(after.into_iter())),
        },
        scenes_rendered: scenes.iter().filter(|s| s.rendered.len() == VIEWS).count() as u64,
        tasks: scenes.iter().map(|s| s.tasks).sum(),
        failed,
        imported: scenes.iter().filter(|s| s.imported).count() as u64,
        objects_missing_glb: scenes.iter().map(|s| s.missing_glbs.len() as u64).sum(),
        scenes_with_missing_glb: scenes.iter().filter(|s| !s.missing_glbs.is_empty()).count()
            as u64,
        // The asset library's, filled in by the caller that reads assets/annotations.json.
        annotation_sources: BTreeMap::new(),
        annotation_placeholder_assets: 0,
    }
}

/// The QA flags of a scene, as (severity, text): severity `bad`, `warn` or `info`.
pub fn flags(scene: &SceneFacts) -> Vec<(&'static str, String)> {
    let mut out = Vec::new();
    for (stage, error) in &scene.failed {
        out.push(("bad", format!("{stage} failed: {error}")));
    }
    if !scene.missing_glbs.is_empty() {
        let named: Vec<String> = scene
            .missing_glbs
            .iter()
            .map(|(instance, uid)| format!("{instance} ({uid})"))
            .collect();
        out.push((
            "warn",
            format!(
                "{} objects without a GLB (the release does not ship it; left out of check \
                 and render): {}",
                named.len(),
                named.join(", ")
            ),
        ));
    }
    if scene.layout.is_none() {
        out.push(("bad", "no layout".to_owned()));
    } else if scene.layout.as_deref() == Some("coarse/layout.json") {
        out.push(("warn", "coarse layout (not refined)".to_owned()));
    }
    match (&scene.check_before, &scene.check_after) {
        (None, _) => out.push(("info", "not checked".to_owned())),
        (before, after) => {
            for (when, check) in [("before settling", before), ("settled", after)] {
                let Some(c) = check else { continue };
                if c.colliding > 0 {
                    out.push((
                        "bad",
                        format!(
                            "{} colliding pairs {when} (rate {:.3})",
                            c.colliding, c.collision_rate
                        ),
                    ));
                }
                if c.floating > 0 {
                    out.push(("bad", format!("{} floating {when}", c.floating)));
                }
                if c.zone_violations > 0 {
                    out.push((
                        "bad",
                        format!("{} zone violations {when}", c.zone_violations),
                    ));
                }
            }
            if scene.check_after.is_some() {
                out.push(("info", "settled".to_owned()));
            } else if scene.settle_tried {
                out.push((
                    "warn",
                    "settling failed (the checked layout stays)".to_owned(),
                ));
            }
        }
    }
    if scene.rendered.is_empty() {
        out.push(("warn", "not rendered".to_owned()));
    } else if scene.rendered.len() < VIEWS {
        out.push((
            "warn",
            format!("{} of {VIEWS} views rendered", scene.rendered.len()),
        ));
    }
    if scene.render_stale {
        out.push((
            "warn",
            "render of another layout (rerun `mesa render`)".to_owned(),
        ));
    }
    if !scene.hidden_in_front.is_empty() {
        out.push((
            "warn",
            format!(
                "hidden in the front view: {}",
                scene.hidden_in_front.join(", ")
            ),
        ));
    }
    if !scene.has_graph {
        out.push(("warn", "no scene graph".to_owned()));
    }
    if scene.tasks == 0 {
        out.push(("warn", "no tasks".to_owned()));
    }
    let warnings: u64 = scene.warnings.values().sum();
    if warnings > 0 {
        let by: Vec<String> = scene
            .warnings
            .iter()
            .map(|(stage, n)| format!("{stage} {n}"))
            .collect();
        let noun = if warnings == 1 { "warning" } else { "warnings" };
        out.push(("info", format!("{warnings} {noun} ({})", by.join(", "))));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene(id: &str, objects: &[&str]) -> SceneFacts {
        SceneFacts {
            table_type: "office_table".into(),
            scene_id: id.into(),
            layout: Some("refined/layout.json".into()),
            objects: objects
                .iter()
                .map(|o| {
                    (
                        (*o).to_owned(),
                        o.trim_end_matches(|c: char| c.is_ascii_digit() || c == '_')
                            .to_owned(),
                    )
                })
                .collect(),
            ..SceneFacts::default()
        }
    }

    #[test]
    fn stats_count_objects_categories_and_collision_rates() {
        let mut a = scene("a", &["mug_0", "mug_1", "book_0"]);
        a.check_before = Some(CheckFacts {
            layout: "refined/layout.json".into(),
            pairs: 3,
            colliding: 1,
            collision_rate: 1.0 / 3.0,
            floating: 0,
            zone_violations: 0,
        });
        let b = scene("b", &["mug_0"]);
        let stats = compute_stats(&[a, b]);
        assert_eq!(stats.scenes, 2);
        assert_eq!(stats.objects, 4);
        assert_eq!(
            stats.objects_per_scene.histogram,
            vec![Bin { value: 1, count: 1 }, Bin { value: 3, count: 1 }]
        );
        assert_eq!(stats.objects_per_scene.median, 2.0);
        assert_eq!(
            stats.top_categories[0],
            NameCount {
                name: "mug".into(),
                count: 3
            }
        );
        assert_eq!(stats.collisions.checked, 1);
        assert_eq!(stats.collisions.not_checked, 1);
        assert_eq!(stats.collisions.before.colliding_pairs, 1);
        assert!((stats.collisions.before.collision_rate - 1.0 / 3.0).abs() < 1e-12);
        assert!(stats.collisions.after.is_none());
    }

    #[test]
    fn after_settling_counts_the_layouts_later_stages_read() {
        let check = |colliding: u64| CheckFacts {
            layout: "refined/layout.json".into(),
            pairs: 10,
            colliding,
            collision_rate: colliding as f64 / 10.0,
            floating: 0,
            zone_violations: 0,
        };
        let mut settled = scene("a", &["mug_0"]);
        settled.check_before = Some(check(2));
        settled.check_after = Some(check(0));
        settled.settle_tried = true;
        let mut unsettled = scene("b", &["mug_0"]);
        unsettled.check_before = Some(check(1));
        unsettled.settle_tried = true;
        let stats = compute_stats(&[settled, unsettled.clone()]);
        assert_eq!(stats.collisions.before.colliding_pairs, 3);
        let after = stats.collisions.after.expect("settling was tried");
        assert_eq!(
            (after.scenes, after.colliding_pairs, after.pairs),
            (2, 1, 20)
        );
        assert!(flags(&unsettled)
            .iter()
            .any(|(_, f)| f.starts_with("settling failed")));
    }

    #[test]
    fn unchecked_scenes_say_so() {
        let flags = flags(&scene("a", &["mug_0"]));
        assert!(flags.iter().any(|(_, f)| f == "not checked"), "{flags:?}");
        assert!(flags.iter().any(|(_, f)| f == "not rendered"), "{flags:?}");
    }
}

//! The template backend: a deterministic writer of the table description, the tasks and the
//! reasoning texts, built from the layout and its scene graph, so the whole pipeline runs
//! offline. No model is involved; every record it produces says `"generator": "template"`.
//!
//! Its texts follow the same structure the prompts ask of a model and pass the same
//! validation. They are plain on purpose: they exercise the pipeline and give a baseline, not
//! the variety of a language model.

use std::collections::BTreeMap;

use mesa_schemas::artifacts::GraphArtifact;
use rand::seq::SliceRandom as _;
use rand::Rng as _;

use crate::seeding::rng_for;
use crate::tasks::types::{plural, ObjectType, SceneTypes};
use crate::tasks::validate::TaskDraft;

/// What the template needs of a scene.
#[derive(Debug, Clone, Copy)]
pub struct TemplateScene<'a> {
    /// The scene id (seeds the choices).
    pub scene_id: &'a str,
    /// The table type, like `office_table`.
    pub table_type: &'a str,
    /// The object types, in layout order.
    pub types: &'a SceneTypes,
    /// The scene graph (nodes: cell, facing, container flag; edges).
    pub graph: &'a GraphArtifact,
}

/// `office_table` → `office table`.
pub fn table_phrase(table_type: &str) -> String {
    table_type.replace(['_', '-'], " ")
}

fn article(noun: &str) -> &'static str {
    match noun.chars().next() {
        Some('a' | 'e' | 'i' | 'o' | 'u') => "an",
        _ => "a",
    }
}

fn count_word(n: usize) -> String {
    const WORDS: [&str; 13] = [
        "no", "one", "two", "three", "four", "five", "six", "seven", "eight", "nine", "ten",
        "eleven", "twelve",
    ];
    WORDS
        .get(n)
        .map_or_else(|| n.to_string(), |w| (*w).to_owned())
}

/// The lower-case noun of a type, plural when it has several objects.
fn noun(t: &ObjectType) -> String {
    let name = t.name.to_lowercase();
    if t.count() > 1 {
        match name.rsplit_once(' ') {
            Some((head, last)) => format!("{head} {}", plural(last)),
            None => plural(&name),
        }
    } else {
        name
    }
}

/// Where a nine-grid cell is, in words (`middle_left` → `on the left`).
fn cell_phrase(cell: &str) -> String {
    match cell {
        "center" => "at the center".to_owned(),
        "middle_left" => "on the left".to_owned(),
        "middle_right" => "on the right".to_owned(),
        "front_middle" => "at the front".to_owned(),
        "back_middle" => "at the back".to_owned(),
        other => format!("at the {}", other.replace('_', " ")),
    }
}

fn relation_phrase(relation: &str) -> &str {
    match relation {
        "left of" => "to the left of",
        "right of" => "to the right of",
        other => other,
    }
}

impl TemplateScene<'_> {
    fn node(&self, instance: &str) -> Option<&mesa_schemas::artifacts::GraphNode> {
        self.graph.nodes.iter().find(|n| n.instance == instance)
    }

    fn type_of(&self, instance: &str) -> Option<&ObjectType> {
        self.types
            .types
            .iter()
            .find(|t| t.instances.iter().any(|i| i == instance))
    }

    /// The most frequent cell of a type's objects (ties: the first in layout order).
    fn main_cell(&self, t: &ObjectType) -> String {
        let mut counts: Vec<(String, usize)> = Vec::new();
        for instance in &t.instances {
            let cell = self
                .node(instance)
                .map_or("center".to_owned(), |n| n.is_at.clone());
            match counts.iter_mut().find(|(c, _)| *c == cell) {
                Some((_, n)) => *n += 1,
                None => counts.push((cell, 1)),
            }
        }
        let best = counts.iter().map(|(_, n)| *n).max().unwrap_or(0);
        counts
            .into_iter()
            .find(|(_, n)| *n == best)
            .map_or_else(|| "center".to_owned(), |(c, _)| c)
    }

    fn is_container(&self, t: &ObjectType) -> bool {
        t.instances
            .iter()
            .any(|i| self.node(i).is_some_and(|n| n.container))
    }

    /// Mean x fraction of a type's cells: 0 for left, 0.5 middle, 1 right.
    fn side(&self, t: &ObjectType) -> f64 {
        let cell = self.main_cell(t);
        if cell.ends_with("left") {
            0.0
        } else if cell.ends_with("right") {
            1.0
        } else {
            0.5
        }
    }

    /// The table description: the table type and every type with its count and place.
    pub fn description(&self) -> String {
        let phrase = table_phrase(self.table_type);
        let mut items: Vec<String> = Vec::new();
        let mut length = 0;
        for (i, t) in self.types.types.iter().enumerate() {
            let item = format!(
                "{} {} {}",
                if t.count() == 1 {
                    article(&noun(t)).to_owned()
                } else {
                    count_word(t.count())
                },
                noun(t),
                cell_phrase(&self.main_cell(t))
            );
            length += item.len() + 2;
            if length > 900 {
                let rest = self.types.types.len() - i;
                items.push(format!("{} more kinds of objects", count_word(rest)));
                break;
            }
            items.push(item);
        }
        let list = match items.len() {
            0 => "nothing on it".to_owned(),
            1 => items[0].clone(),
            n => format!("{} and {}", items[..n - 1].join(", "), items[n - 1]),
        };
        format!("{} {phrase} with {list}.", capitalise(article(&phrase)))
    }

    /// Up to `count` different tasks, each over `min(min_objects, types)` object types (more for
    /// some kinds), chosen with a generator seeded by `seed` and the scene id.
    pub fn tasks(&self, count: usize, min_objects: usize, seed: u64) -> Vec<TaskDraft> {
        let mut rng = rng_for(seed, &["tasks/template", self.scene_id]);
        let types: Vec<&ObjectType> = self.types.types.iter().collect();
        if types.is_empty() {
            return Vec::new();
        }
        let want = min_objects.clamp(1, types.len());
        let start = rng.random_range(0..KINDS.len());
        let mut drafts: Vec<TaskDraft> = Vec::new();
        for k in 0..count * 6 {
            if drafts.len() == count {
                break;
            }
            let kind = KINDS[(start + k) % KINDS.len()];
            let mut picked = types.clone();
            picked.shuffle(&mut rng);
            if let Some(draft) = self.build(kind, &picked, want, &mut rng) {
                if !drafts.iter().any(|d| d.task == draft.task) {
                    drafts.push(draft);
                }
            }
        }
        drafts
    }

    fn build(
        &self,
        kind: Kind,
        shuffled: &[&ObjectType],
        want: usize,
        rng: &mut rand_chacha::ChaCha8Rng,
    ) -> Option<TaskDraft> {
        let the = |t: &ObjectType| format!("the {}", noun(t));
        let away = |ts: &[&ObjectType]| {
            let mean = ts.iter().map(|t| self.side(t)).sum::<f64>() / ts.len() as f64;
            if mean <= 0.5 {
                "right side"
            } else {
                "left side"
            }
        };
        let listing = |ts: &[&ObjectType]| -> String {
            let names: Vec<String> = ts.iter().map(|t| the(t)).collect();
            match names.len() {
                1 => names[0].clone(),
                n => format!("{} and {}", names[..n - 1].join(", "), names[n - 1]),
            }
        };
        let cluster = |ts: &[&ObjectType]| ts.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
        let mut goal = Vec::new();
        let mut actions = Vec::new();
        let picked: Vec<&ObjectType>;
        let task;
        match kind {
            Kind::Gather => {
                picked = shuffled[..want].to_vec();
                let target = format!("front {}", away(&picked).replace(" side", " corner"));
                task = format!("Gather {} at the {target} of the table", listing(&picked));
                for (i, t) in picked.iter().enumerate() {
                    goal.push(format!("Pick up {}", the(t)));
                    actions.push(format!("Pick({})", t.name));
                    if i == 0 {
                        goal.push(format!("Place {} at the {target}", the(t)));
                        actions.push(format!("PlaceAt({target})"));
                    } else {
                        goal.push(format!("Place {} next to {}", the(t), the(picked[i - 1])));
                        actions.push(format!("PlaceAt(next to {})", picked[i - 1].name));
                    }
                }
            }
            Kind::Line => {
                picked = shuffled[..want].to_vec();
                let edge = if rng.random_bool(0.5) {
                    "back"
                } else {
                    "front"
                };
                task = format!(
                    "Line up {} along the {edge} edge of the table",
                    listing(&picked)
                );
                for (i, t) in picked.iter().enumerate() {
                    goal.push(format!("Pick up {}", the(t)));
                    actions.push(format!("Pick({})", t.name));
                    if i == 0 {
                        goal.push(format!("Place {} at the {edge} edge", the(t)));
                        actions.push(format!("PlaceAt({edge} edge)"));
                    } else {
                        goal.push(format!(
                            "Place {} to the right of {} along the {edge} edge",
                            the(t),
                            the(picked[i - 1])
                        ));
                        actions.push(format!("PlaceAt(right of {})", picked[i - 1].name));
                    }
                }
            }
            Kind::Contain => {
                let container = shuffled.iter().find(|t| self.is_container(t))?;
                let others: Vec<&ObjectType> = shuffled
                    .iter()
                    .filter(|t| t.key != container.key && !self.is_container(t))
                    .copied()
                    .collect();
                if others.is_empty() {
                    return None;
                }
                let mut items: Vec<&ObjectType> =
                    others[..(want.saturating_sub(1)).clamp(1, others.len())].to_vec();
                // Too few other kinds (the other types are containers too, say a bowl, a tray
                // and a mug): the other containers are set beside it as well, so the task
                // still involves `want` types. Only the first item goes into the container.
                if items.len() + 1 < want {
                    let extra: Vec<&ObjectType> = shuffled
                        .iter()
                        .filter(|t| t.key != container.key && self.is_container(t))
                        .copied()
                        .take(want - 1 - items.len())
                        .collect();
                    items.extend(extra);
                }
                if items.len() + 1 < want {
                    return None;
                }
                let items = &items[..];
                picked = std::iter::once(*container)
                    .chain(items.iter().copied())
                    .collect();
                let first = items[0];
                task = if items.len() == 1 {
                    format!("Put {} into {}", the(first), the(container))
                } else {
                    format!(
                        "Put {} into {}, then set {} beside it",
                        the(first),
                        the(container),
                        listing(&items[1..])
                    )
                };
                goal.push(format!("Pick up {}", the(first)));
                actions.push(format!("Pick({})", first.name));
                goal.push(format!("Place {} in {}", the(first), the(container)));
                actions.push(format!("PlaceOn({})", container.name));
                for t in &items[1..] {
                    goal.push(format!("Pick up {}", the(t)));
                    actions.push(format!("Pick({})", t.name));
                    goal.push(format!("Place {} beside {}", the(t), the(container)));
                    actions.push(format!("PlaceAt(beside {})", container.name));
                }
            }
            Kind::Clear => {
                picked = shuffled[..want].to_vec();
                let to = away(&picked);
                let from = if to == "right side" {
                    "left side"
                } else {
                    "right side"
                };
                task = format!(
                    "Clear the {from} of the table by moving {} to the {to}",
                    listing(&picked)
                );
                for t in &picked {
                    goal.push(format!("Pick up {}", the(t)));
                    actions.push(format!("Pick({})", t.name));
                    goal.push(format!("Place {} on the {to}", the(t)));
                    actions.push(format!("PlaceAt({to})"));
                }
            }
            Kind::Push => {
                if want < 2 {
                    return None;
                }
                picked = shuffled[..want].to_vec();
                let pushed = picked[0];
                // With three or more types the middle ones move in front of the last; with two,
                // the second moves in front of the pushed one.
                let (movers, anchor): (Vec<&ObjectType>, &ObjectType) = if picked.len() > 2 {
                    (
                        picked[1..picked.len() - 1].to_vec(),
                        picked[picked.len() - 1],
                    )
                } else {
                    (vec![picked[1]], pushed)
                };
                task = format!(
                    "Push {} toward the back of the table, then place {} in front of {}",
                    the(pushed),
                    listing(&movers),
                    the(anchor)
                );
                goal.push(format!("Push {} 10 cm toward the back", the(pushed)));
                actions.push(format!("Push({}, back, 10 cm)", pushed.name));
                for t in movers {
                    goal.push(format!("Pick up {}", the(t)));
                    actions.push(format!("Pick({})", t.name));
                    goal.push(format!("Place {} in front of {}", the(t), the(anchor)));
                    actions.push(format!("PlaceAt(in front of {})", anchor.name));
                }
            }
            Kind::Swap => {
                if want < 2 {
                    return None;
                }
                picked = shuffled[..want].to_vec();
                let (a, b) = (picked[0], picked[1]);
                task = if let Some(c) = picked.get(2) {
                    format!(
                        "Swap the places of {} and {}, then put {} between them",
                        the(a),
                        the(b),
                        the(c)
                    )
                } else {
                    format!("Swap the places of {} and {}", the(a), the(b))
                };
                goal.push(format!("Pick up {}", the(a)));
                actions.push(format!("Pick({})", a.name));
                goal.push(format!("Place {} where {} stands", the(a), the(b)));
                actions.push(format!("PlaceAt(place of {})", b.name));
                goal.push(format!("Pick up {}", the(b)));
                actions.push(format!("Pick({})", b.name));
                goal.push(format!("Place {} where {} stood", the(b), the(a)));
                actions.push(format!("PlaceAt(former place of {})", a.name));
                if let Some(c) = picked.get(2) {
                    goal.push(format!("Pick up {}", the(c)));
                    actions.push(format!("Pick({})", c.name));
                    goal.push(format!(
                        "Place {} between {} and {}",
                        the(c),
                        the(a),
                        the(b)
                    ));
                    actions.push(format!("PlaceAt(between {} and {})", a.name, b.name));
                }
            }
        }
        Some(TaskDraft {
            task,
            goal,
            action_sequence: actions,
            objects_cluster: cluster(&picked),
        })
    }

    /// The reasoning text of a task whose objects are the types `core` (keys): an
    /// introduction, the two lists, the placement paragraph built from the scene graph, and the
    /// closing sentence.
    pub fn reasoning(&self, task: &str, core_keys: &[String]) -> String {
        let phrase = table_phrase(self.table_type);
        let (core, environment): (Vec<&ObjectType>, Vec<&ObjectType>) = self
            .types
            .types
            .iter()
            .partition(|t| core_keys.contains(&t.key));
        let core_count: usize = core.iter().map(|t| t.count()).sum();
        let total = self.types.object_count();
        let mut text = format!(
            "The goal is a layout of {} {phrase} on which a robot can {}. The table holds {} \
             objects: {} that the task involves and {} that complete the scene.\n\n",
            article(&phrase),
            lower_first(task.trim_end_matches('.')),
            count_word(total),
            count_word(core_count),
            count_word(total - core_count),
        );
        text.push_str("**Core Task Objects:**\n");
        text.push_str(&SceneTypes::list(core.iter().copied()));
        text.push_str("\n\n**Environment Objects:**\n");
        text.push_str(&SceneTypes::list(environment.iter().copied()));
        text.push_str("\n\n");
        let mut sentences: Vec<String> = Vec::new();
        for t in &self.types.types {
            let cells: Vec<String> = {
                let mut cells: Vec<String> = Vec::new();
                for i in &t.instances {
                    let cell = self
                        .node(i)
                        .map_or("center".to_owned(), |n| n.is_at.clone());
                    if !cells.contains(&cell) {
                        cells.push(cell);
                    }
                }
                cells
            };
            let facing = t
                .instances
                .first()
                .and_then(|i| self.node(i))
                .map(|n| n.face_to.as_str())
                .filter(|f| *f != "front")
                .map(|f| format!(", facing {}", f.replace('_', " ")))
                .unwrap_or_default();
            let place = if cells.len() == 1 {
                cell_phrase(&cells[0])
            } else {
                let phrases: Vec<String> = cells.iter().map(|c| cell_phrase(c)).collect();
                format!(
                    "spread {} and {}",
                    phrases[..phrases.len() - 1].join(", "),
                    phrases[phrases.len() - 1]
                )
            };
            sentences.push(if t.count() == 1 {
                format!("The {} stands {place}{facing}.", noun(t))
            } else {
                format!(
                    "{} {} stand {place}.",
                    capitalise(&count_word(t.count())),
                    noun(t)
                )
            });
        }
        let mut said: BTreeMap<(String, String, String), ()> = BTreeMap::new();
        for edge in &self.graph.edges {
            let (Some(a), Some(b)) = (self.type_of(&edge.subject), self.type_of(&edge.object))
            else {
                continue;
            };
            let horizontal = !matches!(edge.relation.as_str(), "in" | "above");
            if horizontal && !core_keys.contains(&a.key) {
                continue;
            }
            let key = (a.key.clone(), edge.relation.clone(), b.key.clone());
            if said.insert(key, ()).is_some() || a.key == b.key {
                continue;
            }
            let subject = if a.count() > 1 {
                format!("A {}", a.name.to_lowercase())
            } else {
                format!("The {}", a.name.to_lowercase())
            };
            let object = if b.count() > 1 {
                format!("one of the {}", noun(b))
            } else {
                format!("the {}", b.name.to_lowercase())
            };
            sentences.push(match edge.relation.as_str() {
                "in" => format!("{subject} sits in {object}."),
                "above" => format!("{subject} rests on {object}."),
                other => format!("{subject} is {} {object}.", relation_phrase(other)),
            });
        }
        let core_names: Vec<String> = core.iter().map(|t| noun(t)).collect();
        sentences.push(format!(
            "This keeps the {} within reach for the task, while the other objects complete the \
             {phrase}.",
            if core_names.is_empty() {
                "objects".to_owned()
            } else {
                core_names.join(", ")
            }
        ));
        sentences
            .push("Based on this task analysis, the scene graph is arranged as follows:".into());
        text.push_str(&sentences.join(" "));
        text
    }
}

fn capitalise(text: &str) -> String {
    let mut chars = text.chars();
    match chars.next() {
        Some(first) => first.to_uppercase().chain(chars).collect(),
        None => String::new(),
    }
}

fn lower_first(text: &str) -> String {
    let mut chars = text.chars();
    match chars.next() {
        Some(first) => first.to_lowercase().chain(chars).collect(),
        None => String::new(),
    }
}

#[derive(Debug, Clone, Copy)]
enum Kind {
    Gather,
    Line,
    Contain,
    Clear,
    Push,
    Swap,
}

const KINDS: [Kind; 6] = [
    Kind::Gather,
    Kind::Contain,
    Kind::Line,
    Kind::Push,
    Kind::Clear,
    Kind::Swap,
];

#[cfg(test)]
mod tests {
    use mesa_schemas::artifacts::{GraphNode, GRAPH_SCHEMA};

    use super::*;
    use crate::tasks::validate::check_task;

    fn scene_graph(instances: &[(&str, bool)]) -> GraphArtifact {
        GraphArtifact {
            schema: GRAPH_SCHEMA.to_owned(),
            scene_id: "coffee_table_0009".to_owned(),
            layout: "refined/layout.json".to_owned(),
            nodes: instances
                .iter()
                .map(|(instance, container)| GraphNode {
                    instance: (*instance).to_owned(),
                    is_at: "center".to_owned(),
                    face_to: "front".to_owned(),
                    container: *container,
                })
                .collect(),
            edges: Vec::new(),
            equally_spaced: Vec::new(),
        }
    }

    /// `coffee_table_0009` of `mesa demo --scenes 100 --seed 5`: three types, two of them
    /// containers. A "put X into the container" task found a single non-container type and
    /// involved two types, which its own validation refused (a failed scene, "a bug in mesa").
    #[test]
    fn every_task_involves_enough_types_when_most_types_are_containers() {
        let instances = [
            ("bowl_0", true),
            ("tray_0", true),
            ("mug_0", false),
            ("mug_1", false),
        ];
        let graph = scene_graph(&instances);
        let types = SceneTypes::of_instances(instances.iter().map(|(i, _)| *i));
        assert_eq!(types.types.len(), 3);
        let mut contain_tasks = 0;
        for k in 0..40 {
            let scene_id = format!("coffee_table_{k:04}");
            let scene = TemplateScene {
                scene_id: &scene_id,
                table_type: "coffee_table",
                types: &types,
                graph: &graph,
            };
            let drafts = scene.tasks(5, 3, 5);
            assert_eq!(drafts.len(), 5, "{scene_id}");
            for draft in &drafts {
                let problems = check_task(draft, &types, 3);
                assert!(
                    problems.is_empty(),
                    "{scene_id}: {}: {problems:?}",
                    draft.task
                );
                contain_tasks += usize::from(draft.task.starts_with("Put "));
            }
        }
        // Control: the case that failed is exercised.
        assert!(contain_tasks > 0);
    }

    /// A container type with no other kind of object to put into it gives no "put into" task,
    /// and the other kinds of task still fill the scene.
    #[test]
    fn a_scene_of_containers_only_still_gets_its_tasks() {
        let instances = [("bowl_0", true), ("tray_0", true), ("basket_0", true)];
        let graph = scene_graph(&instances);
        let types = SceneTypes::of_instances(instances.iter().map(|(i, _)| *i));
        let scene = TemplateScene {
            scene_id: "coffee_table_0001",
            table_type: "coffee_table",
            types: &types,
            graph: &graph,
        };
        let drafts = scene.tasks(5, 3, 5);
        assert!(!drafts.is_empty());
        for draft in &drafts {
            assert!(check_task(draft, &types, 3).is_empty(), "{}", draft.task);
            assert!(!draft.task.starts_with("Put "), "{}", draft.task);
        }
    }
}

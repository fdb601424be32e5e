//! The reasoning text: its required structure, read back, checked against the scene, and
//! rewritten when an object is removed (the missing-object corruption of `mesa records`).
//!
//! Structure (SPEC 5.8, as the published records have it): an introduction, a line holding
//! the header `Core Task Objects:` then the task's types as `Type(count)` separated by commas,
//! the same under `Environment Objects:` for every other type, a placement paragraph, and a
//! closing sentence that leads into the scene graph and ends with a colon. The headers may be
//! bold (`**Core Task Objects:**`) and the list may follow on the same line or the next ones.

use std::ops::Range;

use crate::tasks::types::SceneTypes;
use crate::tasks::validate::ReplyProblems;

/// The exact header of the task objects list.
pub const CORE_HEADER: &str = "Core Task Objects:";
/// The exact header of the environment objects list.
pub const ENVIRONMENT_HEADER: &str = "Environment Objects:";

/// A `Type(count)` item of a reasoning list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CountedType {
    /// The type as written.
    pub name: String,
    /// The count as written.
    pub count: usize,
}

/// The two lists of a reasoning text, with where their text lies.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReasoningLists {
    /// The items under `Core Task Objects:`.
    pub core: Vec<CountedType>,
    /// The items under `Environment Objects:`.
    pub environment: Vec<CountedType>,
    /// Byte range of the core list's text (after its header, up to the blank line or the next
    /// header).
    pub core_span: Range<usize>,
    /// Byte range of the environment list's text.
    pub environment_span: Range<usize>,
    /// The text after the environment list (the placement paragraph and closing sentence).
    pub rest_start: usize,
}

/// Reads the two lists of a reasoning text; every structural problem is reported.
pub fn read_lists(text: &str) -> Result<ReasoningLists, ReplyProblems> {
    lists_of(text).map_err(ReplyProblems)
}

fn lists_of(text: &str) -> Result<ReasoningLists, Vec<String>> {
    let mut problems = Vec::new();
    let core_at = find_once(text, CORE_HEADER, &mut problems);
    let env_at = find_once(text, ENVIRONMENT_HEADER, &mut problems);
    let (Some(core_at), Some(env_at)) = (core_at, env_at) else {
        return Err(problems);
    };
    if env_at < core_at {
        problems.push(format!(
            "\"{ENVIRONMENT_HEADER}\" comes before \"{CORE_HEADER}\" (expected the task objects first)"
        ));
        return Err(problems);
    }
    let core = read_list(text, core_at + CORE_HEADER.len(), env_at);
    let environment = read_list(text, env_at + ENVIRONMENT_HEADER.len(), text.len());
    let ((core_span, core), (environment_span, environment)) = match (core, environment) {
        (Ok(core), Ok(environment)) => (core, environment),
        (core, environment) => {
            for (header, list) in [(CORE_HEADER, core), (ENVIRONMENT_HEADER, environment)] {
                if let Err(found) = list {
                    problems.push(format!(
                        "{found} follows \"{header}\" (expected Type(count), ... or None on the \
                         header's line or the next one)"
                    ));
                }
            }
            return Err(problems);
        }
    };
    Ok(ReasoningLists {
        core,
        environment,
        rest_start: environment_span.end,
        core_span,
        environment_span,
    })
}

fn find_once(text: &str, header: &str, problems: &mut Vec<String>) -> Option<usize> {
    let mut found = text.match_indices(header).map(|(i, _)| i);
    match (found.next(), found.next()) {
        (Some(at), None) => Some(at),
        (None, _) => {
            problems.push(format!("the header \"{header}\" is missing"));
            None
        }
        (Some(_), Some(_)) => {
            problems.push(format!(
                "the header \"{header}\" appears more than once (expected once)"
            ));
            None
        }
    }
}

/// The list after a header: the rest of the header's line when it holds a list (after any
/// `**` closing a bold header), else the first non-blank line after it; then every following
/// line that is a list line too. A list line is `None` or `Type(count)` items separated by
/// commas or semicolons, each perhaps behind a bullet. The span covers the list lines without
/// their final line break; `stop` bounds the search. The error says what stands there instead.
fn read_list(
    text: &str,
    after_header: usize,
    stop: usize,
) -> Result<(Range<usize>, Vec<CountedType>), String> {
    let mut at = after_header;
    let bytes = text.as_bytes();
    while at < stop && (bytes[at] == b'*' || bytes[at] == b' ' || bytes[at] == b'\t') {
        at += 1;
    }
    let line_at = |from: usize| -> (usize, usize) {
        let end = text[from..stop].find('\n').map_or(stop, |i| from + i);
        (from, end)
    };
    // The header's own line, or the next non-blank one.
    let (mut start, mut end) = line_at(at);
    if text[start..end].trim().is_empty() {
        let mut next = end + 1;
        loop {
            if next >= stop {
                return Err("nothing".to_owned());
            }
            (start, end) = line_at(next);
            if !text[start..end].trim().is_empty() {
                break;
            }
            next = end + 1;
        }
    }
    let Some(mut items) = list_line(&text[start..end]) else {
        return Err(format!("\"{}\"", text[start..end].trim()));
    };
    let mut span_end = end;
    while span_end + 1 < stop {
        let (next_start, next_end) = line_at(span_end + 1);
        match list_line(&text[next_start..next_end]) {
            Some(more) if !text[next_start..next_end].trim().is_empty() => {
                items.extend(more);
                span_end = next_end;
            }
            _ => break,
        }
    }
    while span_end > start && text.as_bytes()[span_end - 1] == b'\r' {
        span_end -= 1;
    }
    Ok((start..span_end, items))
}

/// The items of one list line, or `None` when it is not a list line.
fn list_line(line: &str) -> Option<Vec<CountedType>> {
    let trimmed = line.trim();
    if trimmed.trim_end_matches('.').eq_ignore_ascii_case("none") {
        return Some(Vec::new());
    }
    let mut items = Vec::new();
    for raw in trimmed.split([',', ';']) {
        let item = raw
            .trim()
            .trim_start_matches(['-', '*', '•'])
            .trim()
            .trim_end_matches('.');
        if item.is_empty() {
            continue;
        }
        items.push(parse_item(item)?);
    }
    (!items.is_empty()).then_some(items)
}

/// `Name(count)` or `Name (count)`.
fn parse_item(item: &str) -> Option<CountedType> {
    let open = item.rfind('(')?;
    let inner = item[open + 1..].strip_suffix(')')?;
    let count: usize = inner.trim().parse().ok()?;
    let name = item[..open].trim().trim_matches('*').trim();
    (!name.is_empty()).then(|| CountedType {
        name: name.to_owned(),
        count,
    })
}

/// Checks a reasoning text against its scene and task: the structure above; every type
/// listed once, matching a type of the layout with that type's count; the two lists together
/// covering every type of the layout; every task type (`task_types`, written types of the
/// task's `Objects cluster`) under the core list; and the closing sentence.
pub fn check_reasoning(text: &str, scene: &SceneTypes, task_types: &[String]) -> Vec<String> {
    let mut problems = Vec::new();
    if text.trim().is_empty() {
        return vec!["the reasoning text is empty".to_owned()];
    }
    if text.contains(mesa_schemas::output::FINAL_ANSWER_MARKER.trim()) {
        problems.push("the reasoning contains the final-answer marker".to_owned());
    }
    let lists = match read_lists(text) {
        Ok(lists) => lists,
        Err(ReplyProblems(mut found)) => {
            problems.append(&mut found);
            return problems;
        }
    };
    let mut seen: Vec<(&str, &str)> = Vec::new();
    let mut core_keys = Vec::new();
    for (header, items) in [
        (CORE_HEADER, &lists.core),
        (ENVIRONMENT_HEADER, &lists.environment),
    ] {
        for item in items {
            let matches = scene.matching(&item.name);
            let [scene_type] = matches.as_slice() else {
                problems.push(if matches.is_empty() {
                    format!(
                        "\"{}\" under \"{header}\" is no type of the layout (its types: {})",
                        item.name,
                        SceneTypes::list(&scene.types)
                    )
                } else {
                    format!("\"{}\" under \"{header}\" names several types", item.name)
                });
                continue;
            };
            if let Some((_, other)) = seen.iter().find(|(k, _)| *k == scene_type.key) {
                problems.push(format!(
                    "{} is listed twice (under \"{other}\" and \"{header}\")",
                    scene_type.name
                ));
                continue;
            }
            seen.push((scene_type.key.as_str(), header));
            if header == CORE_HEADER {
                core_keys.push(scene_type.key.as_str());
            }
            if item.count != scene_type.count() {
                problems.push(format!(
                    "{}({}) under \"{header}\": the layout has {} (expected {})",
                    item.name,
                    item.count,
                    scene_type.count(),
                    scene_type.with_count()
                ));
            }
        }
    }
    let missing: Vec<String> = scene
        .types
        .iter()
        .filter(|t| !seen.iter().any(|(k, _)| *k == t.key))
        .map(|t| t.with_count())
        .collect();
    if !missing.is_empty() {
        problems.push(format!(
            "the lists leave out {} (expected every type of the layout once)",
            missing.join(", ")
        ));
    }
    for written in task_types {
        let matches = scene.matching(written);
        if !matches.is_empty() && !matches.iter().any(|t| core_keys.contains(&t.key.as_str())) {
            problems.push(format!(
                "the task's object type \"{written}\" is not under \"{CORE_HEADER}\""
            ));
        }
    }
    let closing = last_sentence(&text[lists.rest_start..]);
    if closing.is_empty() {
        problems.push(
            "no text after the lists (expected a placement paragraph and a closing sentence \
             leading to the scene graph)"
                .to_owned(),
        );
    } else if !closing.ends_with(':') || !closing.to_lowercase().contains("scene graph") {
        problems.push(format!(
            "the last sentence \"{closing}\" does not lead into the scene graph (expected a \
             sentence naming the scene graph and ending with a colon)"
        ));
    }
    // A last line shaped like a triplet would be read as part of the scene graph.
    if text
        .lines()
        .any(|l| l.trim().starts_with('(') && l.trim().ends_with(')'))
    {
        problems.push(
            "a line of the reasoning looks like a scene-graph triplet (expected prose only)"
                .to_owned(),
        );
    }
    problems
}

/// The last sentence of a text: from after the previous `.`, `!` or `?` followed by a space
/// (or a line break) to the end, trimmed.
pub fn last_sentence(text: &str) -> &str {
    let text = text.trim();
    let bytes = text.as_bytes();
    let mut start = 0;
    for i in 0..bytes.len().saturating_sub(1) {
        if matches!(bytes[i], b'.' | b'!' | b'?' | b'\n') && bytes[i + 1].is_ascii_whitespace() {
            start = i + 1;
        }
    }
    text[start..].trim()
}

/// The reasoning text with fewer objects of some types: `removed` holds (scene type key,
/// objects removed); each listed item is matched to a type of `scene` as the checks match it,
/// its count lowered, and dropped at zero (a list left empty says `None`); both lists are
/// rewritten as `Type(count), ...`. `None` when the text has no readable lists.
pub fn rewrite_counts(
    text: &str,
    scene: &SceneTypes,
    removed: &[(String, usize)],
) -> Option<String> {
    let lists = read_lists(text).ok()?;
    let render = |items: &[CountedType]| -> String {
        let kept: Vec<String> = items
            .iter()
            .filter_map(|item| {
                let matches = scene.matching(&item.name);
                let minus: usize = removed
                    .iter()
                    .filter(|(key, _)| matches.len() == 1 && matches[0].key == *key)
                    .map(|(_, n)| *n)
                    .sum();
                let count = item.count.saturating_sub(minus);
                (count > 0).then(|| format!("{}({count})", item.name))
            })
            .collect();
        if kept.is_empty() {
            "None".to_owned()
        } else {
            kept.join(", ")
        }
    };
    let mut out = String::with_capacity(text.len());
    out.push_str(&text[..lists.core_span.start]);
    out.push_str(&render(&lists.core));
    out.push_str(&text[lists.core_span.end..lists.environment_span.start]);
    out.push_str(&render(&lists.environment));
    out.push_str(&text[lists.environment_span.end..]);
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    const GALLERY_STYLE: &str = "The goal is a tabletop for sorting fruit.\n\n\
        **Core Task Objects:**  \nFruit(5), Bowl(2), Tray(1), Desk Lamp(1)\n\n\
        **Environment Objects:**  \nCarafe(2), Potted Plant(1)\n\n\
        The lamp stands on the left. Based on this task analysis, the scene graph is arranged as follows:";

    fn scene() -> SceneTypes {
        SceneTypes::of_instances([
            "tray_0",
            "bowl_1",
            "desk_lamp_0",
            "plant_0",
            "bowl_0",
            "carafe_1",
            "carafe_0",
            "fruit_0",
            "fruit_1",
            "fruit_4",
            "fruit_5",
            "fruit_2",
        ])
    }

    #[test]
    fn the_published_form_reads_and_checks() {
        let lists = read_lists(GALLERY_STYLE).expect("lists");
        assert_eq!(lists.core.len(), 4);
        assert_eq!(
            lists.environment[1],
            CountedType {
                name: "Potted Plant".into(),
                count: 1
            }
        );
        let problems = check_reasoning(GALLERY_STYLE, &scene(), &["Fruit".into(), "Tray".into()]);
        assert!(problems.is_empty(), "{problems:?}");
    }

    #[test]
    fn wrong_counts_missing_types_and_headers_are_reported() {
        let wrong = GALLERY_STYLE.replace("Fruit(5)", "Fruit(4)");
        let problems = check_reasoning(&wrong, &scene(), &[]);
        assert!(problems[0].contains("the layout has 5"), "{problems:?}");
        let short = GALLERY_STYLE.replace(", Potted Plant(1)", "");
        let problems = check_reasoning(&short, &scene(), &[]);
        assert!(problems[0].contains("leave out Plant(1)"), "{problems:?}");
        let misplaced = check_reasoning(GALLERY_STYLE, &scene(), &["Carafe".into()]);
        assert!(
            misplaced[0].contains("\"Carafe\" is not under"),
            "{misplaced:?}"
        );
        let no_header = GALLERY_STYLE.replace("Core Task Objects:", "Task objects:");
        assert!(check_reasoning(&no_header, &scene(), &[])[0].contains("is missing"));
        let no_closing = GALLERY_STYLE.replace(
            " Based on this task analysis, the scene graph is arranged as follows:",
            "",
        );
        assert!(check_reasoning(&no_closing, &scene(), &[])[0].contains("last sentence"));
    }

    #[test]
    fn counts_are_rewritten_and_empty_types_dropped() {
        let out = rewrite_counts(
            GALLERY_STYLE,
            &scene(),
            &[
                ("fruit".into(), 2),
                ("desk lamp".into(), 1),
                ("plant".into(), 1),
            ],
        )
        .expect("rewrites");
        assert!(out.contains("**Core Task Objects:**  \nFruit(3), Bowl(2), Tray(1)\n\n"));
        // "Potted Plant" is the scene's `plant`, matched as the checks match it.
        assert!(
            out.contains("**Environment Objects:**  \nCarafe(2)\n\nThe lamp"),
            "{out}"
        );
        let lists = read_lists(&out).expect("still readable");
        assert_eq!(lists.core.len(), 3);
    }

    #[test]
    fn same_line_lists_and_none_are_read() {
        let text = "Intro.\nCore Task Objects: Mug(1), Tray (2)\nEnvironment Objects: None\n\
                    Placement. The scene graph follows:";
        let lists = read_lists(text).expect("lists");
        assert_eq!(lists.core.len(), 2);
        assert!(lists.environment.is_empty());
        assert_eq!(
            last_sentence(&text[lists.rest_start..]),
            "The scene graph follows:"
        );
    }
}

//! The GPT score of `mesa eval` (MesaTask paper §5): a chat model sees the front and
//! perspective views of a generated scene with its task and scores it from 1 to 10 on five
//! criteria; a sample's GPT score is the mean of the five, the run's the mean over samples.
//!
//! This module holds what is pure: the `[eval]` settings, the prompt template
//! (`data/prompts/gpt_score.txt`, replaceable by `[eval] gpt_score_prompt`), the request body
//! ([`score_request`]), the validation of a reply ([`parse_score_reply`]) and the aggregate
//! ([`aggregate_gpt_scores`]). The pipeline sends the requests through its chat client (live,
//! or offline batches through the reply cache, as `mesa tasks` does).

use std::collections::BTreeMap;

use mesa_schemas::eval::{CriterionScore, GptScoreMetrics, SampleGptScore};
use mesa_schemas::DatasetLayout;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::tasks::chat::{build_request, CallKind, ChatRequest, View};
use crate::tasks::prompts::{PromptError, PromptTemplate};
use crate::tasks::LlmConfig;

/// The built-in prompt (`data/prompts/gpt_score.txt`).
pub const GPT_SCORE_PROMPT: &str = include_str!("../../../data/prompts/gpt_score.txt");

/// Where the built-in prompt comes from, for messages and metrics.
pub const BUILTIN_SOURCE: &str = "built-in data/prompts/gpt_score.txt";

/// The placeholders the prompt may use.
pub const PLACEHOLDERS: [&str; 4] = ["table_type", "task", "task_info", "objects"];

/// The five criteria of the paper: (reply key, name).
pub const CRITERIA: [(&str, &str); 5] = [
    ("consistency_with_task", "Consistency with Task"),
    ("object_size_reasonableness", "Object Size Reasonableness"),
    (
        "placement_plausibility",
        "Placement Plausibility & Intersections",
    ),
    ("layout_coherence", "Layout Coherence & Realism"),
    ("object_visibility", "Object Visibility"),
];

/// Who gives the GPT score.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Judge {
    /// No judge: `--gpt-score` is refused.
    None,
    /// The chat endpoint of `[eval.llm]`.
    Llm,
}

/// The `[eval]` section of `mesa.toml`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct EvalConfig {
    /// Ask the GPT score of every successful sample (implies drawing the views, as --render);
    /// `--gpt-score` sets it. Needs judge = "llm".
    pub gpt_score: bool,
    /// The chat backend of the GPT score: "none" (the default; --gpt-score is then refused)
    /// or "llm" (the endpoint of [eval.llm]).
    pub judge: Judge,
    /// A prompt template file for the GPT score, relative to the dataset folder (a copy of
    /// data/prompts/gpt_score.txt to edit); "" uses the built-in one.
    pub gpt_score_prompt: String,
    /// The judge's chat endpoint, as [tasks.llm] (its own API key variable, cache shared in
    /// .mesa/cache/chat/). send_images is not used: the GPT score always sends both views.
    pub llm: LlmConfig,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            gpt_score: false,
            judge: Judge::None,
            gpt_score_prompt: String::new(),
            // [tasks.llm]'s defaults: a section that sets some keys takes the others from
            // LlmConfig::default, so the judge's defaults must be the same to be predictable.
            llm: LlmConfig::default(),
        }
    }
}

impl EvalConfig {
    /// What is wrong with the values, one line each (checked when the file is read).
    pub fn problems(&self) -> Vec<String> {
        self.llm.problems("eval.llm", self.judge == Judge::Llm)
    }
}

/// Parses a GPT score prompt file; `source` names it in errors.
pub fn parse_prompt(source: &str, text: &str) -> Result<PromptTemplate, PromptError> {
    PromptTemplate::parse(source, text, &PLACEHOLDERS)
}

/// What one sample's request is made of.
#[derive(Debug, Clone, Copy)]
pub struct ScoreInput<'a> {
    /// The table type, when known.
    pub table_type: Option<&'a str>,
    /// The task info JSON of the prompt.
    pub task_info: Option<&'a Value>,
    /// The scene as evaluated.
    pub layout: &'a DatasetLayout,
    /// The front view (PNG).
    pub front_png: &'a [u8],
    /// The perspective view (PNG).
    pub perspective_png: &'a [u8],
}

/// The object list of the prompt: one line per object, `instance: w x d x h cm, description`,
/// objects without an asset marked (they are not in the views).
pub fn object_lines(layout: &DatasetLayout) -> String {
    let mut lines = Vec::with_capacity(layout.objects.len());
    for object in &layout.objects {
        let [w, d, h] = object.size_cm.0;
        let mut line = format!("- {}: {w:.1} x {d:.1} x {h:.1} cm", object.instance);
        if let Some(description) = object.description.as_deref().filter(|d| !d.is_empty()) {
            line.push_str(", ");
            line.push_str(description);
        }
        if object.retrieved_uid.is_empty() {
            line.push_str(" (no asset found: not in the views)");
        }
        lines.push(line);
    }
    lines.join("\n")
}

/// The request of one sample: the prompt filled from the task and layout, the front and
/// perspective views after the text as PNG data URLs, a JSON object asked for.
pub fn score_request(
    config: &LlmConfig,
    template: &PromptTemplate,
    input: &ScoreInput<'_>,
) -> Result<ChatRequest, PromptError> {
    let task = input
        .task_info
        .and_then(|info| info.get("Task"))
        .and_then(Value::as_str)
        .unwrap_or("(not given)");
    let task_info = match input.task_info {
        Some(info) => serde_json::to_string_pretty(info).unwrap_or_default(),
        None => "(not given)".to_owned(),
    };
    let values: BTreeMap<&str, String> = [
        (
            "table_type",
            input.table_type.unwrap_or("(unknown)").to_owned(),
        ),
        ("task", task.to_owned()),
        ("task_info", task_info),
        ("objects", object_lines(input.layout)),
    ]
    .into_iter()
    .collect();
    let prompt = template.render(&values)?;
    let views = [
        View {
            name: "front".to_owned(),
            file: "front.png".to_owned(),
            png: input.front_png.to_vec(),
        },
        View {
            name: "perspective".to_owned(),
            file: "perspective.png".to_owned(),
            png: input.perspective_png.to_vec(),
        },
    ];
    Ok(build_request(
        CallKind::GptScore,
        config,
        &prompt,
        &views,
        true,
        0,
    ))
}

/// A reply that failed validation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScoreReject {
    /// Every problem found.
    pub problems: Vec<String>,
    /// The criteria keys at fault (missing, or not an integer in 1..=10).
    pub criteria: Vec<String>,
}

/// A validated reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Scored {
    /// The five scores by key.
    pub scores: BTreeMap<String, u32>,
    /// Their mean.
    pub mean: f64,
    /// The model's reason ("" when it gave none).
    pub reason: String,
}

/// Validates a reply: a JSON object (a ```` ```json ```` fence around it tolerated) with each of
/// the five criterion keys an integer from 1 to 10 (not a string, not a fraction), and
/// `reason`, when present, a string. Other keys are ignored.
pub fn parse_score_reply(content: &str) -> Result<Scored, ScoreReject> {
    let mut text = content.trim();
    if let Some(inner) = text.strip_prefix("```") {
        let inner = inner.strip_prefix("json").unwrap_or(inner);
        text = inner.trim().strip_suffix("```").unwrap_or(inner).trim();
    }
    let value: Value = serde_json::from_str(text).map_err(|e| ScoreReject {
        problems: vec![format!("not valid JSON: {e} (expected a JSON object)")],
        criteria: Vec::new(),
    })?;
    let Value::Object(map) = value else {
        return Err(ScoreReject {
            problems: vec![
                "not a JSON object (expected {\"consistency_with_task\": 1-10, ...})".to_owned(),
            ],
            criteria: Vec::new(),
        });
    };
    let mut problems = Vec::new();
    let mut criteria = Vec::new();
    let mut scores = BTreeMap::new();
    for (key, _) in CRITERIA {
        let problem = match map.get(key) {
            None => Some(format!("{key}: missing (expected an integer from 1 to 10)")),
            Some(Value::Number(n)) => match n.as_u64() {
                Some(score @ 1..=10) => {
                    scores.insert(key.to_owned(), score as u32);
                    None
                }
                _ => Some(format!(
                    "{key}: {n} is not an integer from 1 to 10 (expected an integer from 1 to 10)"
                )),
            },
            Some(other) => Some(format!(
                "{key}: {other} is not a number (expected an integer from 1 to 10)"
            )),
        };
        if let Some(problem) = problem {
            problems.push(problem);
            criteria.push(key.to_owned());
        }
    }
    let reason = match map.get("reason") {
        None | Some(Value::Null) => String::new(),
        Some(Value::String(text)) => text.trim().to_owned(),
        Some(other) => {
            problems.push(format!("reason: {other} is not a string (expected text)"));
            String::new()
        }
    };
    if !problems.is_empty() {
        return Err(ScoreReject { problems, criteria });
    }
    let mean = scores.values().map(|s| f64::from(*s)).sum::<f64>() / CRITERIA.len() as f64;
    Ok(Scored {
        scores,
        mean,
        reason,
    })
}

/// The run's GPT score from the samples' (each `None` for a failed sample, which is not
/// counted).
pub fn aggregate_gpt_scores<'a>(
    model: &str,
    prompt: &str,
    samples: impl IntoIterator<Item = &'a SampleGptScore>,
) -> GptScoreMetrics {
    let mut m = GptScoreMetrics {
        model: model.to_owned(),
        prompt: prompt.to_owned(),
        requested: 0,
        scored: 0,
        rejected: 0,
        pending: 0,
        failed: 0,
        not_drawn: 0,
        mean: None,
        criteria: CRITERIA
            .iter()
            .map(|(key, name)| {
                (
                    (*key).to_owned(),
                    CriterionScore {
                        name: (*name).to_owned(),
                        mean: None,
                        count: 0,
                        rejects: 0,
                    },
                )
            })
            .collect(),
    };
    let mut sums: BTreeMap<String, f64> = BTreeMap::new();
    let mut mean_sum = 0.0;
    for sample in samples {
        if sample.status != "not_drawn" {
            m.requested += 1;
        }
        match sample.status.as_str() {
            "scored" => {
                m.scored += 1;
                mean_sum += sample.mean.unwrap_or(0.0);
                for (key, score) in &sample.scores {
                    if let Some(c) = m.criteria.get_mut(key) {
                        c.count += 1;
                        *sums.entry(key.clone()).or_default() += f64::from(*score);
                    }
                }
            }
            "rejected" => {
                m.rejected += 1;
                for key in &sample.rejected_criteria {
                    if let Some(c) = m.criteria.get_mut(key) {
                        c.rejects += 1;
                    }
                }
            }
            "pending" => m.pending += 1,
            "failed" => m.failed += 1,
            _ => m.not_drawn += 1,
        }
    }
    for (key, c) in &mut m.criteria {
        if c.count > 0 {
            c.mean = Some(sums.get(key).copied().unwrap_or(0.0) / c.count as f64);
        }
    }
    if m.scored > 0 {
        m.mean = Some(mean_sum / m.scored as f64);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_prompt_parses_and_names_every_criterion() {
        let template = parse_prompt(BUILTIN_SOURCE, GPT_SCORE_PROMPT).expect("parses");
        for (key, name) in CRITERIA {
            assert!(template.user.contains(key), "{key}");
            assert!(template.user.contains(name), "{name}");
        }
        let err = parse_prompt("x.txt", "[user]\n{{task}} {{objekts}}\n").expect_err("typo");
        assert!(err.to_string().contains("objekts"), "{err}");
    }

    #[test]
    fn a_good_reply_gives_the_mean_and_bad_ones_say_why() {
        let good = r#"{"consistency_with_task": 8, "object_size_reasonableness": 7,
            "placement_plausibility": 9, "layout_coherence": 6, "object_visibility": 10,
            "reason": "tidy"}"#;
        let scored = parse_score_reply(good).expect("valid");
        assert_eq!(scored.mean, 8.0);
        assert_eq!(scored.reason, "tidy");
        let fenced = format!("```json\n{good}\n```");
        assert_eq!(parse_score_reply(&fenced).expect("fenced"), scored);

        let err = parse_score_reply("{not json").expect_err("malformed");
        assert!(err.problems[0].contains("not valid JSON"), "{err:?}");
        let missing = good.replace("\"object_visibility\": 10,", "");
        let err = parse_score_reply(&missing).expect_err("missing");
        assert_eq!(err.criteria, ["object_visibility"]);
        assert!(err.problems[0].contains("missing"), "{err:?}");
        let eleven = good.replace("\"layout_coherence\": 6", "\"layout_coherence\": 11");
        let err = parse_score_reply(&eleven).expect_err("11");
        assert_eq!(err.criteria, ["layout_coherence"]);
        let string = good.replace("\"layout_coherence\": 6", "\"layout_coherence\": \"6\"");
        let err = parse_score_reply(&string).expect_err("string");
        assert!(err.problems[0].contains("not a number"), "{err:?}");
        for bad in ["0", "7.5", "-3"] {
            let text = good.replace(
                "\"layout_coherence\": 6",
                &format!("\"layout_coherence\": {bad}"),
            );
            assert!(parse_score_reply(&text).is_err(), "{bad}");
        }
        // Control: 1 and 10 are in range.
        let edges = good.replace("\"layout_coherence\": 6", "\"layout_coherence\": 1");
        assert_eq!(parse_score_reply(&edges).expect("1 is fine").mean, 7.0);
    }

    #[test]
    fn the_aggregate_averages_scored_samples_and_counts_the_rest() {
        let scored = |values: [u32; 5]| SampleGptScore {
            status: "scored".to_owned(),
            scores: CRITERIA
                .iter()
                .zip(values)
                .map(|((k, _), v)| ((*k).to_owned(), v))
                .collect(),
            mean: Some(values.iter().sum::<u32>() as f64 / 5.0),
            reason: None,
            problems: Vec::new(),
            rejected_criteria: Vec::new(),
            reply: None,
            request_sha256: None,
        };
        let rejected = SampleGptScore {
            status: "rejected".to_owned(),
            rejected_criteria: vec!["object_visibility".to_owned()],
            ..scored([1; 5])
        };
        let samples = [scored([10, 8, 6, 4, 2]), scored([2, 2, 2, 2, 2]), rejected];
        let m = aggregate_gpt_scores("m", "p", &samples);
        assert_eq!((m.requested, m.scored, m.rejected), (3, 2, 1));
        assert_eq!(m.mean, Some(4.0));
        let c = &m.criteria["consistency_with_task"];
        assert_eq!((c.mean, c.count, c.rejects), (Some(6.0), 2, 0));
        assert_eq!(m.criteria["object_visibility"].rejects, 1);
    }
}

//! `mesa.toml`: every threshold and path, each key defaulted and documented.
//!
//! The doc comment of each field is its documentation: it becomes the `description` of the
//! generated JSON Schema, which [`annotated_toml`] prints above each key for
//! `mesa run DATASET --print-config`. Unknown keys are errors (a typo must not silently fall
//! back to a default).

use std::path::{Path, PathBuf};

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::Value;

/// The name of the configuration file in a dataset folder.
pub const CONFIG_FILE: &str = "mesa.toml";

/// The resolved configuration of a dataset.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// How stages run: threads, seed, progress display.
    pub run: RunConfig,
    /// `mesa lift`: depth and masks to point clouds, the table frame and boxes.
    pub lift: mesa_stages::lift::LiftConfig,
    /// `mesa assets`: the asset index (bounds, validity, collision shapes, text index).
    pub assets: mesa_stages::assets::AssetsConfig,
    /// `mesa retrieve`: an asset per instance by text and size (MesaTask's recipe).
    pub retrieve: mesa_stages::retrieve::RetrieveConfig,
    /// `mesa place`: each asset scaled isometrically into its lifted box.
    pub place: mesa_stages::place::PlaceConfig,
    /// `mesa pack`: the annotator pack (scene GLB, photo, snapshots, README).
    pub pack: mesa_stages::pack::PackConfig,
    /// Who edits the packs between `mesa pack` and `mesa ingest`.
    pub annotate: mesa_stages::demo::annotator::AnnotateConfig,
    /// `mesa ingest`: the annotator's edited scene read back into the refined layout.
    pub ingest: mesa_stages::ingest::IngestConfig,
    /// `mesa check`: mesh-level physics QA (collisions, floating, zones) and settling.
    pub check: mesa_stages::check::CheckConfig,
    /// `mesa graph`: the rule-based scene graph (SCENE_GRAPH.md).
    pub graph: mesa_stages::graph::GraphConfig,
    /// `mesa tasks`: task instructions and reasoning texts (the template writer or a chat
    /// model).
    pub tasks: mesa_stages::tasks::TasksConfig,
    /// `mesa records`: SFT and DPO training records and the split.
    pub records: mesa_stages::records::RecordsConfig,
    /// `mesa render`: pictures of each scene's layout (and of single assets with --assets).
    pub render: mesa_stages::render::RenderConfig,
    /// `mesa export`: the simulator export (masses, friction, contacts, the table box).
    pub export: mesa_stages::export::ExportConfig,
    /// `mesa release`: the MesaTask-10K tree (layouts, pictures, annotations, assets).
    pub release: mesa_stages::release::ReleaseConfig,
    /// `mesa eval`: the GPT score's judge (a chat endpoint) and prompt.
    pub eval: mesa_stages::eval::gpt_score::EvalConfig,
    /// `mesa annotate`: asset annotations from a vision-language model or the offline
    /// placeholder.
    pub annotations: mesa_stages::annotate::AnnotationsConfig,
}

/// The `[run]` section.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct RunConfig {
    /// Worker threads; 0 means one per available core. `--jobs` overrides it.
    pub jobs: usize,
    /// Seed of every random choice; combined with the scene id, so scenes are independent.
    pub seed: u64,
    /// Progress display: "auto" (a bar on a terminal, periodic lines otherwise), "bar",
    /// "lines" or "off".
    pub progress: ProgressMode,
    /// Seconds between progress lines when lines are printed.
    pub progress_interval_s: f64,
    /// When another run of the same stage holds this dataset's lock
    /// (`.mesa/locks/<stage>.lock`): "fail" (exit code 2, naming the lock and its process) or
    /// "wait" (poll until it is released). A lock of a process that no longer runs is taken
    /// over either way, with a warning.
    pub lock: LockMode,
}

impl Default for RunConfig {
    fn default() -> Self {
        Self {
            jobs: 0,
            seed: 0,
            progress: ProgressMode::Auto,
            progress_interval_s: 10.0,
            lock: LockMode::Fail,
        }
    }
}

/// How progress is shown.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProgressMode {
    /// A bar on a terminal, periodic lines otherwise.
    Auto,
    /// Always a bar.
    Bar,
    /// Always periodic lines.
    Lines,
    /// Nothing until the summary.
    Off,
}

/// What a stage run does when another run of the same stage holds the dataset's lock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LockMode {
    /// Stop with exit code 2 and say who holds the lock.
    Fail,
    /// Wait until the lock is released.
    Wait,
}

/// A configuration that cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("{path}: cannot read the configuration: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not a valid configuration.
    #[error("{path}: {message}(run `mesa run DATASET --print-config` to see every key with its default)")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message (with line, column and key).
        message: String,
    },
}

impl Config {
    /// Loads `file` if given, else `DATASET/mesa.toml` if it exists, else the defaults.
    pub fn load(dataset: &Path, file: Option<&Path>) -> Result<Self, ConfigError> {
        let path = match file {
            Some(file) => file.to_owned(),
            None => {
                let path = dataset.join(CONFIG_FILE);
                if !path.exists() {
                    return Ok(Self::default());
                }
                path
            }
        };
        let bytes =
            crate::fsio::read_bounded(&path, crate::fsio::CONFIG_LIMIT).map_err(|source| {
                ConfigError::Read {
                    path: path.clone(),
                    source,
                }
            })?;
        let text = String::from_utf8(bytes).map_err(|_| ConfigError::Parse {
            path: path.clone(),
            message: "not UTF-8 text (expected TOML) ".to_owned(),
        })?;
        Self::from_toml(&text).map_err(|message| ConfigError::Parse { path, message })
    }

    /// Parses TOML text; the error message names the line and key.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        let config: Self = toml::from_str(text).map_err(|e| e.to_string())?;
        // Values that parse but cannot work: refused before any work starts.
        config.retrieve.check().map_err(|e| format!("{e} "))?;
        let problems: Vec<String> = config
            .pack
            .problems()
            .into_iter()
            .chain(config.ingest.problems())
            .chain(config.check.problems())
            .chain(config.render.problems())
            .chain(config.assets.budget.problems())
            .chain(config.export.problems())
            .chain(config.eval.problems())
            .chain(config.annotations.problems())
            .collect();
        if !problems.is_empty() {
            return Err(format!("{} ", problems.join("; ")));
        }
        Ok(config)
    }
}

/// The configuration as TOML, every key with its doc comment above it.
pub fn annotated_toml(config: &Config) -> Result<String, toml::ser::Error> {
    let schema = schemars::schema_for!(Config).to_value();
    let table = toml::Table::try_from(config)?;
    let mut out = String::from(
        "# mesa configuration: every key with its resolved value.\n\
         # Put any of these in DATASET/mesa.toml to change them; flags override the file.\n",
    );
    for (section, value) in &table {
        out.push('\n');
        push_comment(&mut out, description(&schema, &schema, section));
        match value {
            toml::Value::Table(keys) => {
                let section_schema = property_schema(&schema, &schema, section);
                push_table(&mut out, &schema, section_schema, section, keys);
            }
            other => out.push_str(&format!("{section} = {other}\n")),
        }
    }
    Ok(out)
}

/// Writes `[name]` with its plain keys, each under its doc comment, then its sub-tables as
/// `[name.sub]` sections the same way.
fn push_table(out: &mut String, root: &Value, schema: &Value, name: &str, keys: &toml::Table) {
    out.push_str(&format!("[{name}]\n"));
    let mut tables = Vec::new();
    for (key, value) in keys {
        if let toml::Value::Table(sub) = value {
            tables.push((key, sub));
            continue;
        }
        push_comment(out, description(root, schema, key));
        out.push_str(&format!("{key} = {value}\n"));
    }
    for (key, sub) in tables {
        out.push('\n');
        push_comment(out, description(root, schema, key));
        let sub_schema = property_schema(root, schema, key);
        push_table(out, root, sub_schema, &format!("{name}.{key}"), sub);
    }
}

fn resolve<'a>(root: &'a Value, schema: &'a Value) -> &'a Value {
    match schema.get("$ref").and_then(Value::as_str) {
        Some(r) => r
            .strip_prefix('#')
            .and_then(|p| root.pointer(p))
            .unwrap_or(schema),
        None => schema,
    }
}

fn property_schema<'a>(root: &'a Value, parent: &'a Value, key: &str) -> &'a Value {
    let parent = resolve(root, parent);
    match parent.get("properties").and_then(|p| p.get(key)) {
        Some(s) => resolve(root, s),
        None => &Value::Null,
    }
}

fn description<'a>(root: &'a Value, parent: &'a Value, key: &str) -> Option<&'a str> {
    let parent = resolve(root, parent);
    let property = parent.get("properties")?.get(key)?;
    property
        .get("description")
        .or_else(|| resolve(root, property).get("description"))
        .and_then(Value::as_str)
}

fn push_comment(out: &mut String, text: Option<&str>) {
    for line in text.unwrap_or("").lines().filter(|l| !l.trim().is_empty()) {
        out.push_str("# ");
        out.push_str(line.trim());
        out.push('\n');
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_documented_and_the_output_parses_back() {
        let text = annotated_toml(&Config::default()).expect("toml");
        let back = Config::from_toml(&text).expect("parses back");
        assert_eq!(back, Config::default());
        // Every key line is preceded by a comment line.
        let lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            if line.contains(" = ") || line.starts_with('[') {
                assert!(lines[i - 1].starts_with("# "), "undocumented: {line}");
            }
        }
    }

    #[test]
    fn check_values_that_cannot_work_are_refused_naming_the_key() {
        let err = Config::from_toml("[check]\npenetration_tolerance_mm = -1\n").expect_err("bad");
        assert!(
            err.contains("[check] penetration_tolerance_mm is -1"),
            "{err}"
        );
        let err = Config::from_toml("[check.settling]\nmax_rounds = 0\n").expect_err("bad");
        assert!(err.contains("[check.settling] max_rounds is 0"), "{err}");
        let err = Config::from_toml(
            "[check.settling]\nsimulate = true\nsimulated_s = 1.0\nrest_window_s = 2.0\n\
             steps_per_second = 5\nfriction = -1\n",
        )
        .expect_err("bad");
        for key in [
            "rest_window_s is 2",
            "steps_per_second is 5",
            "friction is -1",
        ] {
            assert!(err.contains(&format!("[check.settling] {key}")), "{err}");
        }
        Config::from_toml("[check.settling]\nsimulate = true\nsimulated_s = 3.0\n")
            .expect("a good simulation section");
        let err = Config::from_toml("[check]\nlayout = \"truth\"\n").expect_err("bad");
        assert!(err.contains("layout"), "{err}");
    }

    #[test]
    fn asset_budget_keys_are_documented_and_checked() {
        let text = annotated_toml(&Config::default()).expect("toml");
        assert!(text.contains("[assets.budget]\n"), "{text}");
        for key in [
            "triangles = 200000",
            "instances = 100",
            "max_triangles = 50000000",
            "simplified_triangles = 20000",
            "seconds = 20.0",
        ] {
            assert!(text.contains(&format!("\n{key}\n")), "{key}");
        }
        let config = Config::from_toml("[assets.budget]\ntriangles = 5\n").expect("valid");
        assert_eq!(config.assets.budget.triangles, 5);
        let err = Config::from_toml("[assets.budget]\nseconds = -1\n").expect_err("bad");
        assert!(err.contains("[assets.budget] seconds = -1"), "{err}");
    }

    #[test]
    fn eval_judge_keys_are_documented_and_checked_under_their_own_section() {
        let text = annotated_toml(&Config::default()).expect("toml");
        assert!(
            text.contains("[eval]\n") && text.contains("[eval.llm]\n"),
            "{text}"
        );
        assert!(text.contains("\njudge = \"none\"\n"), "{text}");
        let config =
            Config::from_toml("[eval]\njudge = \"llm\"\ngpt_score = true\n").expect("valid");
        assert!(config.eval.gpt_score);
        let err =
            Config::from_toml("[eval]\njudge = \"llm\"\n[eval.llm]\nbase_url = \"ftp://x\"\n")
                .expect_err("bad");
        assert!(err.contains("[eval.llm] base_url \"ftp://x\""), "{err}");
        let err = Config::from_toml("[eval.llm]\nmax_concurrency = 0\n").expect_err("bad");
        assert!(err.contains("[eval.llm] max_concurrency is 0"), "{err}");
        // Control: the URL is only checked when the judge uses it.
        assert!(Config::from_toml("[eval.llm]\nbase_url = \"ftp://x\"\n").is_ok());
        let err = Config::from_toml("[eval]\njudge = \"gpt\"\n").expect_err("bad");
        assert!(err.contains("judge"), "{err}");
    }

    #[test]
    fn annotations_keys_are_documented_and_checked() {
        let text = annotated_toml(&Config::default()).expect("toml");
        assert!(text.contains("[annotations]\n"), "{text}");
        assert!(text.contains("[annotations.llm]\n"), "{text}");
        assert!(text.contains("\nmodel = \"gpt-4o-mini\"\n"), "{text}");
        let config = Config::from_toml("[annotations]\nbackend = \"llm\"\n").expect("valid");
        assert_eq!(config.annotations.source(), "llm:gpt-4o-mini");
        let err = Config::from_toml("[annotations]\nmax_density_kg_m3 = -1\n").expect_err("bad");
        assert!(
            err.contains("[annotations] max_density_kg_m3 is -1"),
            "{err}"
        );
        let err = Config::from_toml("[annotations]\nmin_density_kg_m3 = 9000\n").expect_err("bad");
        assert!(err.contains("above max_density_kg_m3"), "{err}");
        let err = Config::from_toml(
            "[annotations]\nbackend = \"llm\"\n\n[annotations.llm]\nbase_url = \"ftp://x\"\n",
        )
        .expect_err("bad");
        assert!(err.contains("[annotations.llm] base_url"), "{err}");
    }

    #[test]
    fn unknown_keys_are_errors_naming_the_key() {
        let err = Config::from_toml("[run]\njobz = 3\n").expect_err("typo");
        assert!(err.contains("jobz"), "{err}");
    }
}

//! The file tools: commands over single files, not datasets — `mesa validate` (any artifact
//! against its schema), `mesa convert` (a layout between the dataset and the LLM forms),
//! `mesa parse-output` (a model output with the paper's success rule) and `mesa graph
//! --layout` (the scene graph of one layout file).

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, Context as _};
use clap::{Args, ValueEnum};
use mesa_schemas::convert::{category_of_instance, dataset_from_llm, llm_from_dataset};
use mesa_schemas::json::to_sorted_pretty;
use mesa_schemas::output::parse_model_output;
use mesa_schemas::{kinds, validate_text, Kind};
use mesa_stages::graph::{
    extract_graph, keyword_containers, GraphConfig, GraphOptions, LoadedLayout,
};

use crate::cli::Global;
use crate::exit::{UsageError, EXIT_FAILED, EXIT_OK};
use crate::fsio::{read_bounded, write_atomic, JSON_LIMIT, RECORDS_LIMIT};
use crate::layouts::{read_any_layout, read_graph_layout, AnyLayout};

/// `mesa validate`.
#[derive(Debug, Args)]
pub struct ValidateArgs {
    /// Files or folders (folders: every .json and .jsonl file below them).
    #[arg(required = true)]
    pub paths: Vec<PathBuf>,
    /// The kind of files that carry no "schema" field (official formats): layout,
    /// llm-layout, task-info, gallery-record, camera, instances, sft, dpo, trl-sft, trl-dpo,
    /// dataset-info, ... (`mesa validate --list-kinds` shows all).
    #[arg(long, value_name = "KIND")]
    pub kind: Option<String>,
    /// List the kinds and exit.
    #[arg(long, exclusive = true)]
    pub list_kinds: bool,
}

/// `--to`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LayoutForm {
    /// The LLM layout (cm, z_rotation in degrees, objects by descending footprint).
    Llm,
    /// The dataset layout (cm, quaternion xyzw, retrieved_uid, scale_factor).
    Dataset,
}

/// `mesa convert`.
#[derive(Debug, Args)]
pub struct ConvertArgs {
    /// A dataset layout, an LLM layout, or a published MesaTask record (its
    /// `scene_layout_json`).
    pub input: PathBuf,
    /// The form to write.
    #[arg(long, value_enum)]
    pub to: LayoutForm,
    /// Where to write (default, or `-`: standard output). A new or regular file is replaced
    /// atomically (through a symlink, its target); a FIFO or device is written in place.
    #[arg(short, long, value_name = "FILE")]
    pub output: Option<PathBuf>,
    /// Keep the input's object order instead of sorting by descending footprint w·d (the
    /// scene graph's "layout order" depends on it).
    #[arg(long)]
    pub keep_order: bool,
}

/// `mesa parse-output`.
#[derive(Debug, Args)]
pub struct ParseOutputArgs {
    /// A text file holding one model output.
    pub file: PathBuf,
}

/// The kind of an official file that carries no `schema` field, from its file name.
fn kind_from_file_name(path: &Path) -> Option<&'static Kind> {
    let name = path.file_name()?.to_str()?;
    let parent = path
        .parent()
        .and_then(|p| p.file_name())
        .and_then(|n| n.to_str());
    let kind = match (parent, name) {
        (_, "layout.json") => "layout",
        (Some("input"), "camera.json") => "camera",
        (Some("input" | "truth"), "instances.json") => "instances",
        (_, "sft.json") => "sft",
        (Some("records"), "test.json") => "sft",
        (_, "trl_test.jsonl") => "trl-sft",
        (_, "dpo.json") => "dpo",
        (_, "trl_sft.jsonl") => "trl-sft",
        (_, "trl_dpo.jsonl") => "trl-dpo",
        (_, "dataset_info.json") => "dataset-info",
        (_, "Asset_annotation.json") | (Some("assets"), "annotations.json") => "asset-annotations",
        _ => return None,
    };
    Kind::by_name(kind)
}

fn collect_files(path: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
    if path.is_dir() {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(path)?
            .map(|e| e.map(|e| e.path()))
            .collect::<Result<_, _>>()?;
        entries.sort();
        for entry in entries {
            let hidden = entry
                .file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with('.'));
            if entry.is_dir() && !hidden {
                collect_files(&entry, out)?;
            } else if !hidden
                && entry
                    .extension()
                    .is_some_and(|e| e == "json" || e == "jsonl")
            {
                out.push(entry);
            }
        }
    } else {
        out.push(path.to_owned());
    }
    Ok(())
}

/// Runs `mesa validate`.
pub fn validate(args: ValidateArgs, _global: Global) -> anyhow::Result<ExitCode> {
    if args.list_kinds {
        for kind in kinds() {
            println!(
                "{:<15} {:<18} {}",
                kind.name,
                kind.schema_id.unwrap_or("(no schema field)"),
                kind.summary
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let forced = match &args.kind {
        Some(name) => Some(Kind::by_name(name).ok_or_else(|| {
            let names: Vec<&str> = kinds().iter().map(|k| k.name).collect();
            UsageError(format!(
                "--kind {name}: unknown kind (expected one of {})",
                names.join(", ")
            ))
        })?),
        None => None,
    };
    let mut files = Vec::new();
    for path in &args.paths {
        if !path.exists() {
            return Err(UsageError(format!("{}: no such file or folder", path.display())).into());
        }
        collect_files(path, &mut files).with_context(|| format!("{}", path.display()))?;
    }
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut problems = 0usize;
    let mut bad_files = 0usize;
    for file in &files {
        let jsonl = file.extension().is_some_and(|e| e == "jsonl");
        let records = jsonl
            || file
                .file_name()
                .is_some_and(|n| n == "sft.json" || n == "dpo.json" || n == "test.json");
        let limit = if records { RECORDS_LIMIT } else { JSON_LIMIT };
        let text = match read_bounded(file, limit) {
            Ok(bytes) => match String::from_utf8(bytes) {
                Ok(text) => text,
                Err(_) => {
                    writeln!(
                        out,
                        "{}: $: is not UTF-8 text (expected JSON)",
                        file.display()
                    )?;
                    problems += 1;
                    bad_files += 1;
                    continue;
                }
            },
            Err(e) => {
                writeln!(out, "{}: cannot read: {e}", file.display())?;
                problems += 1;
                bad_files += 1;
                continue;
            }
        };
        let kind = forced.or_else(|| {
            // Only files without a `schema` field fall back to their well-known names.
            let first_doc = if jsonl {
                text.lines().find(|l| !l.trim().is_empty()).unwrap_or("")
            } else {
                text.as_str()
            };
            let has_schema = mesa_schemas::json::parse_lenient(first_doc)
                .ok()
                .is_some_and(|v| v.get("schema").is_some());
            if has_schema {
                None
            } else {
                kind_from_file_name(file)
            }
        });
        let found = validate_text(&text, kind, jsonl);
        if !found.is_empty() {
            bad_files += 1;
        }
        for located in &found {
            problems += 1;
            match located.line {
                Some(line) if jsonl => {
                    writeln!(out, "{}:{line}: {}", file.display(), located.problem)?
                }
                Some(line) => {
                    writeln!(out, "{}: {} (line {line})", file.display(), located.problem)?
                }
                None => writeln!(out, "{}: {}", file.display(), located.problem)?,
            }
        }
    }
    out.flush().context("standard output: cannot write")?;
    eprintln!(
        "{} files checked: {} valid, {bad_files} with problems ({problems} problems)",
        files.len(),
        files.len() - bad_files
    );
    Ok(ExitCode::from(if problems == 0 {
        EXIT_OK
    } else {
        EXIT_FAILED
    }))
}

/// Runs `mesa convert`.
pub fn convert(args: ConvertArgs, _global: Global) -> anyhow::Result<ExitCode> {
    let layout = match read_any_layout(&args.input) {
        Ok(layout) => layout,
        Err(e) => {
            eprintln!("mesa: {e:#}");
            return Ok(ExitCode::from(EXIT_FAILED));
        }
    };
    const REORDERED: &str = "objects reordered by descending footprint w·d (the input had \
                             another order, which the scene graph's layout order follows; \
                             --keep-order keeps it)";
    let (bytes, warnings) = match (layout, args.to) {
        (AnyLayout::Dataset(dataset), LayoutForm::Llm) => {
            let mut converted = llm_from_dataset(&dataset);
            if !args.keep_order && converted.layout.sort_objects() {
                converted.warnings.push(REORDERED.to_owned());
            }
            (llm_bytes(&converted.layout)?, converted.warnings)
        }
        (AnyLayout::Llm(llm), LayoutForm::Dataset) => {
            let mut converted = dataset_from_llm(&llm);
            if !args.keep_order && converted.layout.sort_objects() {
                converted.warnings.push(REORDERED.to_owned());
            }
            (to_sorted_pretty(&converted.layout)?, converted.warnings)
        }
        (AnyLayout::Llm(mut llm), LayoutForm::Llm) => {
            let reordered = !args.keep_order && llm.sort_objects();
            (
                llm_bytes(&llm)?,
                if reordered {
                    vec![REORDERED.to_owned()]
                } else {
                    vec![]
                },
            )
        }
        (AnyLayout::Dataset(mut dataset), LayoutForm::Dataset) => {
            let reordered = !args.keep_order && dataset.sort_objects();
            (
                to_sorted_pretty(&dataset)?,
                if reordered {
                    vec![REORDERED.to_owned()]
                } else {
                    vec![]
                },
            )
        }
    };
    for warning in &warnings {
        eprintln!("warning: {}: {warning}", args.input.display());
    }
    match &args.output {
        Some(path) if path.as_os_str() != "-" => write_output(path, &bytes)?,
        _ => write_stdout(&bytes)?,
    }
    Ok(ExitCode::SUCCESS)
}

/// Writes `bytes` to `-o PATH`. Through a temporary file renamed over it (a reader never sees
/// half a file) only onto a new path or a regular file; a symlink to a regular file is
/// resolved first, so the link stays and its target is replaced. Anything else (a FIFO, a
/// terminal, `/dev/stdout`, `/proc/self/fd/1`) is written in place: renaming over it would
/// replace it with a regular file and the bytes would never reach its reader.
fn write_output(path: &Path, bytes: &[u8]) -> anyhow::Result<()> {
    let cannot = || format!("{}: cannot write", path.display());
    let target = match std::fs::metadata(path) {
        Ok(meta) if meta.is_dir() => {
            return Err(UsageError(format!(
                "{}: -o names a folder (expected a file name)",
                path.display()
            ))
            .into())
        }
        Ok(meta) if meta.is_file() => std::fs::canonicalize(path).with_context(cannot)?,
        Ok(_) => {
            let mut file = std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .with_context(cannot)?;
            return file.write_all(bytes).with_context(cannot);
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if std::fs::symlink_metadata(path).is_ok() {
                // A link to nothing: replacing it would silently drop the link.
                return Err(UsageError(format!(
                    "{}: a symlink to a missing file (point it at an existing file or \
                     remove it)",
                    path.display()
                ))
                .into());
            }
            path.to_owned()
        }
        Err(e) => return Err(e).with_context(cannot),
    };
    write_atomic(&target, bytes).with_context(cannot)
}

/// An LLM layout as pretty JSON in the published key order, with a trailing newline.
pub fn llm_bytes(layout: &mesa_schemas::LlmLayout) -> anyhow::Result<Vec<u8>> {
    let mut bytes = serde_json::to_vec_pretty(layout)?;
    bytes.push(b'\n');
    Ok(bytes)
}

/// Runs `mesa parse-output`.
pub fn parse_output(args: ParseOutputArgs, _global: Global) -> anyhow::Result<ExitCode> {
    let bytes = read_bounded(&args.file, JSON_LIMIT)
        .with_context(|| format!("{}: cannot read", args.file.display()))?;
    let text =
        String::from_utf8(bytes).map_err(|_| anyhow!("{}: not UTF-8 text", args.file.display()))?;
    match parse_model_output(&text) {
        Ok(parsed) => {
            write_stdout(&llm_bytes(&parsed.layout)?)?;
            eprintln!(
                "{}: success: {} objects, {} scene-graph lines, reasoning of {} characters",
                args.file.display(),
                parsed.layout.objects.len(),
                parsed.graph_lines.len(),
                parsed.reasoning.chars().count()
            );
            for dropped in &parsed.dropped_objects {
                eprintln!("{}: dropped {dropped}", args.file.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Err(e) => {
            eprintln!("{}: not a success: {e}", args.file.display());
            Ok(ExitCode::from(EXIT_FAILED))
        }
    }
}

/// The container flags of `--containers`: objects named by instance or by category; `""`
/// names none. Also the names that matched nothing.
pub fn containers_from_list(loaded: &LoadedLayout, list: &str) -> (Vec<bool>, Vec<String>) {
    let names: Vec<&str> = list
        .split(',')
        .map(str::trim)
        .filter(|n| !n.is_empty())
        .collect();
    let objects = &loaded.scene.objects;
    let flags = objects
        .iter()
        .map(|o| {
            names
                .iter()
                .any(|n| *n == o.instance || *n == category_of_instance(&o.instance))
        })
        .collect();
    let unmatched = names
        .iter()
        .filter(|n| {
            !objects
                .iter()
                .any(|o| **n == o.instance || **n == category_of_instance(&o.instance))
        })
        .map(|n| (*n).to_owned())
        .collect();
    (flags, unmatched)
}

/// `mesa graph --layout FILE`: prints the triplet lines of one layout to standard output.
/// Warnings go to standard error; a malformed file is an error naming the file, the object
/// and the field.
pub fn print_layout_graph(
    path: &Path,
    containers: Option<&str>,
    equally_spaced: bool,
) -> anyhow::Result<ExitCode> {
    let loaded = read_graph_layout(path)?;
    let options = GraphOptions::from(&GraphConfig::default()).with_equally_spaced(equally_spaced);
    let flags = match containers {
        None => keyword_containers(&loaded.scene, &options),
        Some(list) => {
            let (flags, unmatched) = containers_from_list(&loaded, list);
            for name in unmatched {
                eprintln!(
                    "warning: {}: --containers: \"{name}\" names no object or category of this layout",
                    path.display()
                );
            }
            flags
        }
    };
    for warning in &loaded.warnings {
        eprintln!("warning: {}: {warning}", path.display());
    }
    let graph = extract_graph(&loaded.scene, &flags, &options)
        .map_err(|e| anyhow!("{}: {e}", path.display()))?;
    write_stdout(graph.to_text().as_bytes())?;
    Ok(ExitCode::SUCCESS)
}

/// Writes `bytes` to standard output and flushes, so a write error (a full disk) is an error
/// here rather than lost at exit; a closed pipe keeps its `BrokenPipe` kind in the chain,
/// which `main` turns into a quiet exit (see `exit.rs`). `print!` would panic instead.
pub fn write_stdout(bytes: &[u8]) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(bytes)
        .and_then(|()| out.flush())
        .context("standard output: cannot write")
}

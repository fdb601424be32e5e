//! The one reader of layout files, for every stage and file tool: which file a scene's later
//! stages read ([`chosen_layout`], [`present_layouts`]: the same list feeds their declared
//! inputs), and reading one, in any form (dataset layout, LLM layout, published record),
//! validated, every problem on its own line as `<file>: <json path>: <problem> (expected
//! ...)`, with the SHA-256 of its bytes.

use std::path::Path;

use anyhow::{anyhow, bail, Context as _};
pub use mesa_schemas::layout_file::AnyLayout;
use mesa_schemas::layout_file::{read_layout_text, ReadLayout};
use mesa_schemas::DatasetLayout;
use mesa_stages::graph::LoadedLayout;
use mesa_stages::paths::scene::LAYOUT_CANDIDATES;

use crate::fsio::{read_bounded, sha256_hex, JSON_LIMIT};
use crate::runner::{scene_files, Scene};

/// The layout file a scene's stages after `ingest` read: the first present of
/// [`LAYOUT_CANDIDATES`] (settled, else refined).
pub fn chosen_layout(scene: &Scene) -> Option<&'static str> {
    LAYOUT_CANDIDATES
        .into_iter()
        .find(|rel| scene_files::is_file(&scene.path(rel)))
}

/// Every layout file of [`LAYOUT_CANDIDATES`] present, most refined first (a new
/// `qa/layout.json` makes what was built on `refined/` stale, so all count as inputs).
pub fn present_layouts(scene: &Scene) -> Vec<&'static str> {
    LAYOUT_CANDIDATES
        .into_iter()
        .filter(|rel| scene_files::is_file(&scene.path(rel)))
        .collect()
}

/// The bytes of a layout file as text (hashed only by the readers that return the SHA-256:
/// the graph stage reads 10,000 layouts whose digests the runner already has).
///
/// Inside a scene, the bytes the runner read to hash the layout ([`scene_files`]), if it did.
fn read_text(path: &Path) -> anyhow::Result<String> {
    let bytes = match scene_files::take(path) {
        Some(bytes) => bytes,
        None => read_bounded(path, JSON_LIMIT)
            .with_context(|| format!("{}: cannot read", path.display()))?,
    };
    let text = String::from_utf8(bytes).map_err(|_| {
        anyhow!(
            "{}: not UTF-8 text (expected a layout JSON)",
            path.display()
        )
    })?;
    if mesa_schemas::json::starts_with_bom(&text) {
        bail!("{}: {}", path.display(), mesa_schemas::json::BOM_PROBLEM);
    }
    Ok(text)
}

fn invalid(path: &Path, problems: &[mesa_schemas::Problem]) -> anyhow::Error {
    let lines: Vec<String> = problems
        .iter()
        .map(|p| format!("{}: {p}", path.display()))
        .collect();
    anyhow!(
        "{} is not a valid layout:\n{}",
        path.display(),
        lines.join("\n")
    )
}

/// Reads a layout file of any form with the SHA-256 of its bytes.
pub fn read_layout_file(path: &Path) -> anyhow::Result<(ReadLayout, String)> {
    let text = read_text(path)?;
    let read = read_layout_text(&text).map_err(|problems| invalid(path, &problems))?;
    Ok((read, sha256_hex(text.as_bytes())))
}

/// Reads a layout file of any form (`mesa convert`).
pub fn read_any_layout(path: &Path) -> anyhow::Result<AnyLayout> {
    Ok(read_layout_file(path)?.0.layout)
}

/// Reads a dataset layout file (asset uids and scale factors per object) with its bytes. An
/// LLM layout names no assets: an error that says what `needs_assets_to` (like "check",
/// "draw") cannot do without them.
pub fn read_dataset_layout_bytes(
    path: &Path,
    needs_assets_to: &str,
) -> anyhow::Result<(DatasetLayout, Vec<u8>)> {
    let text = read_text(path)?;
    let layout = dataset_layout(path, &text, needs_assets_to)?;
    Ok((layout, text.into_bytes()))
}

/// [`read_dataset_layout_bytes`] with the SHA-256 of the bytes instead of the bytes.
pub fn read_dataset_layout(
    path: &Path,
    needs_assets_to: &str,
) -> anyhow::Result<(DatasetLayout, String)> {
    let text = read_text(path)?;
    let sha = sha256_hex(text.as_bytes());
    Ok((dataset_layout(path, &text, needs_assets_to)?, sha))
}

/// The dataset layout of `text` (read from `path`), or why it is none.
fn dataset_layout(path: &Path, text: &str, needs_assets_to: &str) -> anyhow::Result<DatasetLayout> {
    let read = read_layout_text(text).map_err(|problems| invalid(path, &problems))?;
    match read.layout {
        AnyLayout::Dataset(layout) => Ok(layout),
        AnyLayout::Llm(_) => bail!(
            "{}: an LLM layout has no assets to {needs_assets_to} (no retrieved_uid or \
             scale_factor per object): expected a dataset layout (`mesa place` writes one; \
             `mesa convert --to dataset` gives one without assets)",
            path.display()
        ),
    }
}

/// Reads a layout file of any form for the scene graph (`mesa graph`): problems one per line,
/// each naming the file.
pub fn read_graph_layout(path: &Path) -> anyhow::Result<LoadedLayout> {
    let text = read_text(path)?;
    mesa_stages::graph::read_layout_text(&text).map_err(|e| {
        let lines: Vec<String> = e
            .problems
            .iter()
            .map(|p| format!("{}: {p}", path.display()))
            .collect();
        anyhow!("{}", lines.join("\n"))
    })
}

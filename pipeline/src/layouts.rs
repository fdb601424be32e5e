//! Reading a layout file of any form, for `convert` and the stages.

use std::path::Path;

use anyhow::{bail, Context as _};
use mesa_schemas::layout_file::read_layout_text;
pub use mesa_schemas::layout_file::AnyLayout;

/// Reads a layout file of any form (dataset layout, LLM layout, published record), validating
/// it first and reporting every problem, each as `<file>: <json path>: <problem> (expected
/// ...)`.
pub fn read_any_layout(path: &Path) -> anyhow::Result<AnyLayout> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read", path.display()))?;
    match read_layout_text(&text) {
        Ok(read) => Ok(read.layout),
        Err(problems) => {
            let lines: Vec<String> = problems
                .iter()
                .map(|p| format!("{}: {p}", path.display()))
                .collect();
            bail!(
                "{} is not a valid layout:\n{}",
                path.display(),
                lines.join("\n")
            )
        }
    }
}

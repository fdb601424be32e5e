//! Every subcommand of `mesa`, one file each: its clap arguments, its configuration overrides,
//! and what it does (for a stage, also its runner adapter over the pure functions of
//! `mesa-stages`). This file is the registry: [`Cli`], the [`Command`] enum and its dispatch,
//! generated from one list; [`pipeline`] says what `mesa run` runs, in order.
//!
//! Adding a command: its file here, its `pub mod` line and its line in the `commands!` list
//! below; a stage that `mesa run` should run also gets its line in [`pipeline::pipeline`].
//! `docs/ARCHITECTURE.md` ("Adding a stage") lists every edit.

// The doc comments of clap's arguments are `mesa --help` as a user reads it: `[run] jobs`
// names a section and key of mesa.toml, and `eval/<name>/` a folder with a placeholder. Read as
// rustdoc, those are a link and an HTML tag that resolve to nothing.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

pub mod annotate;
pub mod assets;
pub mod check;
pub mod demo;
pub mod eval;
pub mod export;
pub mod files;
pub mod graph;
pub mod import;
pub mod ingest;
pub mod lift;
pub mod pack;
pub mod pipeline;
pub mod place;
pub mod records;
pub mod release;
pub mod render;
pub mod report;
pub mod retrieve;
pub mod run;
pub mod status;
pub mod tasks;

use std::process::ExitCode;

use clap::Parser;

use crate::cli::Global;

/// mesa builds MesaTask-style tabletop-scene datasets: depth and masks to boxes, asset
/// retrieval and placement, the annotator round trip, physics QA, scene graphs, and training
/// records.
#[derive(Debug, Parser)]
#[command(name = "mesa", version, about, max_term_width = 100)]
pub struct Cli {
    /// More log output (-v: debug, -vv: trace).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only errors and the final summary.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The registry: `Variant(args type) => run function`, in `mesa --help` order; the doc
/// comment of each line is its `--help` text.
macro_rules! commands {
    ($( $(#[$doc:meta])* $variant:ident($args:ty) => $run:path, )*) => {
        /// The subcommands.
        #[derive(Debug, clap::Subcommand)]
        pub enum Command {
            $( $(#[$doc])* $variant($args), )*
        }

        impl Command {
            /// Runs the command.
            pub fn run(self, global: Global) -> anyhow::Result<ExitCode> {
                match self {
                    $( Self::$variant(args) => $run(args, global), )*
                }
            }
        }
    };
}

commands! {
    /// Run every stage over a dataset, in order.
    Run(run::Args) => run::run,
    /// Print, per stage, how many scenes are done, stale, failed and pending.
    Status(status::Args) => status::run,
    /// Validate artifacts against their schemas, reporting every problem.
    Validate(files::ValidateArgs) => files::validate,
    /// Convert a layout between the dataset form and the LLM form.
    Convert(files::ConvertArgs) => files::convert,
    /// Parse a model output text (reasoning, scene graph, marker, layout JSON).
    ParseOutput(files::ParseOutputArgs) => files::parse_output,
    /// Write a synthetic dataset workspace with ground truth: procedural assets, photos,
    /// depth, masks, cameras and instances, and the true layouts.
    Demo(demo::Args) => demo::run,
    /// Depth maps and instance masks → point clouds, the table frame, and object boxes.
    Lift(lift::Args) => lift::run,
    /// Index the asset library (assets/index/): per asset its bounds in the table frame,
    /// counts, materials and validity, its collision shapes, and the text index. Unchanged
    /// assets are not re-indexed.
    Assets(assets::Args) => assets::run,
    /// Annotate the asset library (assets/annotations.json) with a vision-language model
    /// shown four renders of each asset, or with the offline placeholder from the assets'
    /// names and geometry; each field's source is recorded, a person's fields are kept.
    Annotate(annotate::Args) => annotate::run,
    /// Choose an asset for every lifted instance by text and size, MesaTask's recipe
    /// (coarse/retrieval.json).
    Retrieve(retrieve::Args) => retrieve::run,
    /// Scale each retrieved asset isometrically into its lifted box: the coarse layout
    /// (coarse/layout.json).
    Place(place::Args) => place::run,
    /// Write each scene's annotator pack (pack/): the scene as a GLB for Blender (table,
    /// objects named after their instances, a 1.70 m H1 figure), the photo, a snapshot per
    /// object, index.json and a README for the annotator.
    Pack(pack::Args) => pack::run,
    /// Read each annotator's edited scene (refined/<scene_id>.glb) back into the refined
    /// layout (refined/layout.json) and what changed (refined/diff.json). Scenes whose edited
    /// GLB has not arrived are reported as awaiting annotation.
    Ingest(ingest::Args) => ingest::run,
    /// Physics QA of every scene's layout on the assets' collision shapes: colliding pairs with
    /// their penetration depth, floating objects, zone violations, the collision rate
    /// (qa/check.json); with --settle, the least motion that puts the scene at rest
    /// (qa/layout.json, read by later stages). Ends with the dataset summary qa/summary.json.
    Check(check::Args) => check::run,
    /// Extract the scene graph of every scene (graph/graph.json and graph/graph.txt), or print
    /// the triplets of one layout file with --layout.
    Graph(graph::Args) => graph::run,
    /// Write each scene's table description, tasks and reasoning texts (tasks/tasks.jsonl;
    /// rejected model replies in tasks/rejects.jsonl), with the built-in template writer or a
    /// chat model, live or through offline batches.
    Tasks(tasks::Args) => tasks::run,
    /// Merge every scene's tasks into the training records under records/ (SFT, DPO and TRL
    /// files, dataset_info.json, split.json). Run it once, after all scenes (and all shards).
    Records(records::Args) => records::run,
    /// Render each scene's layout with its assets on the CPU: front, back, left, right and
    /// perspective views (render/<view>.png) with a camera file each; or, with --assets, eight
    /// views around every library asset (assets/renders/<uid>/).
    Render(render::Args) => render::run,
    /// Export each scene for physics simulators (sim/): MJCF with one body per object, its
    /// convex parts as colliders, its visual mesh and an explicit inertia, and the manifest
    /// sim/export.json (docs/export.md). Not part of `mesa run`.
    Export(export::Args) => export::run,
    /// Write the dataset's statistics and plots (report/stats.json, report/*.svg) and one page
    /// with a thumbnail, the QA flags and the files of every scene (report/index.html). Run it
    /// once, after all scenes (and all shards).
    Report(report::Args) => report::run,
    /// Write the MesaTask-10K tree of the dataset: Layout_info/<table_type>/<scene_id>/
    /// {layout.json, front.png} from each scene's refined (or settled) layout and its front
    /// render, and Asset_annotation.json for the assets they use.
    Release(release::Args) => release::run,
    /// Evaluate a task-to-scene model on the dataset's test prompts (docs/eval.md): success
    /// rate, collisions on meshes, CKL, scene-graph self-consistency, task coverage, size
    /// plausibility, FID/KID from feature files (eval/<name>/metrics.json, samples.jsonl,
    /// index.html); --compare puts runs side by side.
    Eval(eval::Args) => eval::run,
    /// Read a released dataset (the MesaTask-10K tree) into a mesa dataset whose scenes enter
    /// at the refined stage (docs/import.md)
    Import(import::Args) => import::run,
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    #[test]
    fn the_cli_is_well_formed() {
        Cli::command().debug_assert();
    }
}

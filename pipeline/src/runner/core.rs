//! What every stage run shares: scenes and their discovery, `--scenes` and `--shard`, the
//! run options, the thread pool and progress display of a run, run records.

use std::path::{Path, PathBuf};
use std::time::Duration;

use mesa_schemas::artifacts::RunMarker;
use mesa_schemas::json::to_sorted_pretty;
use serde::Serialize;

use crate::config::{Config, ProgressMode};
use crate::exit::UsageError;
use crate::fsio::{read_bounded, sha256_hex, write_atomic, SizeLimit};
use crate::progress::Progress;

/// The folder of run records inside a dataset.
pub use mesa_stages::paths::dataset::RUN_DIR;

/// One scene of a dataset.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Scene {
    /// The table type folder, like `office_table`.
    pub table_type: String,
    /// The scene id, like `office_table_0001`.
    pub scene_id: String,
    /// The scene folder.
    pub dir: PathBuf,
}

impl Scene {
    /// `<table_type>/<scene_id>`, the scene's name in markers, globs and summaries.
    pub fn key(&self) -> String {
        format!("{}/{}", self.table_type, self.scene_id)
    }

    /// A path inside the scene folder, relative to the dataset: `scenes/<t>/<s>/<rel>`.
    pub fn rel(&self, rel: &str) -> String {
        format!("scenes/{}/{}/{rel}", self.table_type, self.scene_id)
    }

    /// A path inside the scene folder.
    pub fn path(&self, rel: &str) -> PathBuf {
        self.dir.join(rel)
    }

    /// Whether `mesa import` wrote the scene (its `imported/import.json` exists): it enters at
    /// the refined stage.
    pub fn imported(&self) -> bool {
        self.path(mesa_stages::paths::scene::IMPORT_NOTES).is_file()
    }
}

/// What a stage sees besides the scene.
#[derive(Debug, Clone, Copy)]
pub struct StageContext<'a> {
    /// The dataset folder.
    pub dataset: &'a Path,
    /// The resolved configuration.
    pub config: &'a Config,
}

/// The digest of a serialisable configuration section.
pub fn digest_of<T: Serialize>(section: &T) -> String {
    // serde_json output of a struct is deterministic (field order), which is all we need.
    sha256_hex(&serde_json::to_vec(section).unwrap_or_default())
}

/// `--shard I/N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Shard {
    /// This shard, from 0.
    pub index: usize,
    /// The number of shards.
    pub count: usize,
}

impl Default for Shard {
    fn default() -> Self {
        Self { index: 0, count: 1 }
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        let (i, n) = s
            .split_once('/')
            .ok_or_else(|| format!("shard \"{s}\" is not I/N (expected like 0/4)"))?;
        let index: usize = i
            .trim()
            .parse()
            .map_err(|_| format!("shard index \"{i}\" is not a number (expected like 0/4)"))?;
        let count: usize = n
            .trim()
            .parse()
            .map_err(|_| format!("shard count \"{n}\" is not a number (expected like 0/4)"))?;
        if count == 0 || index >= count {
            return Err(format!(
                "shard {index}/{count} is out of range (expected 0 <= I < N)"
            ));
        }
        Ok(Self { index, count })
    }
}

impl Shard {
    /// The shard of a Slurm array task: `SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN` of
    /// `SLURM_ARRAY_TASK_COUNT`; `None` outside an array job.
    pub fn from_slurm_env() -> Result<Option<Self>, String> {
        Self::from_vars(|name| std::env::var(name).ok())
    }

    fn from_vars(var: impl Fn(&str) -> Option<String>) -> Result<Option<Self>, String> {
        let Some(id) = var("SLURM_ARRAY_TASK_ID") else {
            return Ok(None);
        };
        let parse = |name: &str, value: String| {
            value
                .trim()
                .parse::<usize>()
                .map_err(|_| format!("{name}=\"{value}\" is not a number"))
        };
        let id = parse("SLURM_ARRAY_TASK_ID", id)?;
        let count = var("SLURM_ARRAY_TASK_COUNT").ok_or(
            "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not \
             (pass --shard I/N explicitly)",
        )?;
        let count = parse("SLURM_ARRAY_TASK_COUNT", count)?;
        let min = match var("SLURM_ARRAY_TASK_MIN") {
            Some(min) => parse("SLURM_ARRAY_TASK_MIN", min)?,
            None => 0,
        };
        let index = id.checked_sub(min).ok_or_else(|| {
            format!("SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}")
        })?;
        format!("{index}/{count}").parse().map(Some)
    }

    /// Whether scene number `k` of the sorted list belongs to this shard.
    pub fn owns(&self, k: usize) -> bool {
        k % self.count == self.index
    }
}

/// How a stage run is asked to go.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Only scenes whose `<table_type>/<scene_id>` or `<scene_id>` matches this glob.
    pub scenes: Option<String>,
    /// Worker threads (0 = one per core).
    pub jobs: usize,
    /// The shard of the scene list to process.
    pub shard: Shard,
    /// Redo scenes even when their done marker matches.
    pub force: bool,
    /// Progress display.
    pub progress: ProgressMode,
    /// Seconds between progress lines.
    pub progress_interval: Duration,
    /// Only errors and the summary (`--quiet`): no progress, no closing lines of
    /// [`SceneStage::finish`](crate::runner::SceneStage::finish).
    pub quiet: bool,
    /// When set, only these scenes (`<table_type>/<scene_id>`) of the selection run; the
    /// others are left alone (`mesa tasks` with offline batches runs the scenes whose replies
    /// are all in).
    pub only: Option<std::collections::BTreeSet<String>>,
}

impl RunOptions {
    /// Options from the configuration's `[run]` section, no filter, one shard.
    pub fn from_config(config: &Config) -> Self {
        Self {
            scenes: None,
            jobs: config.run.jobs,
            shard: Shard::default(),
            force: false,
            progress: config.run.progress,
            progress_interval: Duration::from_secs_f64(config.run.progress_interval_s.max(0.1)),
            quiet: false,
            only: None,
        }
    }
}

/// Errors that stop a whole stage run (bad usage or a dataset that is not one).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The folder has no `scenes/`.
    #[error("{0}: not a mesa dataset: it has no scenes/ folder (expected DATASET/scenes/<table_type>/<scene_id>/; `mesa demo DIR` writes one)")]
    NotADataset(PathBuf),
    /// The `--scenes` glob is malformed.
    #[error("--scenes \"{glob}\": {message} (expected a glob like \"office_table/*\" or \"*_00[0-4]?\")")]
    BadGlob {
        /// The glob.
        glob: String,
        /// The parser's message.
        message: String,
    },
    /// The thread pool could not start.
    #[error("cannot start {jobs} worker threads: {message}")]
    Threads {
        /// Requested threads.
        jobs: usize,
        /// The error.
        message: String,
    },
    /// I/O on the dataset folder failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

impl RunError {
    /// As an error of a command: a folder that is no dataset and a bad glob are usage errors
    /// (exit code 2); threads and I/O are not.
    pub fn into_anyhow(self) -> anyhow::Error {
        match self {
            Self::NotADataset(_) | Self::BadGlob { .. } => UsageError(self.to_string()).into(),
            Self::Threads { .. } | Self::Io { .. } => self.into(),
        }
    }
}

/// Lists the scenes of a dataset, sorted by table type then scene id. Folders that cannot be
/// scenes are left out; [`discover_all`] says which and why.
pub fn discover_scenes(dataset: &Path) -> Result<Vec<Scene>, RunError> {
    Ok(discover_all(dataset)?.scenes)
}

/// The longest scene id or table type, in bytes: a file name holds `<scene_id>.glb` and a
/// writer's temporary name `.<name>.mesa-tmp-<pid>-<n>-<host tag>` (7, about 6 and 8 bytes),
/// within the 255 bytes of a file name.
pub const MAX_SCENE_NAME_BYTES: usize = 200;

/// A folder under `scenes/` that is not taken as a scene.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SkippedFolder {
    /// `<table_type>/<scene_id>` (lossy when the name is not UTF-8), or `<table_type>`.
    pub key: String,
    /// Why, and the fix.
    pub problem: String,
    /// A hidden folder (its name starts with '.'): a warning, not a failure.
    pub hidden: bool,
}

/// The scenes of a dataset and the folders under `scenes/` that cannot be scenes.
#[derive(Debug, Clone, Default)]
pub struct Discovery {
    /// The scenes, sorted.
    pub scenes: Vec<Scene>,
    /// The other folders, sorted by key.
    pub skipped: Vec<SkippedFolder>,
}

/// Why a folder name cannot name a table type or a scene, or `None` when it can.
fn folder_name_problem(name: &std::ffi::OsStr) -> Option<(String, bool)> {
    let Some(name) = name.to_str() else {
        return Some((
            "the folder name is not valid UTF-8 (rename it: scene ids are written into \
             layouts, records and file names)"
                .to_owned(),
            false,
        ));
    };
    if name.starts_with('.') {
        return Some((
            "a hidden folder (its name starts with '.') is not a scene (rename it to make it \
             one)"
                .to_owned(),
            true,
        ));
    }
    if name.len() > MAX_SCENE_NAME_BYTES {
        return Some((
            format!(
                "the folder name has {} bytes (at most {MAX_SCENE_NAME_BYTES}: mesa writes files \
                 named after the scene, and a file name holds 255 bytes; shorten it)",
                name.len()
            ),
            false,
        ));
    }
    if name.chars().any(char::is_control) {
        return Some((
            "the folder name holds a control character (a newline, a tab; rename it)".to_owned(),
            false,
        ));
    }
    None
}

/// Lists the scenes of a dataset and the folders under `scenes/` that cannot be scenes (a name
/// that is not UTF-8, too long, with a control character, or hidden). Plain files are ignored.
pub fn discover_all(dataset: &Path) -> Result<Discovery, RunError> {
    let root = dataset.join(mesa_stages::paths::dataset::SCENES);
    if !root.is_dir() {
        return Err(RunError::NotADataset(dataset.to_owned()));
    }
    let io = |path: &Path| {
        let path = path.to_owned();
        move |source| RunError::Io { path, source }
    };
    let mut found = Discovery::default();
    let mut skip = |key: String, (problem, hidden): (String, bool)| {
        found.skipped.push(SkippedFolder {
            key,
            problem,
            hidden,
        })
    };
    let mut scenes = Vec::new();
    for table in std::fs::read_dir(&root).map_err(io(&root))? {
        let table = table.map_err(io(&root))?;
        if !listed_folder(&table) {
            continue;
        }
        let table_os = table.file_name();
        let table_name = table_os.to_string_lossy().into_owned();
        if let Some(problem) = folder_name_problem(&table_os) {
            skip(table_name, problem);
            continue;
        }
        for scene in std::fs::read_dir(table.path()).map_err(io(&table.path()))? {
            let scene = scene.map_err(io(&table.path()))?;
            if !listed_folder(&scene) {
                continue;
            }
            let scene_os = scene.file_name();
            let scene_name = scene_os.to_string_lossy().into_owned();
            if let Some(problem) = folder_name_problem(&scene_os) {
                skip(format!("{table_name}/{scene_name}"), problem);
                continue;
            }
            scenes.push(Scene {
                table_type: table_name.clone(),
                scene_id: scene_name,
                dir: scene.path(),
            });
        }
    }
    scenes.sort();
    found.scenes = scenes;
    found.skipped.sort_by(|a, b| a.key.cmp(&b.key));
    Ok(found)
}

/// Whether a listed entry is a folder, a link followed as [`Path::is_dir`] follows it. The
/// listing says what each entry is, so a scene's folder costs no `stat` of its own (on the
/// 1,000-scene demo, 1,000 of the 23,000 system calls of `mesa graph`); only a link, or a
/// file system that does not say, is statted.
fn listed_folder(entry: &std::fs::DirEntry) -> bool {
    match entry.file_type() {
        Ok(kind) if kind.is_symlink() => entry.path().is_dir(),
        Ok(kind) => kind.is_dir(),
        Err(_) => entry.path().is_dir(),
    }
}

/// Filters scenes by glob, then keeps this shard's share of the sorted list.
pub fn select_scenes(
    scenes: Vec<Scene>,
    glob: Option<&str>,
    shard: Shard,
) -> Result<Vec<Scene>, RunError> {
    let matcher = match glob {
        Some(glob) => Some(
            globset::GlobBuilder::new(glob)
                .literal_separator(false)
                .build()
                .map_err(|e| RunError::BadGlob {
                    glob: glob.to_owned(),
                    message: e.kind().to_string(),
                })?
                .compile_matcher(),
        ),
        None => None,
    };
    Ok(scenes
        .into_iter()
        .filter(|s| {
            matcher
                .as_ref()
                .is_none_or(|m| m.is_match(s.key()) || m.is_match(&s.scene_id))
        })
        .enumerate()
        .filter(|(k, _)| shard.owns(*k))
        .map(|(_, s)| s)
        .collect())
}

/// A marker is a few KB; one of more than 16 MiB is not mesa's, and is read as absent.
pub const MARKER_LIMIT: SizeLimit = SizeLimit {
    bytes: 16 << 20,
    what: "a done marker",
    name: "MARKER_LIMIT",
};

/// Reads a marker; `None` when absent or unreadable (an unreadable marker means "redo"): a
/// link is followed, and what it leads to is read only when it is a regular file of at most
/// `MARKER_LIMIT` (a FIFO there does not hang the run).
pub fn read_marker(path: &Path) -> Option<RunMarker> {
    let bytes = read_bounded(path, MARKER_LIMIT).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// The worker threads of a stage run: every stage, per-scene or dataset-level, runs on one of
/// these (named `mesa-worker-<i>`: a panic there is caught and reported with its scene or
/// asset, not printed with a backtrace).
pub fn thread_pool(jobs: usize) -> Result<rayon::ThreadPool, RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(jobs)
        .thread_name(|i| format!("mesa-worker-{i}"))
        .build()
        .map_err(|e| RunError::Threads {
            jobs,
            message: e.to_string(),
        })
}

/// The progress display of a stage run with `options`.
pub fn progress(name: &str, unit: &'static str, total: usize, options: &RunOptions) -> Progress {
    let mode = if options.quiet {
        ProgressMode::Off
    } else {
        options.progress
    };
    Progress::new(name, unit, total, mode, options.progress_interval)
}

/// Writes a run record (informational: failing to write it must not fail the run).
pub(crate) fn write_run_record<T: Serialize>(path: &Path, summary: &T) {
    if let Ok(bytes) = to_sorted_pretty(summary) {
        if let Err(e) = write_atomic(path, &bytes) {
            tracing::warn!("{}: cannot write run record: {e}", path.display());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Scene and table folders are found from the listing's file types, links to folders
    /// followed as `Path::is_dir` follows them; files, links to files and dangling links are
    /// not scenes. The control: the linked entries are links in the listing, so a listing that
    /// did not follow them would miss those scenes.
    #[test]
    fn linked_folders_are_scenes_and_files_are_not() {
        use std::os::unix::fs::symlink;
        let dir = tempfile::tempdir().expect("tempdir");
        let scenes = dir.path().join("scenes");
        let elsewhere = dir.path().join("elsewhere");
        for folder in [
            scenes.join("desk/desk_0001"),
            elsewhere.join("desk_0002"),
            elsewhere.join("shelf/shelf_0001"),
        ] {
            std::fs::create_dir_all(folder).expect("folder");
        }
        symlink(elsewhere.join("desk_0002"), scenes.join("desk/desk_0002")).expect("link");
        symlink(elsewhere.join("shelf"), scenes.join("shelf")).expect("link");
        std::fs::write(scenes.join("desk/notes.txt"), b"x").expect("file");
        symlink(scenes.join("desk/notes.txt"), scenes.join("desk/desk_0003")).expect("link");
        symlink(elsewhere.join("gone"), scenes.join("desk/desk_0004")).expect("link");
        let keys: Vec<String> = discover_scenes(dir.path())
            .expect("dataset")
            .iter()
            .map(Scene::key)
            .collect();
        assert_eq!(
            keys,
            ["desk/desk_0001", "desk/desk_0002", "shelf/shelf_0001"]
        );
        let linked = std::fs::read_dir(scenes.join("desk"))
            .expect("list")
            .map(|e| e.expect("entry"))
            .find(|e| e.file_name() == "desk_0002")
            .expect("listed");
        assert!(linked.file_type().expect("type").is_symlink());
    }

    #[test]
    fn shards_parse_and_partition() {
        assert_eq!("1/3".parse::<Shard>(), Ok(Shard { index: 1, count: 3 }));
        assert!("3/3".parse::<Shard>().is_err());
        assert!("x/3".parse::<Shard>().is_err());
        assert!("1".parse::<Shard>().is_err());
        let shards: Vec<Shard> = (0..3).map(|i| Shard { index: i, count: 3 }).collect();
        for k in 0..100 {
            assert_eq!(shards.iter().filter(|s| s.owns(k)).count(), 1);
        }
    }

    #[test]
    fn slurm_variables_give_the_shard() {
        let vars = |pairs: &'static [(&'static str, &'static str)]| {
            move |name: &str| {
                pairs
                    .iter()
                    .find(|(k, _)| *k == name)
                    .map(|(_, v)| (*v).to_owned())
            }
        };
        assert_eq!(Shard::from_vars(vars(&[])), Ok(None));
        assert_eq!(
            Shard::from_vars(vars(&[
                ("SLURM_ARRAY_TASK_ID", "2"),
                ("SLURM_ARRAY_TASK_COUNT", "4")
            ])),
            Ok(Some(Shard { index: 2, count: 4 }))
        );
        // `--array=1-4` numbers tasks from 1.
        assert_eq!(
            Shard::from_vars(vars(&[
                ("SLURM_ARRAY_TASK_ID", "4"),
                ("SLURM_ARRAY_TASK_COUNT", "4"),
                ("SLURM_ARRAY_TASK_MIN", "1")
            ])),
            Ok(Some(Shard { index: 3, count: 4 }))
        );
        assert!(Shard::from_vars(vars(&[("SLURM_ARRAY_TASK_ID", "2")])).is_err());
    }

    #[test]
    fn run_errors_are_usage_errors_only_for_usage() {
        use crate::exit::{code_of, EXIT_FAILED, EXIT_USAGE};
        use std::process::ExitCode;
        let usage = RunError::NotADataset(PathBuf::from("x")).into_anyhow();
        assert_eq!(code_of(&usage), ExitCode::from(EXIT_USAGE));
        let io = RunError::Io {
            path: PathBuf::from("x"),
            source: std::io::Error::other("disk full"),
        }
        .into_anyhow();
        assert_eq!(code_of(&io), ExitCode::from(EXIT_FAILED));
        assert!(
            io.to_string().contains("disk full"),
            "the cause is kept: {io}"
        );
    }
}

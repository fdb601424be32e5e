//! One writer per stage and dataset: a stage run holds `.mesa/locks/<stage>.lock` (one lock
//! per shard for `--shard I/N`, whose runs are meant to go at once) from its first scene to its
//! run record, so a second run of the same stage on the same dataset stops at once with a
//! message instead of failing half-way on files the first one renamed away.
//!
//! The lock file is created with `create_new` and holds the holder's pid, host and start time.
//! A lock whose process no longer runs (a killed run) is taken over with a warning. The file
//! is deleted when the [`StageLock`] guard drops, and the `locks/` folder with it when empty,
//! so nothing of the lock stays in the dataset after a run.

use std::fs;
use std::io::{self, Write as _};
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::Context as _;
use serde::{Deserialize, Serialize};

use super::core::{Shard, StageContext, RUN_DIR};
use crate::config::LockMode;
use crate::exit::UsageError;
use crate::fsio::{host_name, process_running, process_start_ticks};

/// The folder of the lock files, under the dataset's `.mesa/`.
pub const LOCK_DIR: &str = "locks";

/// How often a waiting run looks at the lock again.
const POLL: Duration = Duration::from_millis(250);

/// What a lock file holds.
#[derive(Debug, Serialize, Deserialize)]
struct Holder {
    /// The holding process.
    pid: u32,
    /// The machine it runs on (a pid of another machine cannot be checked).
    #[serde(default)]
    host: String,
    /// When it took the lock, seconds since the Unix epoch.
    #[serde(default)]
    started_unix_s: u64,
    /// Its start in clock ticks since boot, to tell it from a later process with its pid.
    #[serde(default)]
    process_start_ticks: Option<u64>,
}

impl Holder {
    fn this_process() -> Self {
        let pid = std::process::id();
        Self {
            pid,
            host: host_name(),
            started_unix_s: now_unix_s(),
            process_start_ticks: process_start_ticks(pid),
        }
    }

    /// Whether the holder certainly no longer runs: same machine, and its pid is gone or now
    /// names a process that started later.
    fn is_dead(&self) -> bool {
        if !self.host.is_empty() && self.host != host_name() {
            return false;
        }
        if !process_running(self.pid) {
            return true;
        }
        match (self.process_start_ticks, process_start_ticks(self.pid)) {
            (Some(then), Some(now)) => then != now,
            _ => false,
        }
    }

    fn describe(&self) -> String {
        let mut text = format!("process {}", self.pid);
        if !self.host.is_empty() && self.host != host_name() {
            text.push_str(&format!(" on host {}", self.host));
        }
        if self.started_unix_s > 0 {
            let ago = now_unix_s().saturating_sub(self.started_unix_s);
            text.push_str(&format!(", started {ago} s ago"));
        }
        text
    }
}

/// The lock of one stage (one shard of it) on one dataset, released on drop.
#[derive(Debug)]
pub struct StageLock {
    path: PathBuf,
}

impl StageLock {
    /// The lock file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for StageLock {
    fn drop(&mut self) {
        let _ = fs::remove_file(&self.path);
        if let Some(dir) = self.path.parent() {
            // Fails while another stage holds its lock there: that one removes it.
            let _ = fs::remove_dir(dir);
        }
    }
}

/// Where the lock of `stage` (and `shard`) on `dataset` lives.
pub fn lock_path(dataset: &Path, stage: &str, shard: Shard) -> PathBuf {
    let name = if shard.count > 1 {
        format!("{stage}.shard-{}-of-{}.lock", shard.index, shard.count)
    } else {
        format!("{stage}.lock")
    };
    dataset.join(RUN_DIR).join(LOCK_DIR).join(name)
}

/// Takes the lock of `stage` on the context's dataset, as `[run] lock` says: fails with a
/// usage error (exit code 2) naming the holder, or waits until it is free. A lock of a process
/// that no longer runs is taken over with a warning.
pub fn lock_stage(ctx: &StageContext<'_>, stage: &str, shard: Shard) -> anyhow::Result<StageLock> {
    let path = lock_path(ctx.dataset, stage, shard);
    let dir = path.parent().unwrap_or(ctx.dataset);
    let mut told_waiting = false;
    loop {
        fs::create_dir_all(dir)
            .with_context(|| format!("{}: cannot create the lock folder", dir.display()))?;
        match fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)
        {
            Ok(mut file) => {
                let lock = StageLock { path: path.clone() };
                let bytes = serde_json::to_vec(&Holder::this_process())?;
                file.write_all(&bytes)
                    .with_context(|| format!("{}: cannot write the lock", path.display()))?;
                return Ok(lock);
            }
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
            // The folder went away between create_dir_all and open: another run released
            // the last lock in it. Try again.
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => {
                return Err(e)
                    .with_context(|| format!("{}: cannot create the lock", path.display()))
            }
        }
        let holder = fs::read_to_string(&path)
            .ok()
            .and_then(|text| serde_json::from_str::<Holder>(&text).ok());
        match &holder {
            Some(holder) if holder.is_dead() => {
                eprintln!(
                    "warning: {}: taking over the lock of `mesa {stage}` from {}, which no \
                     longer runs (a run that was killed)",
                    path.display(),
                    holder.describe()
                );
                let _ = fs::remove_file(&path);
                continue;
            }
            // Released between our attempt and the read: try again.
            None if !path.exists() => continue,
            _ => {}
        }
        let who = match &holder {
            Some(holder) => holder.describe(),
            None => "a process that left no readable pid in it".to_owned(),
        };
        match ctx.config.run.lock {
            LockMode::Fail => {
                return Err(UsageError::new(format!(
                    "{}: `mesa {stage}` is already running on this dataset ({who}); two runs \
                     of one stage on one dataset would undo each other's files. Wait for it to \
                     finish, or set `[run] lock = \"wait\"` in mesa.toml to wait for it; if no \
                     such run is going (the process is gone), delete the lock file",
                    path.display()
                ))
                .into());
            }
            LockMode::Wait => {
                if !told_waiting {
                    eprintln!(
                        "{stage}: waiting for {} ({who}) to be released",
                        path.display()
                    );
                    told_waiting = true;
                }
                std::thread::sleep(POLL);
            }
        }
    }
}

fn now_unix_s() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_secs())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn ctx<'a>(dataset: &'a Path, config: &'a Config) -> StageContext<'a> {
        StageContext { dataset, config }
    }

    #[test]
    fn a_held_lock_stops_a_second_taker_and_goes_on_release() {
        let dir = tempfile::tempdir().expect("tempdir");
        let config = Config::default();
        let ctx = ctx(dir.path(), &config);
        let first = lock_stage(&ctx, "graph", Shard::default()).expect("first");
        let err = lock_stage(&ctx, "graph", Shard::default()).expect_err("held");
        let message = format!("{err:#}");
        assert!(message.contains("graph.lock"), "{message}");
        assert!(
            message.contains(&format!("process {}", std::process::id())),
            "{message}"
        );
        assert!(err.downcast_ref::<UsageError>().is_some(), "exit code 2");
        // Another stage has its own lock.
        let other = lock_stage(&ctx, "lift", Shard::default()).expect("other stage");
        drop(first);
        drop(other);
        assert!(
            !dir.path().join(RUN_DIR).join(LOCK_DIR).exists(),
            "nothing of the locks stays"
        );
        lock_stage(&ctx, "graph", Shard::default()).expect("free again");
    }

    #[test]
    fn shards_have_their_own_locks() {
        let dataset = Path::new("d");
        let one = lock_path(dataset, "lift", Shard { index: 0, count: 2 });
        let two = lock_path(dataset, "lift", Shard { index: 1, count: 2 });
        assert_ne!(one, two);
    }
}

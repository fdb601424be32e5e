//! Input digests remembered by file identity, so that a rerun does not hash again a large
//! scene input that has not changed.
//!
//! A done marker records the SHA-256 of every input, and each run compares them to decide what
//! is stale, so each run hashed every input anew: a real RGB-D frame is 5 MB (a 1280×720
//! `depth.npy` and its photo), 5 ms of hashing a scene out of 35 ms of lifting it, and 50 GB
//! for a rerun of 10,000 such scenes with nothing to do. Build tools and version control
//! answer this with the file's identity: `git` trusts its index entry when a file's inode,
//! size and times are those it recorded. So does this module, for the scene inputs of at
//! least [`REMEMBER_FROM_BYTES`] at every run.
//!
//! **Small files, on a forced rerun.** A run hashes a scene's small inputs and its outputs and
//! writes no digests file for them: writing one costs more than the hashing it saves, and a rerun
//! with nothing to do (which skips every scene) would write one a scene and stage. A forced run
//! (`--force`) over a scene whose marker says done looks up its small inputs and the outputs that
//! come out the same too ([`RememberedDigests::for_rerun`]), and remembers them once settled: a
//! cheap stage's forced rerun hashed every layout and graph of the dataset again (`mesa graph
//! --force`: 31 KB a scene, 10–20 µs of its 130). A small file is read whole either way (the stage
//! gets the input's bytes; an output is compared with the new bytes, unless the next paragraph
//! leaves it unread), and its identity is taken
//! through the open file after the read: the remembered digest is used when it is the remembered
//! identity (which had settled when it was remembered, so any change since, during the read too,
//! would have given a later `ctime`), and a digest is remembered only when that identity has
//! settled as of a time taken before the read (a writer busy with the file during the read leaves a
//! `ctime` too recent). An output kept this way holds exactly the new bytes, so the remembered
//! digest is theirs. This costs a read of the digests file and a `stat` a file, about what hashing
//! 30 KB does on the machines measured: a few per cent of a `mesa graph` rerun, more for a stage
//! whose outputs are larger.
//!
//! **Outputs left unread, on a forced rerun.** A small file read whole is remembered with a
//! fingerprint of its bytes too, their XXH3-128 (0.4 µs for a 15 KB `graph.json`, against 8 µs
//! for a SHA-256 on the machine measured); an entry written without one (by an earlier version)
//! gets it the next time the file is read with the identity remembered. Before an output is
//! read back to be compared with the new bytes, it is statted without following a link: a
//! regular file whose identity is the one remembered holds the bytes it held then (the
//! argument above), so when the fingerprint remembered with it is that of the new bytes, it
//! holds them, and is left alone unread with the remembered SHA-256
//! ([`RememberedDigests::output_unchanged`]). Otherwise (no fingerprint, another length,
//! another identity or fingerprint) it is read and compared as before. A `stat`
//! instead of an open, a read, an `fstat` and a close a file: the reads of `graph.json` and
//! `graph.txt` were 10 µs of the 50 µs a scene of the stage's bare loop. XXH3 is not a
//! cryptographic hash: someone who can choose both a scene's earlier output and its new one
//! could make the two collide, and the old one would be kept; but choosing both means writing
//! the scene's inputs, whose outputs are theirs to decide anyway.
//!
//! **Output folders, on a forced rerun.** Before it writes a scene's outputs the runner sweeps
//! their folder of dead writers' temporary files, a listing of the folder (five system calls and
//! a 32 KB buffer: a twentieth of `mesa graph --force`). A folder's `mtime` and `ctime` change
//! whenever an entry is made, removed or renamed in it, and a temporary file is made by an
//! entry. So a forced rerun stats the folder first: when its identity is the one remembered when
//! it was last listed and held no temporary file at all (of a dead writer or a running one), no
//! entry has been made in it since, and the listing is left out. The identity remembered is the
//! one taken before that listing, once settled as of a time taken before the `stat`: an entry
//! made after the `stat` either shows in the listing (and nothing is remembered) or changes the
//! folder's times after the remembered ones. A folder something was written in by this run is
//! not remembered (the write renamed an entry into it).
//!
//! **The identity** is the device, the inode, the size, the modification time and the status
//! change time (`ctime`), to the nanosecond. Writing to a file, truncating it, replacing it by
//! rename, or setting its times (`touch -d`, `cp -p`, `rsync -t`) all set its `ctime` to the
//! current time, and no system call sets `ctime` to a chosen value; a file put back with the
//! old size and modification time still gets a new `ctime`.
//!
//! **Only settled files are remembered.** A file system keeps times to a granularity (a few
//! milliseconds of kernel clock on ext4, two seconds on FAT): two writes within one tick can
//! leave the same times. So a digest is remembered only when the file's `ctime` and `mtime`
//! are [`SETTLED_AFTER`] or more in the past when it is hashed, and its identity is the same
//! before and after the hashing (no writer was busy with it). A later change then gets a later
//! `ctime` than the remembered one. A file written seconds ago is hashed at every run until it
//! settles. What this does not survive is a system clock set back by more than the margin, or
//! a file system whose clock runs behind this machine's; delete `.mesa/digests/` to have every
//! input hashed again.
//!
//! **Where.** One small text file a stage and scene (inputs and outputs),
//! `.mesa/digests/<stage>/<table_type>/<scene_id>.txt`, out of the scene folder and the markers:
//! file identities differ between copies of a dataset, and markers must be the same bytes for the
//! same work. A line is `<sha256> <dev> <ino> <size> <mtime> <ctime> <path>`, times as
//! `<seconds>.<nanoseconds>`, the digest followed by `:` and the fingerprint in 32 hex digits
//! when there is one (for an output folder, `swept` in place of the digest and the path ending
//! in `/`); the file is written atomically when an entry changes. A file that
//! does not parse is ignored whole (every input is hashed, and the file is written anew).

use std::collections::BTreeMap;
use std::fs;
use std::io;
use std::os::unix::fs::MetadataExt as _;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use super::scene_files;
use crate::fsio::{
    check_regular_file, read_own_bounded, read_sized, sha256_hex, sha256_reader, write_atomic,
    SizeLimit, HASHED_INPUT_LIMIT,
};

/// Inputs smaller than this are hashed every time (256 KiB: a quarter of a millisecond of
/// hashing, against a lookup that costs a read of the digests file).
pub const REMEMBER_FROM_BYTES: u64 = 256 << 10;

/// How long ago a file must have last changed for its digest to be remembered.
pub const SETTLED_AFTER: Duration = Duration::from_secs(3);

/// A digests file read whole (1 MiB: a line is under 300 bytes, a scene has a few inputs).
const DIGESTS_LIMIT: SizeLimit = SizeLimit {
    bytes: 1 << 20,
    what: "a remembered-digests file",
    name: "DIGESTS_LIMIT",
};

/// The first line of a digests file.
const HEADER: &str = "mesa.digests/1";

/// What an output folder's entry holds in place of a digest: the folder was listed and held no
/// temporary file ([`RememberedDigests::look_at_folder`]).
const SWEPT: &str = "swept";

/// A file's identity (module docs): what changes whenever its content may have.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FileIdentity {
    dev: u64,
    ino: u64,
    size: u64,
    mtime: (i64, i64),
    ctime: (i64, i64),
}

impl FileIdentity {
    /// The identity in `meta`.
    pub fn of(meta: &fs::Metadata) -> Self {
        Self {
            dev: meta.dev(),
            ino: meta.ino(),
            size: meta.size(),
            mtime: (meta.mtime(), meta.mtime_nsec()),
            ctime: (meta.ctime(), meta.ctime_nsec()),
        }
    }

    /// Whether the file last changed [`SETTLED_AFTER`] or more before `now`.
    fn settled_at(&self, now: SystemTime) -> bool {
        let Ok(now) = now.duration_since(UNIX_EPOCH) else {
            return false;
        };
        let limit = now.saturating_sub(SETTLED_AFTER);
        let before = |(seconds, nanos): (i64, i64)| {
            u64::try_from(seconds).is_ok_and(|s| {
                let nanos = u32::try_from(nanos).unwrap_or(u32::MAX).min(999_999_999);
                Duration::new(s, nanos) <= limit
            })
        };
        before(self.mtime) && before(self.ctime)
    }

    fn parse(fields: &[&str]) -> Option<Self> {
        let time = |text: &str| -> Option<(i64, i64)> {
            let (seconds, nanos) = text.split_once('.')?;
            let nanos: i64 = nanos.parse().ok()?;
            (0..1_000_000_000).contains(&nanos).then_some(())?;
            Some((seconds.parse().ok()?, nanos))
        };
        match fields {
            [dev, ino, size, mtime, ctime] => Some(Self {
                dev: dev.parse().ok()?,
                ino: ino.parse().ok()?,
                size: size.parse().ok()?,
                mtime: time(mtime)?,
                ctime: time(ctime)?,
            }),
            _ => None,
        }
    }
}

/// What is remembered of one file (or output folder).
#[derive(Debug, Clone, PartialEq, Eq)]
struct Entry {
    /// The identity it had when its digest was taken (module docs).
    identity: FileIdentity,
    /// Its SHA-256 in hex, or [`SWEPT`] for an output folder found clean.
    digest: String,
    /// The XXH3-128 of its bytes, when they were read whole ([`fingerprint`]).
    fingerprint: Option<u128>,
}

impl Entry {
    /// Its line in the digests file.
    fn line(&self, rel: &str) -> String {
        let FileIdentity {
            dev,
            ino,
            size,
            mtime,
            ctime,
        } = self.identity;
        let digest = &self.digest;
        let fingerprint = match self.fingerprint {
            Some(value) => format!(":{value:032x}"),
            None => String::new(),
        };
        format!(
            "{digest}{fingerprint} {dev} {ino} {size} {}.{:09} {}.{:09} {rel}\n",
            mtime.0, mtime.1, ctime.0, ctime.1
        )
    }
}

/// The content fingerprint of `bytes`: their XXH3-128 (module docs).
fn fingerprint(bytes: &[u8]) -> u128 {
    xxhash_rust::xxh3::xxh3_128(bytes)
}

/// A fingerprint as written: 32 hex digits.
fn parse_fingerprint(text: &str) -> Option<u128> {
    let hex = text.len() == 32 && text.bytes().all(|b| b.is_ascii_hexdigit());
    hex.then(|| u128::from_str_radix(text, 16).ok())?
}

/// The remembered digests of one stage's inputs in one scene: loaded when first needed,
/// written back by [`RememberedDigests::save`] when an entry changed.
#[derive(Debug)]
pub struct RememberedDigests {
    path: PathBuf,
    entries: Option<BTreeMap<String, Entry>>,
    changed: bool,
    /// Whether small files are looked up and remembered too (a forced rerun: module docs).
    small_too: bool,
}

/// What [`RememberedDigests::look_at_folder`] found of an output folder.
#[derive(Debug)]
pub struct FolderLook {
    rel: String,
    /// The folder's identity before its listing (`None` when it was not statted: not a forced
    /// rerun, or no folder there).
    identity: Option<FileIdentity>,
    /// Its identity is the one remembered when it was last found clean: no entry has been
    /// made, removed or renamed in it since, so no temporary file can have appeared, and the
    /// runner need not list it.
    pub unchanged: bool,
}

impl RememberedDigests {
    /// The digests remembered in `path` (nothing is read yet).
    pub fn at(path: PathBuf) -> Self {
        Self {
            path,
            entries: None,
            changed: false,
            small_too: false,
        }
    }

    /// The same, for a forced rerun of a scene done before: its small inputs and the outputs
    /// that come out the same are looked up and remembered too (module docs).
    pub fn for_rerun(mut self) -> Self {
        self.small_too = true;
        self
    }

    /// The entries, read from the file the first time (none when it is missing or does not
    /// parse).
    fn entries(&mut self) -> &mut BTreeMap<String, Entry> {
        let path = &self.path;
        self.entries.get_or_insert_with(|| {
            read_own_bounded(path, DIGESTS_LIMIT)
                .ok()
                .and_then(|bytes| String::from_utf8(bytes).ok())
                .and_then(|text| parse(&text))
                .unwrap_or_default()
        })
    }

    /// The SHA-256 of the scene input `path` (`rel` names it in the file): the remembered one
    /// when the file's identity is the one remembered with it, else hashed (and remembered
    /// when the file has settled, as of `now`).
    pub fn digest(&mut self, path: &Path, rel: &str, now: SystemTime) -> io::Result<String> {
        // A scene's input the runner looked up just before is not statted again.
        let size = match scene_files::regular_file_size(path) {
            Some(size) if size <= HASHED_INPUT_LIMIT.bytes => size,
            _ => check_regular_file(path, HASHED_INPUT_LIMIT)?,
        };
        let file = fs::File::open(path)?;
        // A name with a line break cannot be a line of the file: such a file is hashed.
        let listable = !rel.contains('\n');
        if size < REMEMBER_FROM_BYTES {
            // Read whole, and the bytes handed to the stage that runs next on this thread
            // ([`scene_files`]): it reads what was hashed, without opening the file again.
            let cap = REMEMBER_FROM_BYTES.saturating_mul(2);
            let bytes = read_sized(&file, size, cap - 1)?;
            if bytes.len() as u64 >= cap {
                // It grew while being read: hashed whole from the start, not handed over.
                return sha256_reader(fs::File::open(path)?, HASHED_INPUT_LIMIT);
            }
            let digest = if self.small_too && listable {
                self.known_or_hashed(rel, &bytes, &file.metadata()?, now)
            } else {
                sha256_hex(&bytes)
            };
            scene_files::keep(path, bytes);
            return Ok(digest);
        }
        if !listable {
            return sha256_reader(file, HASHED_INPUT_LIMIT);
        }
        let before = FileIdentity::of(&file.metadata()?);
        if let Some(entry) = self.entries().get(rel) {
            if entry.identity == before {
                return Ok(entry.digest.clone());
            }
        }
        let digest = sha256_reader(&file, HASHED_INPUT_LIMIT)?;
        let after = FileIdentity::of(&file.metadata()?);
        self.note(rel, (before == after).then_some(before), &digest, None, now);
        Ok(digest)
    }

    /// The digest of an output the runner made, `bytes`: either written anew (`kept` is
    /// `None`) or held already by the file whose metadata after the read `kept` gives
    /// ([`write_if_changed_kept`](crate::fsio::write_if_changed_kept)). On a forced rerun a
    /// kept output's digest is the remembered one when its identity is unchanged (module docs);
    /// otherwise `bytes` are hashed. `now` is a time taken before the file was read.
    pub fn output_digest(
        &mut self,
        rel: &str,
        bytes: &[u8],
        kept: Option<fs::Metadata>,
        now: SystemTime,
    ) -> String {
        match kept {
            Some(after) if self.small_too && !rel.contains('\n') => {
                return self.known_or_hashed(rel, bytes, &after, now);
            }
            // Kept, not looked up on this run: what is remembered of it still holds.
            Some(_) => {}
            // Written anew: a new identity, which no entry can match.
            None => {
                if let Some(entries) = &mut self.entries {
                    self.changed |= entries.remove(rel).is_some();
                }
            }
        }
        sha256_hex(bytes)
    }

    /// The digest of `bytes`, just read from a file whose metadata taken through the open file
    /// after the read is `after`: the remembered one when that identity is the one remembered
    /// with it, else hashed, and remembered when that identity has settled as of `now`, a time
    /// taken before the read (module docs).
    fn known_or_hashed(
        &mut self,
        rel: &str,
        bytes: &[u8],
        after: &fs::Metadata,
        now: SystemTime,
    ) -> String {
        let after = FileIdentity::of(after);
        if let Some(entry) = self.entries().get_mut(rel) {
            if entry.identity == after {
                // Remembered without a fingerprint (by an earlier version): the bytes are at
                // hand to add it.
                let added = entry.fingerprint.is_none();
                if added {
                    entry.fingerprint = Some(fingerprint(bytes));
                }
                let digest = entry.digest.clone();
                self.changed |= added;
                return digest;
            }
        }
        let digest = sha256_hex(bytes);
        // One identity, taken after the read: settled, it covers the read (module docs). The
        // bytes are at hand: their fingerprint is remembered too, for [`Self::output_unchanged`].
        self.note(rel, Some(after), &digest, Some(fingerprint(bytes)), now);
        digest
    }

    /// On a forced rerun, the remembered SHA-256 of the output at `path` (`rel` names it in the
    /// file) when it holds `bytes` already as far as the remembered digests tell, unread: its
    /// identity, taken by a `stat` that does not follow a link, is the one remembered, and the
    /// content fingerprint remembered with it is that of `bytes` (module docs). `None` when they
    /// cannot tell (not a forced rerun, nothing remembered, another length, another identity,
    /// another fingerprint): the caller reads the file and compares.
    pub fn output_unchanged(&mut self, path: &Path, rel: &str, bytes: &[u8]) -> Option<String> {
        if !self.small_too || rel.contains('\n') {
            return None;
        }
        let entry = self.entries().get(rel)?;
        let remembered = entry.fingerprint?;
        // Another length cannot be the same bytes: no `stat` for it.
        if entry.identity.size != bytes.len() as u64 {
            return None;
        }
        let meta = fs::symlink_metadata(path).ok()?;
        let same = meta.file_type().is_file()
            && FileIdentity::of(&meta) == entry.identity
            && remembered == fingerprint(bytes);
        same.then(|| entry.digest.clone())
    }

    /// Remembers `digest` for `rel` with the file's `identity` while it was read (`None` when
    /// it changed during the read) if that identity has settled as of `now`; otherwise forgets
    /// what was remembered for it.
    fn note(
        &mut self,
        rel: &str,
        identity: Option<FileIdentity>,
        digest: &str,
        fingerprint: Option<u128>,
        now: SystemTime,
    ) {
        let entries = self.entries();
        if let Some(identity) = identity.filter(|i| i.settled_at(now)) {
            let entry = Entry {
                identity,
                digest: digest.to_owned(),
                fingerprint,
            };
            if entries.get(rel) != Some(&entry) {
                entries.insert(rel.to_owned(), entry);
                self.changed = true;
            }
        } else if entries.remove(rel).is_some() {
            self.changed = true;
        }
    }

    /// Looks at a scene's output folder `dir` (`rel`: its path in the dataset, ending in '/')
    /// before the runner sweeps it of dead writers' temporary files. On a forced rerun the
    /// folder is statted, and the sweep can be left out when its identity is the one remembered
    /// when it was last found clean ([`FolderLook::unchanged`], module docs); otherwise nothing
    /// is looked up and the folder is swept.
    pub fn look_at_folder(&mut self, dir: &Path, rel: String) -> FolderLook {
        let identity = if self.small_too && rel.ends_with('/') && !rel.contains('\n') {
            fs::metadata(dir)
                .ok()
                .filter(fs::Metadata::is_dir)
                .map(|meta| FileIdentity::of(&meta))
        } else {
            None
        };
        let unchanged = identity.is_some_and(|now| {
            self.entries()
                .get(&rel)
                .is_some_and(|entry| entry.identity == now && entry.digest == SWEPT)
        });
        FolderLook {
            rel,
            identity,
            unchanged,
        }
    }

    /// What the runner did with a folder it looked at ([`Self::look_at_folder`]): `clean` when
    /// its listing found no temporary file (of a dead writer or a running one), or it was left
    /// unlisted, and nothing was written in it since. A folder left unlisted and clean stays
    /// remembered; one listed clean is remembered with the identity it had before the listing,
    /// if that had settled as of `now` (a time taken before the `stat`); any other is forgotten
    /// (a write renamed an entry into it: the identity remembered can no longer match).
    pub fn note_folder(&mut self, look: FolderLook, clean: bool, now: SystemTime) {
        if look.identity.is_none() && self.entries.is_none() || look.unchanged && clean {
            return;
        }
        self.note(&look.rel, look.identity.filter(|_| clean), SWEPT, None, now);
    }

    /// Keeps only the entries of files `keep` names (a file no longer an input or an output
    /// is forgotten).
    pub fn retain(&mut self, keep: impl Fn(&str) -> bool) {
        if let Some(entries) = &mut self.entries {
            let before = entries.len();
            entries.retain(|rel, _| keep(rel));
            self.changed |= entries.len() != before;
        }
    }

    /// Writes the file when an entry changed. The digests are only a shortcut: a file that
    /// cannot be written means the inputs are hashed again next time, nothing worse, so the
    /// caller may ignore the error (the marker written next reports a full disk).
    pub fn save(&self) -> io::Result<()> {
        let Some(entries) = self.entries.as_ref().filter(|_| self.changed) else {
            return Ok(());
        };
        if entries.is_empty() {
            return match fs::remove_file(&self.path) {
                Err(e) if e.kind() != io::ErrorKind::NotFound => Err(e),
                _ => Ok(()),
            };
        }
        let mut text = format!("{HEADER}\n");
        for (rel, entry) in entries {
            text.push_str(&entry.line(rel));
        }
        // An entry changed since the file was read, so its bytes differ: written without
        // reading the file again to compare.
        write_atomic(&self.path, text.as_bytes())
    }
}

/// The entries of a digests file, or `None` when any line does not parse.
fn parse(text: &str) -> Option<BTreeMap<String, Entry>> {
    let mut lines = text.lines();
    (lines.next()? == HEADER).then_some(())?;
    let mut entries = BTreeMap::new();
    for line in lines {
        let fields: Vec<&str> = line.splitn(7, ' ').collect();
        let [first, rest @ .., rel] = fields.as_slice() else {
            return None;
        };
        // A file's digest, with its content's fingerprint after a colon when it was read whole.
        let (digest, fingerprint) = match first.split_once(':') {
            Some((digest, fingerprint)) => (digest, Some(parse_fingerprint(fingerprint)?)),
            None => (*first, None),
        };
        let hex = digest.len() == 64 && digest.bytes().all(|b| b.is_ascii_hexdigit());
        // A folder's entry ends in '/' and says it was swept clean; a file's gives its digest.
        let valid = if rel.ends_with('/') {
            digest == SWEPT && fingerprint.is_none()
        } else {
            hex && !rel.is_empty()
        };
        if !valid {
            return None;
        }
        let identity = FileIdentity::parse(rest)?;
        let entry = Entry {
            identity,
            digest: digest.to_owned(),
            fingerprint,
        };
        entries.insert((*rel).to_owned(), entry);
    }
    Some(entries)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fsio::sha256_file;

    const LATER: Duration = Duration::from_secs(3600);

    /// A file of `len` bytes of `byte` in `dir`.
    fn input(dir: &Path, name: &str, byte: u8, len: usize) -> PathBuf {
        let path = dir.join(name);
        fs::write(&path, vec![byte; len]).expect("write");
        path
    }

    #[test]
    fn a_settled_large_input_is_hashed_once_and_its_digest_then_trusted() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = input(dir.path(), "depth.npy", 7, 300_000);
        let store = dir.path().join("digests/lift/t/s.txt");
        // As if an hour had passed: the file has settled.
        let later = SystemTime::now() + LATER;
        let mut memo = RememberedDigests::at(store.clone());
        let truth = sha256_file(&file).expect("sha");
        assert_eq!(memo.digest(&file, "in/depth.npy", later).expect("d"), truth);
        memo.save().expect("save");
        let text = fs::read_to_string(&store).expect("saved");
        assert!(text.starts_with("mesa.digests/1\n"), "{text}");
        assert!(
            text.contains(&truth) && text.ends_with(" in/depth.npy\n"),
            "{text}"
        );

        // The remembered digest is what is returned, unread: a forged one shows it.
        let forged = "ab".repeat(32);
        fs::write(&store, text.replace(&truth, &forged)).expect("forge");
        let mut memo = RememberedDigests::at(store.clone());
        assert_eq!(
            memo.digest(&file, "in/depth.npy", later).expect("d"),
            forged
        );

        // Control: the same bytes written again in place (same inode, same size, the old
        // modification time put back) is a new ctime: hashed again, and the truth comes back.
        // (Past the file system's timestamp granularity first, which SETTLED_AFTER covers in
        // real use and `later` skips here.)
        let meta = fs::metadata(&file).expect("meta");
        let mtime = meta.modified().expect("mtime");
        std::thread::sleep(Duration::from_millis(50));
        fs::write(&file, vec![7; 300_000]).expect("rewrite");
        fs::File::options()
            .write(true)
            .open(&file)
            .and_then(|f| f.set_modified(mtime))
            .expect("set mtime");
        let after = fs::metadata(&file).expect("meta");
        assert_eq!((after.ino(), after.size()), (meta.ino(), meta.size()));
        assert_eq!(after.modified().expect("mtime"), mtime);
        assert_ne!(
            (after.ctime(), after.ctime_nsec()),
            (meta.ctime(), meta.ctime_nsec())
        );
        let mut memo = RememberedDigests::at(store.clone());
        assert_eq!(memo.digest(&file, "in/depth.npy", later).expect("d"), truth);
        memo.save().expect("save");
        assert!(!fs::read_to_string(&store).expect("saved").contains(&forged));
    }

    #[test]
    fn a_file_that_changed_lately_or_a_small_one_is_not_remembered() {
        let dir = tempfile::tempdir().expect("tempdir");
        let store = dir.path().join("digests.txt");
        let big = input(dir.path(), "image.png", 1, 300_000);
        let small = input(dir.path(), "camera.json", 2, 100);
        let mut memo = RememberedDigests::at(store.clone());
        // Now: the file was written a moment ago.
        memo.digest(&big, "big", SystemTime::now()).expect("d");
        memo.digest(&small, "small", SystemTime::now() + LATER)
            .expect("d");
        memo.save().expect("save");
        assert!(!store.exists(), "nothing to remember");
        // Control: an hour later the big one is remembered (and the small one still not).
        memo.digest(&big, "big", SystemTime::now() + LATER)
            .expect("d");
        memo.digest(&small, "small", SystemTime::now() + LATER)
            .expect("d");
        memo.save().expect("save");
        let text = fs::read_to_string(&store).expect("saved");
        assert!(
            text.ends_with(" big\n") && text.lines().count() == 2,
            "{text}"
        );
        // An input no longer declared is forgotten; with none left, the file goes.
        memo.retain(|rel| rel == "small");
        memo.save().expect("save");
        assert!(!store.exists());
    }

    #[test]
    fn a_damaged_digests_file_is_ignored_whole() {
        let dir = tempfile::tempdir().expect("tempdir");
        let file = input(dir.path(), "depth.npy", 3, 300_000);
        let truth = sha256_file(&file).expect("sha");
        let later = SystemTime::now() + LATER;
        let store = dir.path().join("d.txt");
        let mut memo = RememberedDigests::at(store.clone());
        memo.digest(&file, "x", later).expect("d");
        memo.save().expect("save");
        let good = fs::read_to_string(&store).expect("saved");
        let forged = good.replace(&truth, &"cd".repeat(32));
        // Control: the forged file as it is is trusted.
        fs::write(&store, &forged).expect("write");
        let trusted = RememberedDigests::at(store.clone()).digest(&file, "x", later);
        assert_eq!(trusted.expect("d"), "cd".repeat(32));
        // The entry line with one field replaced.
        let entry = forged.lines().nth(1).expect("entry").to_owned();
        let with_field = |i: usize, value: &str| {
            let mut fields: Vec<&str> = entry.split(' ').collect();
            fields[i] = value;
            format!("mesa.digests/1\n{}\n", fields.join(" "))
        };
        let mtime = entry.split(' ').nth(4).expect("mtime");
        let (seconds, _) = mtime.split_once('.').expect("a dot");
        for damaged in [
            forged.replacen("mesa.digests/1", "mesa.digests/2", 1),
            forged.clone() + "not a line\n",
            with_field(0, &"zz".repeat(32)),
            with_field(0, "cd"),
            with_field(1, "-1"),
            with_field(3, "300000x"),
            with_field(4, &format!("{seconds}.1234567890")),
            with_field(4, seconds),
            with_field(5, "now"),
            with_field(6, ""),
            // A fingerprint is 32 hex digits after a colon.
            with_field(0, &format!("{}:{}", "cd".repeat(32), "0".repeat(31))),
            with_field(0, &format!("{}:{}", "cd".repeat(32), "g".repeat(32))),
            with_field(0, &format!("{}:", "cd".repeat(32))),
            with_field(0, &format!("{}::{}", "cd".repeat(32), "0".repeat(32))),
            // A folder's entry holds `swept` and a file's a digest, not the other way round.
            with_field(0, SWEPT),
            forged.clone() + with_field(6, "a/folder/").lines().nth(1).expect("line") + "\n",
            forged[..forged.len() / 2].to_owned(),
            String::new(),
        ] {
            fs::write(&store, &damaged).expect("write");
            let got = RememberedDigests::at(store.clone()).digest(&file, "x", later);
            assert_eq!(got.expect("d"), truth, "{damaged:?}");
        }
        // A folder's entry holds no fingerprint.
        let folder =
            with_field(0, &format!("{SWEPT}:{}", "0".repeat(32))).replace(" x\n", " a/folder/\n");
        fs::write(
            &store,
            forged.clone() + folder.lines().nth(1).expect("line") + "\n",
        )
        .expect("write");
        let got = RememberedDigests::at(store.clone()).digest(&file, "x", later);
        assert_eq!(got.expect("d"), truth);
        // Control: a file's entry with a fingerprint is read and trusted.
        fs::write(
            &store,
            with_field(0, &format!("{}:{}", "cd".repeat(32), "0a".repeat(16))),
        )
        .expect("write");
        let trusted = RememberedDigests::at(store.clone()).digest(&file, "x", later);
        assert_eq!(trusted.expect("d"), "cd".repeat(32));
        // Control: a folder's entry as it is written is read, and the file's beside it trusted.
        let folder = with_field(0, SWEPT).replace(" x\n", " a/folder/\n");
        fs::write(
            &store,
            forged.clone() + folder.lines().nth(1).expect("line") + "\n",
        )
        .expect("write");
        let trusted = RememberedDigests::at(store.clone()).digest(&file, "x", later);
        assert_eq!(trusted.expect("d"), "cd".repeat(32));
    }
}

//! Atomic writes and content digests.
//!
//! A file is written to a temporary name in the same folder and renamed over the target, so a
//! reader (or a rerun after `kill -9`) sees either the old bytes or the new ones, never a
//! mixture. Temporary names carry the owner's file name, [`TMP_MARK`], the writing process's
//! pid and a tag of its machine (`.<name>.mesa-tmp-<pid>-<n>-<host tag>`), so a rerun can sweep
//! the leftovers of a killed run for exactly the files it is about to write, and leave alone
//! those of a run still going (two runs on one dataset must not delete each other's files
//! half-way), on this machine or on another one sharing the dataset (the shards of a cluster
//! job: a pid says nothing about a process of another machine).

use std::collections::HashMap;
use std::fs;
use std::io::{self, BufRead, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

use anyhow::{anyhow, bail, Context as _};
use serde::de::DeserializeOwned;
use sha2::{Digest, Sha256};

/// The marker in the names of temporary files (also in `.gitignore`).
pub const TMP_MARK: &str = ".mesa-tmp-";

static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The name of this machine (`/proc/sys/kernel/hostname`, else `/etc/hostname`; empty when
/// neither is readable).
pub fn host_name() -> String {
    fs::read_to_string("/proc/sys/kernel/hostname")
        .or_else(|_| fs::read_to_string("/etc/hostname"))
        .map(|name| name.trim().to_owned())
        .unwrap_or_default()
}

/// This machine's tag in temporary names: 8 hex digits of a hash (64-bit FNV-1a, folded) of
/// its host name. Short, so that a temporary name stays within a file name's 255 bytes
/// ([`MAX_SCENE_NAME_BYTES`](crate::runner::MAX_SCENE_NAME_BYTES)).
fn host_tag() -> &'static str {
    static TAG: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TAG.get_or_init(|| tag_of_host(&host_name()))
}

fn tag_of_host(host: &str) -> String {
    let hash = host.bytes().fold(0xcbf2_9ce4_8422_2325u64, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    });
    format!("{:08x}", (hash ^ (hash >> 32)) as u32)
}

/// The temporary name beside `path` that this process writes it under next.
fn tmp_path(path: &Path) -> io::Result<PathBuf> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, "path has no file name"))?;
    Ok(dir.join(format!(
        ".{}{}{}-{}-{}",
        name.to_string_lossy(),
        TMP_MARK,
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed),
        host_tag()
    )))
}

/// Writes `bytes` to `path` atomically, creating parent folders.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let dir = path.parent().unwrap_or_else(|| Path::new("."));
    fs::create_dir_all(dir)?;
    let tmp = tmp_path(path)?;
    let result = (|| {
        let mut file = fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        // No fsync: atomicity against a killed process needs only the rename; durability
        // against power loss is the filesystem's job and would cost a flush per file.
        drop(file);
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` like [`write_atomic`], unless `path` is a regular file that already
/// holds exactly these bytes: then nothing is written and it returns `false`. Replacing a file
/// by rename makes ext4 (and others with its `auto_da_alloc` rule) flush the new file's data
/// before the rename, about half a millisecond a file; a rerun whose outputs and markers come
/// out the same pays a read instead.
pub fn write_if_changed(path: &Path, bytes: &[u8]) -> io::Result<bool> {
    Ok(write_if_changed_kept(path, bytes)?.is_none())
}

/// [`write_if_changed`], giving back what it found of the file it left alone: `Some` with the
/// file's metadata, taken through the open file after it was read, when it held these bytes
/// already (nothing was written); `None` when the bytes were written. The runner takes a kept
/// output's digest from its remembered digests when that identity says the file has not changed
/// ([`crate::runner::digests`]).
pub fn write_if_changed_kept(path: &Path, bytes: &[u8]) -> io::Result<Option<fs::Metadata>> {
    if let Some(kept) = holding(path, bytes) {
        return Ok(Some(kept));
    }
    write_atomic(path, bytes)?;
    Ok(None)
}

/// The metadata of `path`, taken through the open file after it was read, when it is a regular
/// file (not a link) whose contents are `bytes`; `None` otherwise.
///
/// The file is opened first ([`open_own_file`]: a link is refused by the open, a FIFO does not
/// block it), so the path is walked once: a scene's output sits eight folders down, and the
/// walk was most of a `stat`'s cost. A file of up to [`WHOLE_COMPARE_UP_TO`] is then read
/// before it is statted, never more than one byte past the length of `bytes`
/// ([`read_sized`]), and the one `fstat` after the read tells its type and length and gives
/// the identity the runner needs after a read (two `fstat`s a file before: one to see the
/// length, one for the identity). Of anything but a regular file, at most that many bytes are
/// read and then refused: a FIFO or a terminal gives nothing (`O_NONBLOCK`), a folder an
/// error. A larger file is statted first, and read block by block only if it has the length.
fn holding(path: &Path, bytes: &[u8]) -> Option<fs::Metadata> {
    let file = open_own_file(path).ok()?;
    let len = bytes.len() as u64;
    if len <= WHOLE_COMPARE_UP_TO {
        let held = read_sized(&file, len, len).ok()?;
        if held != bytes {
            return None;
        }
        let meta = file.metadata().ok()?;
        return (meta.is_file() && meta.len() == len).then_some(meta);
    }
    let meta = file.metadata().ok()?;
    if !meta.is_file() || meta.len() != len {
        return None;
    }
    let mut reader = io::BufReader::with_capacity(1 << 16, &file);
    let mut rest = bytes;
    loop {
        let block = reader.fill_buf().ok()?;
        if block.is_empty() {
            break;
        }
        let n = block.len();
        if n > rest.len() || block != &rest[..n] {
            return None;
        }
        rest = &rest[n..];
        reader.consume(n);
    }
    if !rest.is_empty() {
        return None;
    }
    // Statted again after the read: the identity that covers it.
    file.metadata().ok().filter(|after| after.len() == len)
}

/// Opens one of mesa's own files (an output or a marker it wrote) to read it, refusing a link
/// as the last component (the open fails with `ELOOP`) and without waiting on a FIFO or a
/// device (`O_NONBLOCK`, which changes nothing for a regular file). The caller stats the open
/// file (`File::metadata`) and reads only a regular one.
///
/// Inputs are statted by path before they are opened ([`check_regular_file`]): a link to
/// them is followed, and nothing of a user's that is not a regular file is ever opened.
pub fn open_own_file(path: &Path) -> io::Result<fs::File> {
    use std::os::unix::fs::OpenOptionsExt as _;
    fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(path)
}

/// Up to this size, [`holding`] reads a file whole to compare it; above it, block by
/// block, so that comparing a scene's GLB does not hold a second copy of it in memory.
const WHOLE_COMPARE_UP_TO: u64 = 1 << 20;

/// A file written through a temporary name beside it and renamed over the target by
/// [`AtomicFile::commit`], for outputs too large to hold in memory (the record files).
/// Dropped without a commit, it removes the temporary file and leaves the target as it was.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    writer: Option<io::BufWriter<fs::File>>,
}

impl AtomicFile {
    /// Starts writing `path` (creating parent folders; leftovers of a killed writer of the same
    /// file are swept first).
    pub fn create(path: &Path) -> io::Result<Self> {
        let dir = path.parent().unwrap_or_else(|| Path::new("."));
        fs::create_dir_all(dir)?;
        sweep_tmp_for(path)?;
        let tmp = tmp_path(path)?;
        let file = fs::File::create(&tmp)?;
        Ok(Self {
            target: path.to_owned(),
            tmp,
            writer: Some(io::BufWriter::with_capacity(1 << 20, file)),
        })
    }

    /// The file being written.
    pub fn target(&self) -> &Path {
        &self.target
    }

    /// Flushes and renames the temporary file over the target.
    pub fn commit(mut self) -> io::Result<()> {
        if let Some(writer) = self.writer.take() {
            let file = writer.into_inner().map_err(|e| e.into_error())?;
            drop(file);
        }
        fs::rename(&self.tmp, &self.target)
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match self.writer.as_mut() {
            Some(w) => w.write(buf),
            None => Err(io::Error::other("write after commit")),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match self.writer.as_mut() {
            Some(w) => w.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            let _ = fs::remove_file(&self.tmp);
        }
    }
}

/// Removes temporary files left beside `path` by a killed writer of that same file: those whose
/// pid names a process of this machine that no longer runs (or whose name carries no pid).
/// Those of a process still running, this one included, are left alone: they are another run's
/// work in progress; so are those of another machine, whose processes cannot be seen from here.
pub fn sweep_tmp_for(path: &Path) -> io::Result<()> {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return Ok(());
    };
    let prefix = format!(".{}{}", name.to_string_lossy(), TMP_MARK);
    sweep_dead_tmp(dir, |file| file.strip_prefix(prefix.as_str())).map(drop)
}

/// [`sweep_tmp_for`] for every file of `dir` at once: removes the temporary files of dead
/// writers, whatever file they were writing, in one listing of the folder. For a folder that
/// takes one file a scene (a stage's markers of a table type: thousands of files), sweeping it
/// once before the scenes costs one listing, where sweeping beside each file would list the
/// folder once a scene. Gives how many temporary files the listing found, those of running
/// writers and those it removed alike (0 for a folder that does not exist).
pub fn sweep_dead_tmp_in(dir: &Path) -> io::Result<usize> {
    sweep_dead_tmp(dir, |file| {
        file.strip_prefix('.')
            .and_then(|n| n.rfind(TMP_MARK).map(|at| &n[at + TMP_MARK.len()..]))
    })
}

/// Removes the files of `dir` that `owner_part` takes for temporary files (giving what follows
/// [`TMP_MARK`] in their name, `<pid>-<n>-<host tag>`) and whose writer no longer runs; gives
/// how many such files it found.
fn sweep_dead_tmp(dir: &Path, owner_part: impl Fn(&str) -> Option<&str>) -> io::Result<usize> {
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(0),
        Err(e) => return Err(e),
    };
    let mut found = 0;
    for entry in entries {
        let entry = entry?;
        let file_name = entry.file_name();
        let Some(rest) = owner_part(&file_name.to_string_lossy()).map(str::to_owned) else {
            continue;
        };
        found += 1;
        if !writer_is_dead(&rest) {
            continue;
        }
        let _ = fs::remove_file(entry.path());
    }
    Ok(found)
}

/// Whether the writer of a temporary file, `owner` being what follows [`TMP_MARK`] in its
/// name, certainly no longer runs: a process of this machine that has exited, or a name with
/// no pid. A name of mesa before the host tag (`<pid>-<n>`) is taken for this machine's.
fn writer_is_dead(owner: &str) -> bool {
    let mut parts = owner.split('-');
    let Some(pid) = parts.next().and_then(|p| p.parse::<u32>().ok()) else {
        return true;
    };
    let _counter = parts.next();
    if let Some(tag) = parts.next() {
        if tag != host_tag() {
            return false;
        }
    }
    pid != std::process::id() && !process_running(pid)
}

/// Whether process `pid` of this machine may still be running. On Linux it is whether
/// `/proc/<pid>` exists (a reaped process has none); where there is no `/proc`, every process
/// counts as running, so nothing that might be in use is swept or taken over.
pub fn process_running(pid: u32) -> bool {
    let proc_root = Path::new("/proc");
    if !proc_root.join("self").exists() {
        return true;
    }
    proc_root.join(pid.to_string()).exists()
}

/// When process `pid` started, in clock ticks since boot (`/proc/<pid>/stat`, field 22), to
/// tell a process from a later one that got the same pid; `None` where it cannot be read.
pub fn process_start_ticks(pid: u32) -> Option<u64> {
    let stat = fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from after it.
    let after_name = &stat[stat.rfind(')')? + 1..];
    after_name.split_whitespace().nth(19)?.parse().ok()
}

/// SHA-256 of bytes, as lowercase hex.
pub fn sha256_hex(bytes: &[u8]) -> String {
    mesa_stages::sha256_hex(bytes)
}

/// The most bytes mesa reads or hashes of one kind of file, so a stray huge file (a sparse
/// disk image, a wrong path) fails in a second with a message instead of costing minutes and
/// gigabytes of memory.
#[derive(Debug, Clone, Copy)]
pub struct SizeLimit {
    /// The limit in bytes.
    pub bytes: u64,
    /// The kind of file, for messages ("a layout or JSON file").
    pub what: &'static str,
    /// The constant's name, so a message can say where the limit is set.
    pub name: &'static str,
}

/// A stage's declared input, hashed for its digests (4 GiB): far above any scene file or asset
/// index mesa writes; hashing is streamed, so this bounds time, not memory.
pub const HASHED_INPUT_LIMIT: SizeLimit = SizeLimit {
    bytes: 4 << 30,
    what: "a stage input",
    name: "HASHED_INPUT_LIMIT",
};

/// A layout file or JSON artifact read whole (64 MiB): a dense layout of a thousand objects is
/// under 1 MiB.
pub const JSON_LIMIT: SizeLimit = SizeLimit {
    bytes: 64 << 20,
    what: "a layout or JSON file",
    name: "JSON_LIMIT",
};

/// A records file `mesa validate` reads whole (`sft.json`, `dpo.json`, `test.json`, `.jsonl`:
/// 1 GiB), which grows with the dataset, unlike a layout.
pub const RECORDS_LIMIT: SizeLimit = SizeLimit {
    bytes: 1 << 30,
    what: "a records file",
    name: "RECORDS_LIMIT",
};

/// A configuration file (`mesa.toml`, 1 MiB): every key with its default is under 10 KiB.
pub const CONFIG_LIMIT: SizeLimit = SizeLimit {
    bytes: 1 << 20,
    what: "a configuration file",
    name: "CONFIG_LIMIT",
};

/// An image read whole (a render, a photo: 256 MiB; a 100-megapixel 16-bit RGBA PNG is
/// under 800 MiB raw, but mesa's own renders are a few hundred KiB).
pub const IMAGE_LIMIT: SizeLimit = SizeLimit {
    bytes: 256 << 20,
    what: "an image",
    name: "IMAGE_LIMIT",
};

/// An asset GLB read whole to be drawn (2 GiB).
pub const GLB_LIMIT: SizeLimit = SizeLimit {
    bytes: 2 << 30,
    what: "a GLB file",
    name: "GLB_LIMIT",
};

/// What kind of non-regular file `meta` describes, for messages.
fn special_kind(meta: &fs::Metadata) -> &'static str {
    let kind = meta.file_type();
    if kind.is_dir() {
        return "a folder";
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt as _;
        if kind.is_fifo() {
            return "a FIFO";
        }
        if kind.is_char_device() {
            return "a character device";
        }
        if kind.is_block_device() {
            return "a block device";
        }
        if kind.is_socket() {
            return "a socket";
        }
    }
    "a special file"
}

/// Checks, before anything opens it, that `path` (symlinks followed) is a regular file of at
/// most `limit` bytes, and returns its size. A FIFO would block an open or a read forever and a
/// device such as `/dev/zero` never ends, so only regular files are read. The error's kind is
/// `InvalidInput` (`NotFound` for a missing file); its message does not repeat the path, which
/// callers already put in front.
pub fn check_regular_file(path: &Path, limit: SizeLimit) -> io::Result<u64> {
    let meta = fs::metadata(path)?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "not a regular file ({}): only regular files are read; replace it with the file \
                 itself",
                special_kind(&meta)
            ),
        ));
    }
    if meta.len() > limit.bytes {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!(
                "{}, over the limit of {} for {}: check it is the file meant (a disk image, a \
                 sparse or corrupt copy?); the limit is mesa's `fsio::{}`",
                human_bytes(meta.len()),
                human_bytes(limit.bytes),
                limit.what,
                limit.name
            ),
        ));
    }
    Ok(meta.len())
}

/// A byte count for messages: bytes with MiB or GiB beside them.
pub fn human_bytes(n: u64) -> String {
    const MIB: u64 = 1 << 20;
    const GIB: u64 = 1 << 30;
    if n >= GIB {
        format!("{n} bytes ({:.1} GiB)", n as f64 / GIB as f64)
    } else if n >= MIB {
        format!("{n} bytes ({:.1} MiB)", n as f64 / MIB as f64)
    } else {
        format!("{n} bytes")
    }
}

/// Reads a regular file of at most `limit.bytes` bytes whole ([`check_regular_file`] first, and the
/// read itself bounded, so a file that grows meanwhile cannot exceed the limit).
pub fn read_bounded(path: &Path, limit: SizeLimit) -> io::Result<Vec<u8>> {
    let len = check_regular_file(path, limit)?;
    read_statted(&fs::File::open(path)?, len, limit)
}

/// [`read_bounded`] for one of mesa's own files (a marker, a remembered-digests file): opened
/// with [`open_own_file`] (a link is an error) and read by [`read_own_small`].
pub fn read_own_bounded(path: &Path, limit: SizeLimit) -> io::Result<Vec<u8>> {
    read_own_small(&open_own_file(path)?, limit)
}

/// What [`read_own_small`] asks for in its first read: a done marker or a digests file is
/// under a kilobyte.
const SMALL_FIRST_READ: usize = 4096;

/// Reads one of mesa's own small files, opened with [`open_own_file`], in one call when it is
/// small: the first read asks for 4 KB (`SMALL_FIRST_READ`), and a regular file's read stops
/// only at its end (page-cache reads on Linux, as [`read_sized`] relies on), so a shorter
/// answer is the whole file, without the `fstat` that would tell its size first (one system
/// call a scene and file in a forced rerun). A file that fills that read is statted: anything
/// but a regular file of at most `limit` is an error, and the rest is read to its end.
///
/// What the callers make of a short answer from something else: a FIFO or a terminal gives
/// nothing (`O_NONBLOCK`), a folder an error, and both callers parse what they read (a marker,
/// a digests file), so an empty or cut answer is no marker and no digests, as a missing file
/// is.
pub fn read_own_small(file: &fs::File, limit: SizeLimit) -> io::Result<Vec<u8>> {
    let first = SMALL_FIRST_READ.min(usize::try_from(limit.bytes).unwrap_or(usize::MAX));
    let mut bytes = vec![0u8; first];
    let n = loop {
        match (&*file).read(&mut bytes) {
            Ok(n) => break n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    };
    if n < first {
        bytes.truncate(n);
        return Ok(bytes);
    }
    let meta = file.metadata()?;
    let what = if !meta.is_file() {
        special_kind(&meta)
    } else if meta.len() > limit.bytes {
        "a file over the limit for it"
    } else {
        let size = meta.len().saturating_sub(n as u64);
        let rest = read_sized(file, size, limit.bytes - n as u64)?;
        bytes.extend_from_slice(&rest);
        if bytes.len() as u64 > limit.bytes {
            return Err(grew_over(limit));
        }
        return Ok(bytes);
    };
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "{what} ({}), where mesa keeps {}: remove it and run again",
            human_bytes(meta.len()),
            limit.what
        ),
    ))
}

/// The reading half of [`read_bounded`], for a caller that has statted the file itself (by
/// path, or through the open `file`) and found a regular file of `len` bytes, at most
/// `limit.bytes`: an error when it grew over the limit since.
pub fn read_statted(file: &fs::File, len: u64, limit: SizeLimit) -> io::Result<Vec<u8>> {
    let bytes = read_sized(file, len, limit.bytes)?;
    if bytes.len() as u64 > limit.bytes {
        return Err(grew_over(limit));
    }
    Ok(bytes)
}

/// The error for a file that grew over `limit` while it was read.
fn grew_over(limit: SizeLimit) -> io::Error {
    io::Error::new(
        io::ErrorKind::InvalidInput,
        format!(
            "grew over the limit of {} while being read",
            human_bytes(limit.bytes)
        ),
    )
}

/// Reads `file` (a regular file, `size` bytes long when it was statted) whole, but never more
/// than `max + 1` bytes: a caller tells a file that outgrew `max` by the extra byte. Any
/// reader is taken, for the tests.
///
/// **Why not `read_to_end`.** It reads in blocks of 8 KiB at first and always makes one more
/// read to see the end, so a 10 KB layout took three reads. Here the first read asks for one
/// byte more than `size`; a regular file's read stops only at its end (page-cache reads on
/// Linux), so when it returns exactly `size` bytes the file has been read whole, in one call.
/// A file that grew since it was statted, or a read cut short, goes on block by block to the
/// end as before.
pub fn read_sized(mut file: impl Read, size: u64, max: u64) -> io::Result<Vec<u8>> {
    let want = size.min(max).saturating_add(1);
    let mut bytes = vec![0u8; usize::try_from(want).map_err(io::Error::other)?];
    let mut filled = 0;
    while filled < bytes.len() {
        let n = match file.read(&mut bytes[filled..]) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        filled += n;
        if filled as u64 == size && filled < bytes.len() {
            // Asked for more than `size` and got exactly `size`: the end.
            bytes.truncate(filled);
            return Ok(bytes);
        }
    }
    bytes.truncate(filled);
    if filled as u64 == want {
        // Longer than `size` (it grew since it was statted) or than `max`: the rest, up to
        // one byte over `max`.
        file.take(max.saturating_add(1) - want)
            .read_to_end(&mut bytes)?;
    }
    Ok(bytes)
}

/// [`read_bounded`] as UTF-8 text (`InvalidData` when it is not).
pub fn read_text_bounded(path: &Path, limit: SizeLimit) -> io::Result<String> {
    String::from_utf8(read_bounded(path, limit)?).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            "not UTF-8 text (expected a JSON or text file)",
        )
    })
}

/// SHA-256 of a file's content, streamed. Only a regular file of at most
/// [`HASHED_INPUT_LIMIT`] is hashed (see [`check_regular_file`]).
pub fn sha256_file(path: &Path) -> io::Result<String> {
    check_regular_file(path, HASHED_INPUT_LIMIT)?;
    sha256_reader(fs::File::open(path)?, HASHED_INPUT_LIMIT)
}

/// SHA-256 of what `reader` gives, streamed, up to `limit`'s bytes.
pub fn sha256_reader(reader: impl Read, limit: SizeLimit) -> io::Result<String> {
    let mut file = reader.take(limit.bytes);
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = file.read(&mut buf)?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(mesa_stages::hex(&hasher.finalize()))
}

/// Digests of files shared by many scenes (asset index, annotations), computed once per run.
#[derive(Debug, Default)]
pub struct DigestCache {
    shared: Mutex<HashMap<PathBuf, String>>,
}

impl DigestCache {
    /// The digest of `path` (a file outside the scene folders), hashed the first time only.
    /// A scene's own inputs go through `runner::digests` instead.
    pub fn digest(&self, path: &Path) -> io::Result<String> {
        if let Some(d) = self.lock().get(path) {
            return Ok(d.clone());
        }
        let d = sha256_file(path)?;
        self.lock().insert(path.to_owned(), d.clone());
        Ok(d)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<PathBuf, String>> {
        // A poisoned cache only means another thread panicked mid-insert; the map is fine.
        self.shared.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Reads a JSON artifact, naming the file in every error: at most [`JSON_LIMIT`], a
/// regular file only.
pub fn read_json<T: DeserializeOwned>(path: &Path, hint: &str) -> anyhow::Result<T> {
    let bytes = read_bounded(path, JSON_LIMIT)
        .with_context(|| format!("{}: cannot read ({hint})", path.display()))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| anyhow!("{}: not UTF-8 text (expected JSON; {hint})", path.display()))?;
    if mesa_schemas::json::starts_with_bom(&text) {
        bail!("{}: {}", path.display(), mesa_schemas::json::BOM_PROBLEM);
    }
    let value =
        serde_json::from_str(&text).map_err(|e| anyhow!("{}: {e} ({hint})", path.display()))?;
    mesa_schemas::json::check_unique_keys(&text)
        .map_err(|e| anyhow!("{}: {e} ({hint})", path.display()))?;
    Ok(value)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_if_changed_leaves_a_file_that_holds_the_bytes() {
        use std::os::unix::fs::MetadataExt as _;
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("out/graph.txt");
        assert!(write_if_changed(&target, b"(a, is at, center)\n").expect("first write"));
        let inode = |p: &Path| fs::symlink_metadata(p).expect("meta").ino();
        let first = inode(&target);
        // The same bytes: not written (the file is the same inode, not a renamed copy).
        assert!(!write_if_changed(&target, b"(a, is at, center)\n").expect("same"));
        assert_eq!(inode(&target), first);
        // Controls: other bytes of the same length, and another length, are written.
        assert!(write_if_changed(&target, b"(b, is at, center)\n").expect("changed"));
        assert_ne!(inode(&target), first);
        assert_eq!(fs::read(&target).expect("read"), b"(b, is at, center)\n");
        assert!(
            write_if_changed(&target, b"(b, is at, center)\n(b, face to, front)\n")
                .expect("longer")
        );
        assert_eq!(
            fs::read(&target).expect("read"),
            b"(b, is at, center)\n(b, face to, front)\n"
        );
        // Bytes that the file starts with, but shorter: written (the read goes one byte past).
        assert!(write_if_changed(&target, b"(b, is at, center)\n").expect("shorter"));
        assert_eq!(fs::read(&target).expect("read"), b"(b, is at, center)\n");
        // The metadata given back for a kept file is the file's, as statted after the read.
        let kept = write_if_changed_kept(&target, b"(b, is at, center)\n")
            .expect("kept")
            .expect("the file holds the bytes");
        assert_eq!((kept.ino(), kept.len()), (inode(&target), 19));
        // A link to a file with the bytes is replaced by a file, as write_atomic does.
        let elsewhere = dir.path().join("elsewhere.txt");
        fs::write(&elsewhere, b"linked").expect("write");
        let link = dir.path().join("out/link.txt");
        std::os::unix::fs::symlink(&elsewhere, &link).expect("symlink");
        assert!(write_if_changed(&link, b"linked").expect("link"));
        assert!(fs::symlink_metadata(&link).expect("meta").is_file());
        // A FIFO is replaced by a file, without waiting for a writer to open it (the empty
        // bytes too: a FIFO reads as empty, but it is not a regular file).
        for bytes in [&b""[..], b"(a, is at, center)\n"] {
            let fifo = dir.path().join("out/fifo.txt");
            let _ = fs::remove_file(&fifo);
            let status = std::process::Command::new("mkfifo")
                .arg(&fifo)
                .status()
                .expect("mkfifo");
            assert!(status.success());
            assert!(write_if_changed(&fifo, bytes).expect("fifo"));
            assert_eq!(fs::read(&fifo).expect("read"), bytes);
        }
    }

    /// Temporary names carry this machine's tag, and the tags of two host names differ.
    #[test]
    fn temporary_names_carry_the_host_tag() {
        let dir = tempfile::tempdir().expect("tempdir");
        let tmp = tmp_path(&dir.path().join("out.json")).expect("name");
        let name = tmp
            .file_name()
            .expect("name")
            .to_string_lossy()
            .into_owned();
        let owner = name.split(TMP_MARK).nth(1).expect("mark");
        let parts: Vec<&str> = owner.split('-').collect();
        assert_eq!(parts.len(), 3, "{name}");
        assert_eq!(parts[0], std::process::id().to_string());
        assert_eq!(parts[2], host_tag());
        assert_eq!(host_tag().len(), 8);
        assert_ne!(tag_of_host("node-1"), tag_of_host("node-2"));
        assert_eq!(tag_of_host(&host_name()), host_tag());
    }

    #[test]
    fn atomic_write_replaces_and_sweeps() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("a/b/out.json");
        write_atomic(&target, b"one").expect("write");
        write_atomic(&target, b"two").expect("write");
        assert_eq!(fs::read(&target).expect("read"), b"two");
        let dead = dead_pid();
        let stray = dir.path().join(format!("a/b/.out.json{TMP_MARK}{dead}-0"));
        fs::write(&stray, b"half").expect("stray");
        let other = dir
            .path()
            .join(format!("a/b/.other.json{TMP_MARK}{dead}-0"));
        fs::write(&other, b"half").expect("other");
        // A leftover of a process that runs (this one) is another run's work in progress.
        let live = dir
            .path()
            .join(format!("a/b/.out.json{TMP_MARK}{}-7", std::process::id()));
        fs::write(&live, b"busy").expect("live");
        sweep_tmp_for(&target).expect("sweep");
        assert!(!stray.exists(), "a dead writer's leftover is swept");
        assert!(other.exists(), "only the named file's leftovers are swept");
        assert!(
            live.exists(),
            "a live writer's temporary file is left alone"
        );
    }

    #[test]
    fn a_folder_sweep_removes_every_dead_writers_leftover_and_nothing_else() {
        let dir = tempfile::tempdir().expect("tempdir");
        let dead = dead_pid();
        let strays: Vec<PathBuf> = ["a.json", "b.json", "name.with.dots.json"]
            .iter()
            .map(|n| dir.path().join(format!(".{n}{TMP_MARK}{dead}-3")))
            .collect();
        for stray in &strays {
            fs::write(stray, b"half").expect("stray");
        }
        // Written by this mesa on this machine, by a dead process: swept too.
        let tagged = dir
            .path()
            .join(format!(".c.json{TMP_MARK}{dead}-4-{}", host_tag()));
        fs::write(&tagged, b"half").expect("tagged");
        let live = dir
            .path()
            .join(format!(".a.json{TMP_MARK}{}-1", std::process::id()));
        let kept = [
            dir.path().join("a.json"),
            // Not temporary names: no leading dot, or no mark.
            dir.path().join(format!("a.json{TMP_MARK}{dead}-0")),
            dir.path().join(".hidden.json"),
            live.clone(),
            // Another machine's writer (the same pid says nothing here): left alone.
            dir.path().join(format!(
                ".b.json{TMP_MARK}{dead}-2-{}",
                tag_of_host("another-node")
            )),
        ];
        for file in &kept {
            fs::write(file, b"keep").expect("write");
        }
        // Found: the four of dead writers, removed, and the two of writers it cannot call dead.
        assert_eq!(sweep_dead_tmp_in(dir.path()).expect("sweep"), 6);
        for stray in strays.iter().chain([&tagged]) {
            assert!(!stray.exists(), "{} is swept", stray.display());
        }
        for file in &kept {
            assert!(file.exists(), "{} is left alone", file.display());
        }
        assert_eq!(sweep_dead_tmp_in(dir.path()).expect("again"), 2);
        // A folder that does not exist has nothing to sweep.
        assert_eq!(
            sweep_dead_tmp_in(&dir.path().join("none")).expect("missing folder"),
            0
        );
    }

    /// The pid of a process that has exited and been reaped.
    fn dead_pid() -> u32 {
        let mut child = std::process::Command::new("true")
            .spawn()
            .expect("spawn true");
        let pid = child.id();
        child.wait().expect("wait");
        pid
    }

    #[test]
    fn running_processes_are_told_from_dead_ones() {
        assert!(process_running(std::process::id()));
        assert!(!process_running(dead_pid()));
        assert!(process_start_ticks(std::process::id()).is_some());
    }

    #[test]
    fn streamed_files_appear_only_on_commit() {
        let dir = tempfile::tempdir().expect("tempdir");
        let target = dir.path().join("records/sft.json");
        let mut file = AtomicFile::create(&target).expect("create");
        file.write_all(b"[]\n").expect("write");
        assert!(!target.exists(), "nothing before the commit");
        file.commit().expect("commit");
        assert_eq!(fs::read(&target).expect("read"), b"[]\n");
        let mut abandoned = AtomicFile::create(&target).expect("create");
        abandoned.write_all(b"half").expect("write");
        drop(abandoned);
        assert_eq!(
            fs::read(&target).expect("read"),
            b"[]\n",
            "an abandoned write changes nothing"
        );
        let leftovers = fs::read_dir(dir.path().join("records"))
            .expect("list")
            .count();
        assert_eq!(leftovers, 1, "and leaves no temporary file");
    }

    /// A reader of `data` as a regular file reads: each call gives what is asked for, up to
    /// the end; except its first call, which may be cut to `cut` bytes (a read cut short) or
    /// fail with `Interrupted`. It counts its calls.
    struct FileLike<'a> {
        data: &'a [u8],
        cut: Option<usize>,
        interrupt_first: bool,
        calls: usize,
    }

    impl Read for FileLike<'_> {
        fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
            self.calls += 1;
            if std::mem::take(&mut self.interrupt_first) {
                return Err(io::ErrorKind::Interrupted.into());
            }
            let limit = self.cut.take().unwrap_or(usize::MAX);
            let n = buf.len().min(limit).min(self.data.len());
            buf[..n].copy_from_slice(&self.data[..n]);
            self.data = &self.data[n..];
            Ok(n)
        }
    }

    fn file_like(data: &[u8]) -> FileLike<'_> {
        FileLike {
            data,
            cut: None,
            interrupt_first: false,
            calls: 0,
        }
    }

    /// A file read whole in one call when it still has its statted size; every other case (a
    /// read cut short, a file that grew or shrank, one over the bound) reads on to its end or
    /// to one byte over the bound, as `read_to_end` over `take(max + 1)` does.
    #[test]
    fn a_sized_read_reads_whole_in_one_call_and_every_other_case_to_the_end() {
        let data: Vec<u8> = (0..10_000u32).map(|i| (i * 7 % 251) as u8).collect();
        let reference = |max: u64| {
            let mut all = Vec::new();
            data.as_slice()
                .take(max + 1)
                .read_to_end(&mut all)
                .expect("read");
            all
        };
        // The size as statted: one call.
        let mut reader = file_like(&data);
        let bytes = read_sized(&mut reader, data.len() as u64, 1 << 20).expect("read");
        assert!(bytes == data);
        assert_eq!(reader.calls, 1);
        // The control: `read_to_end` makes more calls for the same file.
        let mut reader = file_like(&data);
        let mut all = Vec::new();
        (&mut reader)
            .take(1 << 20)
            .read_to_end(&mut all)
            .expect("read");
        assert!(reader.calls > 1, "{} calls", reader.calls);

        for (cut, interrupt_first) in [
            (None, false),
            (None, true),
            (Some(1), false),
            (Some(4096), true),
        ] {
            for (size, max) in [
                (10_000, 1 << 20), // as statted
                (9_000, 1 << 20),  // grew since
                (11_000, 1 << 20), // shrank since
                (10_000, 9_999),   // over the bound
                (5_000, 6_000),    // grew over the bound
                (0, 1 << 20),      // was empty
            ] {
                let mut reader = file_like(&data);
                reader.cut = cut;
                reader.interrupt_first = interrupt_first;
                let bytes = read_sized(&mut reader, size, max).expect("read");
                let expected = reference(max);
                assert!(
                    bytes == expected,
                    "cut {cut:?}, size {size}, max {max}: {} bytes read, {} expected",
                    bytes.len(),
                    expected.len()
                );
            }
        }
        let bytes = read_sized(file_like(&[]), 0, 100).expect("read");
        assert!(bytes.is_empty());
    }

    /// mesa's own small files are read whole at any size up to the limit (below the first
    /// read's size, at it, and past it); a file over the limit and a folder are errors, and a
    /// FIFO gives nothing without waiting for a writer.
    #[test]
    fn own_small_files_are_read_whole_and_anything_else_refused() {
        let dir = tempfile::tempdir().expect("tempdir");
        let limit = SizeLimit {
            bytes: 10_000,
            what: "a test file",
            name: "TEST_LIMIT",
        };
        for len in [
            0,
            1,
            800,
            SMALL_FIRST_READ - 1,
            SMALL_FIRST_READ,
            SMALL_FIRST_READ + 1,
            10_000,
        ] {
            let path = dir.path().join(format!("f{len}"));
            let data: Vec<u8> = (0..len).map(|i| (i * 31 % 251) as u8).collect();
            fs::write(&path, &data).expect("write");
            assert!(
                read_own_bounded(&path, limit).expect("read") == data,
                "{len} bytes"
            );
        }
        let over = dir.path().join("over");
        fs::write(&over, vec![7u8; 10_001]).expect("write");
        let e = read_own_bounded(&over, limit).expect_err("over the limit");
        assert!(e.to_string().contains("over the limit"), "{e}");
        let e = read_own_bounded(dir.path(), limit).expect_err("a folder");
        assert_eq!(e.raw_os_error(), Some(libc::EISDIR), "{e}");
        let fifo = dir.path().join("fifo");
        let status = std::process::Command::new("mkfifo")
            .arg(&fifo)
            .status()
            .expect("mkfifo");
        assert!(status.success());
        assert!(read_own_bounded(&fifo, limit).expect("a FIFO").is_empty());
        // A link is refused by the open.
        let link = dir.path().join("link");
        std::os::unix::fs::symlink(dir.path().join("f800"), &link).expect("symlink");
        let e = read_own_bounded(&link, limit).expect_err("a link");
        assert_eq!(e.raw_os_error(), Some(libc::ELOOP), "{e}");
    }

    #[test]
    fn digests_are_sha256() {
        assert_eq!(
            sha256_hex(b"abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}

//! What the runner learnt of a scene's files while it prepared the scene, handed to the stage
//! that processes it on the same thread: the bytes of the small inputs it hashed, and which
//! files exist.
//!
//! **Why.** A cheap stage paid for its files twice. The graph stage's work is 5 µs a scene,
//! and around it the runner hashed the layout (open, read, close) and then the stage read it
//! again; and the scene's layout candidates were looked up three times (for the waiting
//! check, the inputs, the run), two `stat`s each. On 1,000 scenes that was about a tenth of
//! `mesa graph`. With the bytes handed over, the marker's digest also describes exactly the
//! bytes the stage used.
//!
//! **Scope.** [`process_scene`](super::process_scene) opens a record for one scene on its
//! thread and closes it when the scene is done, outputs written or not, so nothing outlives
//! the scene: a file that a later stage of `mesa run` writes (a settled `qa/layout.json`) is
//! seen by that stage's own record. Outside a scene (`mesa status`, the file tools, other
//! threads a stage starts) every call goes to the file system. Within a scene no one else
//! writes its inputs: the stage's lock keeps other runs out, and a stage's outputs are written
//! after its run.

use std::cell::RefCell;
use std::path::{Path, PathBuf};

/// One scene's record.
#[derive(Default)]
struct SceneFiles {
    /// Whether a path is a regular file (following links, as [`Path::is_file`]).
    is_file: Entries<Known>,
    /// The bytes of inputs the runner read whole to hash them.
    bytes: Entries<Vec<u8>>,
}

/// A few paths of one scene with what is known of each, looked up by the path's bytes.
///
/// A scene knows half a dozen files, so a list searched in order costs less than a map, whose
/// hash of a `Path` parses it into components first. Two spellings of one file (`a//b`, `a/b`)
/// are two entries: a miss only costs a lookup again, never a wrong answer.
struct Entries<T>(Vec<(PathBuf, T)>);

impl<T> Default for Entries<T> {
    fn default() -> Self {
        Self(Vec::new())
    }
}

impl<T> Entries<T> {
    fn position(&self, path: &Path) -> Option<usize> {
        let key = path.as_os_str().as_encoded_bytes();
        self.0
            .iter()
            .position(|(p, _)| p.as_os_str().as_encoded_bytes() == key)
    }

    fn get(&self, path: &Path) -> Option<&T> {
        self.position(path).map(|i| &self.0[i].1)
    }

    fn insert(&mut self, path: &Path, value: T) {
        match self.position(path) {
            Some(i) => self.0[i].1 = value,
            None => self.0.push((path.to_path_buf(), value)),
        }
    }

    fn remove(&mut self, path: &Path) -> Option<T> {
        self.position(path).map(|i| self.0.swap_remove(i).1)
    }
}

/// What a scene's record knows of a path.
#[derive(Debug, Clone, Copy)]
enum Known {
    /// Not a regular file (absent, a folder, …).
    NotAFile,
    /// A regular file, with its size when the runner statted it (not when it only read it).
    File(Option<u64>),
}

thread_local! {
    static RECORD: RefCell<Option<SceneFiles>> = const { RefCell::new(None) };
}

/// Runs `f` with a fresh record of the scene's files on this thread, dropped when `f` returns
/// or panics.
pub(crate) fn within_scene<R>(f: impl FnOnce() -> R) -> R {
    struct Close(Option<SceneFiles>);
    impl Drop for Close {
        fn drop(&mut self) {
            let outer = self.0.take();
            RECORD.with(|record| *record.borrow_mut() = outer);
        }
    }
    let outer = RECORD.with(|record| record.borrow_mut().replace(SceneFiles::default()));
    let _close = Close(outer);
    f()
}

/// Whether `path` is a regular file ([`Path::is_file`]), looked up once per scene.
pub fn is_file(path: &Path) -> bool {
    RECORD.with(|record| {
        let mut record = record.borrow_mut();
        let Some(files) = record.as_mut() else {
            return path.is_file();
        };
        if let Some(known) = files.is_file.get(path) {
            return matches!(known, Known::File(_));
        }
        let known = match std::fs::metadata(path) {
            Ok(meta) if meta.is_file() => Known::File(Some(meta.len())),
            _ => Known::NotAFile,
        };
        files.is_file.insert(path, known);
        matches!(known, Known::File(_))
    })
}

/// The size of `path` when [`is_file`] found it a regular file in this scene, so that the
/// runner reading it next does not stat it again; `None` outside a scene, or when not known.
pub(crate) fn regular_file_size(path: &Path) -> Option<u64> {
    RECORD.with(
        |record| match record.borrow().as_ref()?.is_file.get(path)? {
            Known::File(size) => *size,
            Known::NotAFile => None,
        },
    )
}

/// Keeps the bytes of an input the runner read whole (to hash it), for the stage; nothing is
/// kept outside a scene.
pub(crate) fn keep(path: &Path, bytes: Vec<u8>) {
    RECORD.with(|record| {
        if let Some(files) = record.borrow_mut().as_mut() {
            files.is_file.insert(path, Known::File(None));
            files.bytes.insert(path, bytes);
        }
    });
}

/// The bytes of `path` as the runner read them for this scene, if it did (taken: a second
/// call reads the file).
pub fn take(path: &Path) -> Option<Vec<u8>> {
    RECORD.with(|record| record.borrow_mut().as_mut()?.bytes.remove(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Entries are found by the path's bytes: an insert of a known path replaces its value, a
    /// removal takes it out, and another spelling of the same file is another entry.
    #[test]
    fn entries_are_found_by_the_paths_bytes() {
        let mut entries = Entries::default();
        entries.insert(Path::new("s/graph/graph.json"), 1);
        entries.insert(Path::new("s/graph/graph.txt"), 2);
        entries.insert(Path::new("s/graph/graph.json"), 3);
        assert_eq!(entries.0.len(), 2);
        assert_eq!(entries.get(Path::new("s/graph/graph.json")), Some(&3));
        assert_eq!(entries.get(Path::new("s//graph/graph.json")), None);
        assert_eq!(entries.remove(Path::new("s/graph/graph.json")), Some(3));
        assert_eq!(entries.get(Path::new("s/graph/graph.json")), None);
        assert_eq!(entries.get(Path::new("s/graph/graph.txt")), Some(&2));
    }

    /// Inside a scene, answers come from the record; outside, from the file system. The
    /// control: the same questions outside a scene see the file's change.
    #[test]
    fn a_record_lives_as_long_as_its_scene() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("layout.json");
        within_scene(|| {
            assert!(!is_file(&path));
            assert_eq!(regular_file_size(&path), None);
            std::fs::write(&path, b"{}").expect("write");
            // Looked up once per scene: still absent.
            assert!(!is_file(&path));
            assert_eq!(regular_file_size(&path), None);
            keep(&path, b"kept".to_vec());
            assert!(is_file(&path));
            assert_eq!(take(&path).as_deref(), Some(&b"kept"[..]));
            assert_eq!(take(&path), None);
        });
        assert!(is_file(&path));
        keep(&path, b"kept".to_vec());
        assert_eq!(take(&path), None);
        // A new scene starts with nothing known; its size is that of its lookup.
        within_scene(|| {
            assert_eq!(regular_file_size(&path), None);
            assert!(is_file(&path));
            assert_eq!(regular_file_size(&path), Some(2));
            std::fs::write(&path, b"{ }").expect("write");
            assert_eq!(regular_file_size(&path), Some(2));
            assert_eq!(take(&path), None);
        });
        assert_eq!(regular_file_size(&path), None);
        // A panic inside a scene closes its record too.
        let caught = std::panic::catch_unwind(|| {
            within_scene(|| {
                keep(&path, b"kept".to_vec());
                panic!("stage bug");
            })
        });
        assert!(caught.is_err());
        assert_eq!(take(&path), None);
    }
}

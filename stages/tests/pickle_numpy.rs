//! `sbert_text_features.pkl` as Python's pickle and numpy write it: protocols 2 to 5, float16
//! and float32, numpy 1.x and 2.x global names, C, Fortran and big-endian arrays, read by
//! `mesa_stages::pickle` bit for bit; and the protocol-4 file mesa writes, loaded by Python's
//! `pickle.load` (what `compress_pickle.load` does for `.pkl`).
//!
//! Needs `MESA_PYTHON` (a Python with numpy; scripts/test.sh sets it): skipped with a message
//! without it, a failure under `MESA_REQUIRE_TOOLS=1`.

use std::path::{Path, PathBuf};
use std::process::Command;

use mesa_stages::pickle::{read_text_features, write_text_features, FloatKind, PickleError};

fn python() -> Option<PathBuf> {
    let required = std::env::var_os("MESA_REQUIRE_TOOLS").is_some();
    match std::env::var_os("MESA_PYTHON") {
        Some(p) => Some(PathBuf::from(p)),
        None => {
            assert!(
                !required,
                "MESA_PYTHON is not set: scripts/test.sh sets it to a Python with numpy"
            );
            eprintln!("SKIPPED: pickles written by numpy (set MESA_PYTHON to a Python with numpy)");
            None
        }
    }
}

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/pickles.py")
}

fn generate(python: &Path, dir: &Path) -> Vec<serde_json::Value> {
    let out = Command::new(python)
        .arg(script())
        .arg(dir)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "pickles.py failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let cases = std::fs::read_to_string(dir.join("cases.json")).expect("cases.json");
    serde_json::from_str::<Vec<serde_json::Value>>(&cases).expect("cases parse")
}

#[test]
fn numpy_pickles_read_bit_for_bit_and_python_reads_ours() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = generate(&python, dir.path());
    assert_eq!(
        cases.len(),
        4 * 2 * 2 * 3,
        "every protocol, dtype, numpy and order"
    );
    for case in &cases {
        let name = case["name"].as_str().expect("name");
        let pkl = std::fs::read(dir.path().join(format!("{name}.pkl"))).expect("pkl");
        let expected = std::fs::read(dir.path().join(format!("{name}.bin"))).expect("bin");
        let uids: Vec<String> = serde_json::from_str(
            &std::fs::read_to_string(dir.path().join(format!("{name}.uids.json"))).expect("uids"),
        )
        .expect("uids parse");
        // The numpy 2.x cases really name numpy._core (the generator's renaming worked).
        let names_core = pkl.windows(11).any(|w| w == b"numpy._core");
        assert_eq!(names_core, case["numpy"] == 2, "{name}: global names");
        let features = read_text_features(&pkl).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert_eq!(features.uids, uids, "{name}");
        assert_eq!(features.cols, 768, "{name}");
        let kind = if case["kind"] == "f2" {
            FloatKind::F16
        } else {
            FloatKind::F32
        };
        assert_eq!(features.kind, kind, "{name}");
        assert!(
            features.data_le == expected,
            "{name}: features differ from numpy's bytes"
        );

        // Ours, loaded by Python's pickle (checked against numpy's bytes there).
        let ours = dir.path().join(format!("{name}.ours.pkl"));
        std::fs::write(&ours, write_text_features(&features)).expect("write");
        let out = Command::new(&python)
            .arg(script())
            .arg("--check")
            .arg(&ours)
            .arg(dir.path().join(format!("{name}.bin")))
            .arg(dir.path().join(format!("{name}.uids.json")))
            .output()
            .expect("python runs");
        assert!(
            out.status.success(),
            "{name}: pickle.load of mesa's file: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    // Control: the Python check sees a changed bit (it can fail).
    let name = cases[0]["name"].as_str().expect("name");
    let mut features =
        read_text_features(&std::fs::read(dir.path().join(format!("{name}.pkl"))).expect("pkl"))
            .expect("reads");
    features.data_le[100] ^= 1;
    let ours = dir.path().join("control.pkl");
    std::fs::write(&ours, write_text_features(&features)).expect("write");
    let out = Command::new(&python)
        .arg(script())
        .arg("--check")
        .arg(&ours)
        .arg(dir.path().join(format!("{name}.bin")))
        .arg(dir.path().join(format!("{name}.uids.json")))
        .output()
        .expect("python runs");
    assert!(!out.status.success(), "a flipped bit must fail the check");
}

#[test]
fn truncated_and_corrupted_numpy_pickles_are_errors() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    generate(&python, dir.path());
    for name in ["p2_f2_np1_C", "p5_f4_np2_F"] {
        let pkl = std::fs::read(dir.path().join(format!("{name}.pkl"))).expect("pkl");
        // Control: whole, it reads.
        assert!(read_text_features(&pkl).is_ok());
        for cut in (0..pkl.len()).step_by(97) {
            assert!(
                read_text_features(&pkl[..cut]).is_err(),
                "{name} cut at {cut}"
            );
        }
        // Every single-byte change either reads or is an error; none panics.
        for at in (0..pkl.len().min(400)).chain((pkl.len().saturating_sub(200))..pkl.len()) {
            for value in [0u8, 0x80, 0xff, b'c', b'R'] {
                let mut bad = pkl.clone();
                bad[at] = value;
                let _ = read_text_features(&bad);
            }
        }
    }
}

#[test]
fn dangerous_globals_are_refused_by_name() {
    let Some(python) = python() else { return };
    let dir = tempfile::tempdir().expect("tempdir");
    let file = dir.path().join("evil.pkl");
    let code = format!(
        "import pickle, os\n\
         class E:\n    def __reduce__(self): return (os.system, ('true',))\n\
         class V:\n    def __reduce__(self): return (eval, ('1',))\n\
         for p in (2, 5):\n\
         \x20   pickle.dump({{'uids': ['a'], 'text_features': E()}}, open(r'{0}.%d' % p, 'wb'), protocol=p)\n\
         \x20   pickle.dump({{'uids': ['a'], 'text_features': V()}}, open(r'{0}.v%d' % p, 'wb'), protocol=p)\n",
        file.display()
    );
    let out = Command::new(&python)
        .arg("-c")
        .arg(code)
        .output()
        .expect("python");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Protocol 2 writes Python 2's module names (`__builtin__`).
    for (suffix, global) in [
        ("2", "posix.system"),
        ("5", "posix.system"),
        ("v2", "__builtin__.eval"),
        ("v5", "builtins.eval"),
    ] {
        let bytes = std::fs::read(format!("{}.{suffix}", file.display())).expect("read");
        let err = read_text_features(&bytes).expect_err("refused");
        assert_eq!(err, PickleError::Global(global.to_owned()), "{suffix}");
        assert!(err.to_string().contains(global));
    }
}

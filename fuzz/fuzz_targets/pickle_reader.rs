//! The reader of `sbert_text_features.pkl` on arbitrary bytes: every input must give the
//! features or an error (a refused global, a truncation, a malformed structure), never a
//! panic, a hang or an allocation beyond the input's size; whatever reads must write back to
//! a pickle that reads to the same features, and to a `.npy` of the right length.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mesa_stages::pickle::{read_text_features, write_text_features};

fuzz_target!(|data: &[u8]| {
    if let Ok(features) = read_text_features(data) {
        let again = read_text_features(&write_text_features(&features)).expect("ours reads");
        assert_eq!(again, features);
        let npy = features.to_npy();
        assert!(npy.len() >= features.data_le.len());
    }
});

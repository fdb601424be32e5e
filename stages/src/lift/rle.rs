//! COCO run-length masks (`{"size": [h, w], "counts": [...] | "..."}`), as pycocotools
//! encodes them: runs alternate 0s and 1s starting with 0s, in **column-major** order; the
//! string form packs each count in 5-bit groups offset by 48, with counts after the second
//! stored as differences from the count two before.

use serde_json::Value;

/// The most pixels a mask may have: pixel indices are `u32`, and a mask this large is a
/// damaged `size` long before it is a real image (16384 × 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

/// The most 5-bit groups one compressed count may use: 12 groups are 60 bits, which hold any
/// run length of an image of [`MAX_PIXELS`] and still leave the sign bit inside an `i64`.
const MAX_GROUPS: u32 = 12;

/// A decoded mask: its size and the row-major indices of its pixels, sorted.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RleMask {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major indices of the mask's pixels, sorted.
    pub pixels: Vec<u32>,
}

/// Why a COCO RLE object cannot be decoded; the text names the field and what is expected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RleError {
    /// `size` is absent or not a two-element list.
    #[error("size is missing or not [height, width]")]
    SizeMissing,
    /// An entry of `size` is not a non-negative integer.
    #[error("size must be two integers")]
    SizeNotIntegers,
    /// `size` has more pixels than [`MAX_PIXELS`].
    #[error(
        "size [{height}, {width}] has more than {MAX_PIXELS} pixels (expected the size of the \
         depth map, [height, width])"
    )]
    SizeTooLarge {
        /// `size[0]`.
        height: u64,
        /// `size[1]`.
        width: u64,
    },
    /// An entry of a list `counts` is not a non-negative integer.
    #[error("counts must be non-negative integers")]
    CountsNotIntegers,
    /// `counts` is absent or neither a list nor a string.
    #[error("counts is missing (a list of run lengths or a compressed string)")]
    CountsMissing,
    /// The runs do not add up to the pixels of `size`.
    #[error("the runs cover {total} pixels but size [{height}, {width}] has {pixels}")]
    WrongTotal {
        /// The sum of the runs (saturating).
        total: u64,
        /// `size[0]`.
        height: usize,
        /// `size[1]`.
        width: usize,
        /// `height × width`.
        pixels: usize,
    },
    /// A byte of a compressed `counts` is outside `'0'..='o'`.
    #[error("invalid character {0:?} in counts")]
    InvalidCharacter(char),
    /// A compressed `counts` stops inside a number.
    #[error("counts ends in the middle of a number")]
    Unterminated,
    /// A compressed run length uses more 5-bit groups than any real mask needs, or adding
    /// it to the run two before leaves the 64-bit range.
    #[error(
        "counts: run {index} is out of range (more than {MAX_GROUPS} characters, or beyond \
         2^59 pixels; expected the pycocotools string of a mask of at most {MAX_PIXELS} pixels)"
    )]
    RunOutOfRange {
        /// Which run (0-based).
        index: usize,
    },
    /// A decoded run length is negative.
    #[error("negative run length {0}")]
    NegativeRun(i64),
}

/// The `[height, width]` of a COCO RLE object, checked against the pixel limit, without
/// reading its counts.
pub fn size(value: &Value) -> Result<(usize, usize), RleError> {
    let size = value
        .get("size")
        .and_then(Value::as_array)
        .filter(|s| s.len() == 2)
        .ok_or(RleError::SizeMissing)?;
    let dim = |v: &Value| v.as_u64().ok_or(RleError::SizeNotIntegers);
    let (height, width) = (dim(&size[0])?, dim(&size[1])?);
    // Checked before any count is read, so `height * width` below cannot overflow.
    if height.checked_mul(width).is_none_or(|n| n > MAX_PIXELS) {
        return Err(RleError::SizeTooLarge { height, width });
    }
    Ok((height as usize, width as usize))
}

/// Decodes a COCO RLE object.
pub fn decode(value: &Value) -> Result<RleMask, RleError> {
    let (height, width) = size(value)?;
    let counts: Vec<u64> = match value.get("counts") {
        Some(Value::Array(list)) => list
            .iter()
            .map(|c| c.as_u64().ok_or(RleError::CountsNotIntegers))
            .collect::<Result<_, _>>()?,
        Some(Value::String(text)) => decode_string(text)?,
        _ => return Err(RleError::CountsMissing),
    };
    let total = counts.iter().fold(0u64, |sum, c| sum.saturating_add(*c));
    if total != (width * height) as u64 {
        return Err(RleError::WrongTotal {
            total,
            height,
            width,
            pixels: width * height,
        });
    }
    let mut pixels = Vec::new();
    let mut position = 0u64;
    for (i, run) in counts.iter().enumerate() {
        if i % 2 == 1 {
            for j in position..position + run {
                let (row, col) = ((j as usize) % height, (j as usize) / height);
                pixels.push((row * width + col) as u32);
            }
        }
        position += run;
    }
    pixels.sort_unstable();
    Ok(RleMask {
        width,
        height,
        pixels,
    })
}

fn decode_string(text: &str) -> Result<Vec<u64>, RleError> {
    let bytes = text.as_bytes();
    let mut counts: Vec<i64> = Vec::new();
    let mut p = 0;
    while p < bytes.len() {
        let mut x: i64 = 0;
        let mut k = 0;
        loop {
            let c = i64::from(bytes[p]) - 48;
            if !(0..64).contains(&c) {
                return Err(RleError::InvalidCharacter(bytes[p] as char));
            }
            // pycocotools shifts without a bound (undefined behaviour in C past 64 bits).
            if k == MAX_GROUPS {
                return Err(RleError::RunOutOfRange {
                    index: counts.len(),
                });
            }
            x |= (c & 0x1f) << (5 * k);
            let more = c & 0x20 != 0;
            p += 1;
            k += 1;
            if !more {
                if c & 0x10 != 0 {
                    x |= -1i64 << (5 * k);
                }
                break;
            }
            if p >= bytes.len() {
                return Err(RleError::Unterminated);
            }
        }
        if counts.len() > 2 {
            x = x
                .checked_add(counts[counts.len() - 2])
                .ok_or(RleError::RunOutOfRange {
                    index: counts.len(),
                })?;
        }
        counts.push(x);
    }
    counts
        .into_iter()
        .map(|c| u64::try_from(c).map_err(|_| RleError::NegativeRun(c)))
        .collect()
}

/// Encodes a mask as COCO RLE with list counts (used by tests and by `mesa demo`).
pub fn encode_counts(width: usize, height: usize, row_major: &[bool]) -> Value {
    let mut counts = Vec::new();
    let mut current = false;
    let mut run = 0u64;
    for col in 0..width {
        for row in 0..height {
            let v = row_major[row * width + col];
            if v != current {
                counts.push(run);
                run = 0;
                current = v;
            }
            run += 1;
        }
    }
    counts.push(run);
    serde_json::json!({"size": [height, width], "counts": counts})
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn list_counts_are_column_major() {
        // 2×3 (h=2, w=3): pixels (row 0, col 1) and (row 1, col 1) and (row 1, col 2).
        let mask =
            decode(&serde_json::json!({"size": [2, 3], "counts": [2, 2, 1, 1]})).expect("decode");
        assert_eq!(mask.pixels, vec![1, 4, 5]);
    }

    #[test]
    fn encode_then_decode_is_identity() {
        let (w, h) = (7, 5);
        let bits: Vec<bool> = (0..w * h).map(|i| (i * 7 + i / 3) % 5 < 2).collect();
        let mask = decode(&encode_counts(w, h, &bits)).expect("decode");
        let expected: Vec<u32> = (0..w * h).filter(|&i| bits[i]).map(|i| i as u32).collect();
        assert_eq!(mask.pixels, expected);
    }

    #[test]
    fn compressed_strings_decode_like_pycocotools() {
        // pycocotools.mask.encode of a 4×4 Fortran array with a 2×2 block at rows 1-2,
        // cols 1-2 gives counts [5, 2, 2, 2, 5], compressed as "52202" with the delta rule:
        // 5, 2, then 2-5=-3, 2-2=0, 5-2=3.
        let text = compress(&[5, 2, 2, 2, 5]);
        let mask = decode(&serde_json::json!({"size": [4, 4], "counts": text})).expect("decode");
        assert_eq!(mask.pixels, vec![5, 6, 9, 10]);
    }

    /// pycocotools' rleToString, for the test.
    fn compress(counts: &[i64]) -> String {
        let mut out = String::new();
        for i in 0..counts.len() {
            let mut x = counts[i];
            if i > 2 {
                x -= counts[i - 2];
            }
            let mut more = true;
            while more {
                let mut c = x & 0x1f;
                x >>= 5;
                more = if c & 0x10 != 0 { x != -1 } else { x != 0 };
                if more {
                    c |= 0x20;
                }
                out.push((c + 48) as u8 as char);
            }
        }
        out
    }

    /// The run lengths of `encode_counts`' list form.
    fn list_counts(value: &Value) -> Vec<i64> {
        value["counts"]
            .as_array()
            .expect("counts")
            .iter()
            .map(|c| c.as_i64().expect("integer"))
            .collect()
    }

    #[test]
    fn over_long_compressed_runs_are_errors_not_panics() {
        // Thirteen groups with the continuation bit: a shift past 64 bits in the old decoder
        // (a panic in debug builds, a silent wrap in release).
        let text = "o".repeat(12) + "0";
        let e = decode(&serde_json::json!({"size": [4, 4], "counts": text})).expect_err("error");
        assert_eq!(e, RleError::RunOutOfRange { index: 0 });
        assert!(
            e.to_string().starts_with("counts: run 0 is out of range"),
            "{e}"
        );
        // A run of 2^59 - 1 repeated: the delta rule's running sum leaves i64.
        let big = compress(&[0, 1, (1 << 59) - 1]);
        let mut text = big.clone();
        for _ in 0..40 {
            text.push_str(&big[big.len() - 12..]);
        }
        let e = decode(&serde_json::json!({"size": [4, 4], "counts": text})).expect_err("error");
        assert!(matches!(e, RleError::RunOutOfRange { .. }), "{e}");
        // A size whose product overflows.
        let e =
            decode(&serde_json::json!({"size": [u64::MAX, 3], "counts": [0]})).expect_err("error");
        assert!(matches!(e, RleError::SizeTooLarge { .. }), "{e}");
    }

    proptest! {
        /// Any counts string is decoded or refused with an error, never a panic.
        #[test]
        fn any_counts_string_decodes_or_errors(
            text in "[\\x00-\\x7f]{0,80}",
            height in 0u64..40,
            width in 0u64..40,
        ) {
            let value = serde_json::json!({"size": [height, width], "counts": text});
            if let Ok(mask) = decode(&value) {
                prop_assert!(mask.pixels.iter().all(|&p| (p as u64) < height * width));
            }
        }

        /// Counts strings made of pycocotools' alphabet reach the deeper checks, never a panic.
        #[test]
        fn any_pycocotools_alphabet_string_decodes_or_errors(text in "[0-o]{0,120}") {
            let _ = decode(&serde_json::json!({"size": [9, 9], "counts": text}));
        }

        /// encode → compress → decode gives back the mask.
        #[test]
        fn compressed_round_trip(
            (width, height, bits) in (1usize..24, 1usize..24).prop_flat_map(|(w, h)| {
                (
                    Just(w),
                    Just(h),
                    prop::collection::vec(any::<bool>(), w * h),
                )
            })
        ) {
            let text = compress(&list_counts(&encode_counts(width, height, &bits)));
            let mask = decode(&serde_json::json!({"size": [height, width], "counts": text}))
                .expect("decode");
            let expected: Vec<u32> = (0..width * height)
                .filter(|&i| bits[i])
                .map(|i| i as u32)
                .collect();
            prop_assert_eq!(mask.pixels, expected);
        }
    }

    #[test]
    fn wrong_totals_are_errors() {
        assert!(decode(&serde_json::json!({"size": [2, 2], "counts": [1, 1]})).is_err());
    }
}

//! COCO run-length masks (`{"size": [h, w], "counts": [...] | "..."}`), as pycocotools
//! encodes them: runs alternate 0s and 1s starting with 0s, in **column-major** order; the
//! string form packs each count in 5-bit groups offset by 48, with counts after the second
//! stored as differences from the count two before.

use serde_json::Value;

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

/// Decodes a COCO RLE object.
pub fn decode(value: &Value) -> Result<RleMask, String> {
    let size = value
        .get("size")
        .and_then(Value::as_array)
        .filter(|s| s.len() == 2)
        .ok_or("size is missing or not [height, width]")?;
    let dim = |v: &Value| {
        v.as_u64()
            .map(|x| x as usize)
            .ok_or("size must be two integers")
    };
    let (height, width) = (dim(&size[0])?, dim(&size[1])?);
    let counts: Vec<u64> = match value.get("counts") {
        Some(Value::Array(list)) => list
            .iter()
            .map(|c| c.as_u64().ok_or("counts must be non-negative integers"))
            .collect::<Result<_, _>>()?,
        Some(Value::String(text)) => decode_string(text)?,
        _ => return Err("counts is missing (a list of run lengths or a compressed string)".into()),
    };
    let total: u64 = counts.iter().sum();
    if total != (width * height) as u64 {
        return Err(format!(
            "the runs cover {total} pixels but size [{height}, {width}] has {}",
            width * height
        ));
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

fn decode_string(text: &str) -> Result<Vec<u64>, String> {
    let bytes = text.as_bytes();
    let mut counts: Vec<i64> = Vec::new();
    let mut p = 0;
    while p < bytes.len() {
        let mut x: i64 = 0;
        let mut k = 0;
        loop {
            let c = i64::from(bytes[p]) - 48;
            if !(0..64).contains(&c) {
                return Err(format!(
                    "invalid character {:?} in counts",
                    bytes[p] as char
                ));
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
                return Err("counts ends in the middle of a number".into());
            }
        }
        if counts.len() > 2 {
            x += counts[counts.len() - 2];
        }
        counts.push(x);
    }
    counts
        .into_iter()
        .map(|c| u64::try_from(c).map_err(|_| format!("negative run length {c}")))
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

    #[test]
    fn wrong_totals_are_errors() {
        assert!(decode(&serde_json::json!({"size": [2, 2], "counts": [1, 1]})).is_err());
    }
}

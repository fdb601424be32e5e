//! NumPy `.npy` files of 2-D float16 / float32 arrays (what `numpy.save` writes for SBERT
//! embeddings), read into f32 (float16 converts exactly).

use std::path::Path;

/// A 2-D float array, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Matrix {
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// `rows × cols` values, row after row.
    pub data: Vec<f32>,
}

/// Reads a `.npy` file; errors say what is wrong and what is expected.
pub fn read_matrix(path: &Path) -> Result<Matrix, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read: {e}"))?;
    parse_matrix(&bytes)
}

/// Parses the bytes of a `.npy` file holding a 2-D `<f2`/`<f4` array in C order (a 1-D array
/// is one row).
pub fn parse_matrix(bytes: &[u8]) -> Result<Matrix, String> {
    const EXPECTED: &str = "a .npy file of a 2-D float16 or float32 array, as numpy.save writes";
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(format!("not a .npy file (expected {EXPECTED})"));
    }
    let (header_len, header_start) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => {
            return Err(format!(
                "unsupported .npy version {v} (expected {EXPECTED})"
            ))
        }
    };
    let header = bytes
        .get(header_start..header_start + header_len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| format!("truncated or non-text header (expected {EXPECTED})"))?;
    let field = |key: &str| -> Result<&str, String> {
        let at = header
            .find(&format!("'{key}'"))
            .ok_or_else(|| format!("the header has no '{key}' (expected {EXPECTED})"))?;
        let rest = &header[at + key.len() + 2..];
        let rest = rest
            .trim_start()
            .strip_prefix(':')
            .unwrap_or(rest)
            .trim_start();
        Ok(rest)
    };
    let descr = field("descr")?;
    let descr = descr
        .strip_prefix('\'')
        .and_then(|d| d.split('\'').next())
        .ok_or_else(|| format!("unreadable descr (expected {EXPECTED})"))?;
    let width = match descr {
        "<f2" | "|f2" => 2,
        "<f4" => 4,
        other => {
            return Err(format!(
                "dtype {other} (expected float16 '<f2' or float32 '<f4', little-endian; convert \
                 with array.astype('float32'))"
            ))
        }
    };
    if field("fortran_order")?.starts_with("True") {
        return Err(
            "fortran_order is True (expected C order: save numpy.ascontiguousarray(array))"
                .to_owned(),
        );
    }
    let shape = field("shape")?;
    let shape = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| format!("unreadable shape (expected {EXPECTED})"))?;
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("unreadable shape ({shape}) (expected {EXPECTED})"))?;
    let (rows, cols) = match dims.as_slice() {
        [n] => (1, *n),
        [r, c] => (*r, *c),
        _ => {
            return Err(format!(
                "the array has {} dimensions (expected 2: one row per item)",
                dims.len()
            ))
        }
    };
    let count = rows
        .checked_mul(cols)
        .ok_or_else(|| format!("shape ({rows}, {cols}) is too large"))?;
    let data_start = header_start + header_len;
    let body = &bytes[data_start.min(bytes.len())..];
    if body.len() != count * width {
        return Err(format!(
            "the data has {} bytes, the shape ({rows}, {cols}) of {descr} needs {} (the file is \
             truncated or damaged)",
            body.len(),
            count * width
        ));
    }
    let data = if width == 2 {
        body.chunks_exact(2)
            .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
            .collect()
    } else {
        body.chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect()
    };
    Ok(Matrix { rows, cols, data })
}

/// The bytes of a `.npy` file of a 2-D array (float32, or float16 when `half` is set), as
/// `numpy.save` writes them.
pub fn write_matrix(matrix: &Matrix, half: bool) -> Vec<u8> {
    let descr = if half { "<f2" } else { "<f4" };
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}, {}), }}",
        matrix.rows, matrix.cols
    );
    // Magic (6) + version (2) + length (2) + header + '\n', padded to 64 bytes.
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + matrix.data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in &matrix.data {
        if half {
            out.extend_from_slice(&half::f16::from_f32(*v).to_le_bytes());
        } else {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn float32_and_float16_round_trip() {
        let m = Matrix {
            rows: 2,
            cols: 3,
            data: vec![1.0, -2.5, 0.25, 3.0, 0.0, -0.125],
        };
        assert_eq!(parse_matrix(&write_matrix(&m, false)), Ok(m.clone()));
        // These values are exact in float16.
        assert_eq!(parse_matrix(&write_matrix(&m, true)), Ok(m));
    }

    #[test]
    fn numpys_own_header_is_read() {
        // numpy.save(np.zeros((2, 2), dtype=np.float32)) with its exact header.
        let mut bytes = b"\x93NUMPY\x01\x00v\x00".to_vec();
        let mut header = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 2), }".to_owned();
        while header.len() < 117 {
            header.push(' ');
        }
        header.push('\n');
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&[0u8; 16]);
        let m = parse_matrix(&bytes).expect("reads");
        assert_eq!((m.rows, m.cols), (2, 2));
    }

    #[test]
    fn bad_files_say_what_is_expected() {
        assert!(parse_matrix(b"PK\x03\x04")
            .expect_err("an error")
            .starts_with("not a .npy file"));
        let m = Matrix {
            rows: 1,
            cols: 2,
            data: vec![1.0, 2.0],
        };
        let mut bytes = write_matrix(&m, false);
        bytes.pop();
        assert!(parse_matrix(&bytes)
            .expect_err("an error")
            .contains("truncated"));
        let mut f8 = write_matrix(&m, false);
        let at = f8.windows(3).position(|w| w == b"<f4").expect("descr");
        f8[at + 2] = b'8';
        let e = parse_matrix(&f8).expect_err("an error");
        assert!(e.starts_with("dtype <f8 (expected float16"), "{e}");
    }
}

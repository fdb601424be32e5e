//! NumPy `.npy` files of 2-D float16 / float32 arrays (what `numpy.save` writes for SBERT
//! embeddings), read into f32 (float16 converts exactly).
//!
//! Parsed by hand although the workspace depends on `ndarray-npy` (which reads depth maps in
//! [`crate::lift::inputs`]): ndarray-npy 0.9 has no float16 element type (its readable
//! elements are the integers, `f32`, `f64`, `bool` and complex numbers), and float16 is how
//! large feature matrices are shipped (12,000 × 768 features are 18 MB instead of 37 MB).
//! Parsing the bytes here also compares the header's shape with the length of the data before
//! allocating, where ndarray-npy allocates what the header asks for first.

use std::path::{Path, PathBuf};

/// What every error says is expected.
const EXPECTED: &str = "a .npy file of a 2-D float16 or float32 array, as numpy.save writes";

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

/// Why a `.npy` file cannot be read; the text says what is wrong and what is expected (the
/// caller names the file).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum NpyError {
    /// The file cannot be read.
    #[error("cannot read: {message}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        message: String,
    },
    /// The magic string is missing.
    #[error("not a .npy file (expected {EXPECTED})")]
    NotNpy,
    /// A format version other than 1, 2 or 3.
    #[error("unsupported .npy version {0} (expected {EXPECTED})")]
    Version(u8),
    /// The header is cut or not text.
    #[error("truncated or non-text header (expected {EXPECTED})")]
    Header,
    /// The header dictionary lacks a key.
    #[error("the header has no '{0}' (expected {EXPECTED})")]
    MissingKey(String),
    /// `descr` is not a quoted string.
    #[error("unreadable descr (expected {EXPECTED})")]
    Descr,
    /// A dtype other than little-endian float16 or float32.
    #[error(
        "dtype {0} (expected float16 '<f2' or float32 '<f4', little-endian; convert with \
         array.astype('float32'))"
    )]
    Dtype(String),
    /// The array is stored column-major.
    #[error("fortran_order is True (expected C order: save numpy.ascontiguousarray(array))")]
    FortranOrder,
    /// `shape` is not a parenthesised tuple.
    #[error("unreadable shape (expected {EXPECTED})")]
    Shape,
    /// `shape` holds something other than integers.
    #[error("unreadable shape ({0}) (expected {EXPECTED})")]
    ShapeText(String),
    /// Not a 1-D or 2-D array.
    #[error("the array has {0} dimensions (expected 2: one row per item)")]
    Dimensions(usize),
    /// The shape's size overflows.
    #[error("shape ({rows}, {cols}) is too large")]
    TooLarge {
        /// Rows of the header's shape.
        rows: usize,
        /// Columns of the header's shape.
        cols: usize,
    },
    /// The data is not as long as the shape says.
    #[error(
        "the data has {bytes} bytes, the shape ({rows}, {cols}) of {descr} needs {needed} (the \
         file is truncated or damaged)"
    )]
    Length {
        /// Bytes after the header.
        bytes: usize,
        /// Rows of the header's shape.
        rows: usize,
        /// Columns of the header's shape.
        cols: usize,
        /// The dtype.
        descr: String,
        /// Bytes the shape needs.
        needed: usize,
    },
}

/// Reads a `.npy` file; errors say what is wrong and what is expected.
pub fn read_matrix(path: &Path) -> Result<Matrix, NpyError> {
    let bytes = std::fs::read(path).map_err(|e| NpyError::Read {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    parse_matrix(&bytes)
}

/// Parses the bytes of a `.npy` file holding a 2-D `<f2`/`<f4` array in C order (a 1-D array
/// is one row).
pub fn parse_matrix(bytes: &[u8]) -> Result<Matrix, NpyError> {
    let (rows, cols, width, body) = parse_body(bytes, false)?;
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

/// Parses the bytes of a `.npy` file holding a 2-D `<f2`, `<f4` or `<f8` array in C order into
/// f64 values (what `mesa eval` reads feature files with): `(rows, cols, values)`.
pub fn parse_matrix_f64(bytes: &[u8]) -> Result<(usize, usize, Vec<f64>), NpyError> {
    let (rows, cols, width, body) = parse_body(bytes, true)?;
    let data = match width {
        2 => body
            .chunks_exact(2)
            .map(|b| f64::from(half::f16::from_le_bytes([b[0], b[1]]).to_f32()))
            .collect(),
        4 => body
            .chunks_exact(4)
            .map(|b| f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])))
            .collect(),
        _ => body
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
            .collect(),
    };
    Ok((rows, cols, data))
}

/// The shape, element width and data bytes of a `.npy` file (float64 accepted when `wide`).
fn parse_body(bytes: &[u8], wide: bool) -> Result<(usize, usize, usize, &[u8]), NpyError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(NpyError::NotNpy);
    }
    let (header_len, header_start) = match bytes[6] {
        1 => (usize::from(u16::from_le_bytes([bytes[8], bytes[9]])), 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(NpyError::Version(v)),
    };
    let header = bytes
        .get(header_start..header_start + header_len)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or(NpyError::Header)?;
    let field = |key: &str| -> Result<&str, NpyError> {
        let at = header
            .find(&format!("'{key}'"))
            .ok_or_else(|| NpyError::MissingKey(key.to_owned()))?;
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
        .ok_or(NpyError::Descr)?;
    let width = match descr {
        "<f2" | "|f2" => 2,
        "<f4" => 4,
        "<f8" if wide => 8,
        other => return Err(NpyError::Dtype(other.to_owned())),
    };
    if field("fortran_order")?.starts_with("True") {
        return Err(NpyError::FortranOrder);
    }
    let shape = field("shape")?;
    let shape = shape
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or(NpyError::Shape)?;
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| NpyError::ShapeText(shape.to_owned()))?;
    let (rows, cols) = match dims.as_slice() {
        [n] => (1, *n),
        [r, c] => (*r, *c),
        _ => return Err(NpyError::Dimensions(dims.len())),
    };
    let needed = rows
        .checked_mul(cols)
        .and_then(|count| count.checked_mul(width))
        .ok_or(NpyError::TooLarge { rows, cols })?;
    let data_start = header_start + header_len;
    let body = &bytes[data_start.min(bytes.len())..];
    if body.len() != needed {
        return Err(NpyError::Length {
            bytes: body.len(),
            rows,
            cols,
            descr: descr.to_owned(),
            needed,
        });
    }
    Ok((rows, cols, width, body))
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
    use proptest::prelude::*;

    proptest! {
        /// Damaged files are read or refused, never a panic.
        #[test]
        fn damaged_files_are_read_or_refused(
            flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..6),
            keep in 0.0f64..=1.0,
        ) {
            let m = Matrix { rows: 3, cols: 4, data: (0..12).map(|i| i as f32).collect() };
            let mut bytes = write_matrix(&m, false);
            for (at, value) in flips {
                let i = at.index(bytes.len());
                bytes[i] = value;
            }
            bytes.truncate(((bytes.len() as f64) * keep).round() as usize);
            if let Ok(read) = parse_matrix(&bytes) {
                prop_assert_eq!(read.data.len(), read.rows * read.cols);
            }
        }
    }

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
    fn a_shape_whose_byte_length_overflows_is_refused() {
        // 2^62 float32 values: the count fits a usize, its bytes do not (a panic in debug
        // builds before the check covered the bytes).
        let mut bytes = b"\x93NUMPY\x01\x00v\x00".to_vec();
        let mut header =
            "{'descr': '<f4', 'fortran_order': False, 'shape': (4611686018427387904, 1), }"
                .to_owned();
        while header.len() < 117 {
            header.push(' ');
        }
        header.push('\n');
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(&[0u8; 16]);
        let e = parse_matrix(&bytes).expect_err("an error");
        assert_eq!(
            e,
            NpyError::TooLarge {
                rows: 1 << 62,
                cols: 1
            }
        );
    }

    #[test]
    fn bad_files_say_what_is_expected() {
        assert!(parse_matrix(b"PK\x03\x04")
            .expect_err("an error")
            .to_string()
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
            .to_string()
            .contains("truncated"));
        let mut f8 = write_matrix(&m, false);
        let at = f8.windows(3).position(|w| w == b"<f4").expect("descr");
        f8[at + 2] = b'8';
        let e = parse_matrix(&f8).expect_err("an error").to_string();
        assert!(e.starts_with("dtype <f8 (expected float16"), "{e}");
    }
}

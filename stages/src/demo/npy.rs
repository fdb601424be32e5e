//! Writing NumPy `.npy` files (format version 1.0) of little-endian float32 matrices, as
//! `numpy.save` does for a C-ordered `float32` array.

/// The bytes of a `.npy` file holding a `rows × columns` float32 matrix (row-major values).
pub(crate) fn npy_f32(rows: usize, columns: usize, values: &[f32]) -> Vec<u8> {
    debug_assert_eq!(values.len(), rows * columns);
    let mut header =
        format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {columns}), }}");
    // Magic (6) + version (2) + header length (2) + header, padded with spaces and ended by a
    // newline to a multiple of 64 bytes.
    let unpadded = 10 + header.len() + 1;
    let padding = (64 - unpadded % 64) % 64;
    header.push_str(&" ".repeat(padding));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + values.len() * 4);
    out.extend_from_slice(b"\x93NUMPY");
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_is_aligned_and_describes_the_array() {
        let bytes = npy_f32(2, 3, &[1.0, 2.0, 3.0, 4.0, 5.0, f32::NAN]);
        assert_eq!(&bytes[..6], b"\x93NUMPY");
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        assert_eq!((10 + header_len) % 64, 0);
        let header = std::str::from_utf8(&bytes[10..10 + header_len]).expect("ascii");
        assert!(
            header.contains("'shape': (2, 3)")
                && header.contains("'<f4'")
                && header.ends_with('\n')
        );
        assert_eq!(bytes.len(), 10 + header_len + 24);
        let first = f32::from_le_bytes(
            bytes[10 + header_len..14 + header_len]
                .try_into()
                .expect("4"),
        );
        assert_eq!(first, 1.0);
    }
}

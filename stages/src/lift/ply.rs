//! Binary little-endian PLY point clouds (xyz float32 + rgb uchar), as Open3D and trimesh read
//! them.

/// A point with its colour: xyz in metres, rgb.
pub type ColoredPoint = ([f32; 3], [u8; 3]);

/// Writes points with colours as a binary little-endian PLY.
pub fn write_ply(points: &[ColoredPoint], comment: &str) -> Vec<u8> {
    let mut ply = PlyWriter::new(points.len(), comment);
    for &(xyz, rgb) in points {
        ply.push(xyz, rgb);
    }
    ply.finish()
}

/// A PLY as [`write_ply`] writes it, written point by point as they are made (no list of
/// points in between): the header, with the count given up front, then 15 bytes a point.
pub struct PlyWriter {
    out: Vec<u8>,
    count: usize,
    header_len: usize,
}

impl PlyWriter {
    /// A PLY of `count` points (exactly that many must be pushed) and the comment line
    /// `comment` (line breaks made spaces).
    pub fn new(count: usize, comment: &str) -> Self {
        let header = format!(
            "ply\nformat binary_little_endian 1.0\ncomment {}\nelement vertex {}\n\
             property float x\nproperty float y\nproperty float z\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
            comment.replace('\n', " "),
            count
        );
        let mut out = Vec::with_capacity(header.len() + count * 15);
        out.extend_from_slice(header.as_bytes());
        Self {
            out,
            count,
            header_len: header.len(),
        }
    }

    /// Appends a point: x, y, z as little-endian `f32`, then red, green, blue.
    #[inline]
    pub fn push(&mut self, xyz: [f32; 3], rgb: [u8; 3]) {
        let mut point = [0u8; 15];
        for (bytes, c) in point.chunks_exact_mut(4).zip(xyz) {
            bytes.copy_from_slice(&c.to_le_bytes());
        }
        point[12..].copy_from_slice(&rgb);
        self.out.extend_from_slice(&point);
    }

    /// The file's bytes.
    ///
    /// # Panics
    /// When the number of points pushed is not the count of [`Self::new`] (the header would
    /// not describe the data).
    pub fn finish(self) -> Vec<u8> {
        let pushed = (self.out.len() - self.header_len) / 15;
        assert_eq!(
            pushed, self.count,
            "a PLY's header promised {} points",
            self.count
        );
        self.out
    }
}

/// Why bytes are not a PLY as [`write_ply`] writes it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PlyError {
    /// No `end_header` line.
    #[error("no end_header")]
    NoEndHeader,
    /// The header is not UTF-8.
    #[error("{0}")]
    HeaderText(String),
    /// No `element vertex N` line.
    #[error("no vertex element")]
    NoVertexElement,
    /// The vertex count is not a number.
    #[error("vertex count: {0}")]
    VertexCount(String),
    /// The data is not 15 bytes per vertex.
    #[error("{bytes} bytes of vertex data for {count} vertices")]
    Length {
        /// Bytes after the header.
        bytes: usize,
        /// The header's vertex count.
        count: usize,
    },
}

/// Reads back what [`write_ply`] writes (for tests and tools).
pub fn read_ply(bytes: &[u8]) -> Result<Vec<ColoredPoint>, PlyError> {
    let end = b"end_header\n";
    let at = bytes
        .windows(end.len())
        .position(|w| w == end)
        .ok_or(PlyError::NoEndHeader)?;
    let header =
        std::str::from_utf8(&bytes[..at]).map_err(|e| PlyError::HeaderText(e.to_string()))?;
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .ok_or(PlyError::NoVertexElement)?
        .trim()
        .parse()
        .map_err(|e: std::num::ParseIntError| PlyError::VertexCount(e.to_string()))?;
    let body = &bytes[at + end.len()..];
    // A count whose byte length overflows is as wrong as any other mismatch.
    if count.checked_mul(15) != Some(body.len()) {
        return Err(PlyError::Length {
            bytes: body.len(),
            count,
        });
    }
    Ok(body
        .chunks_exact(15)
        .map(|c| {
            let f = |i: usize| f32::from_le_bytes([c[i], c[i + 1], c[i + 2], c[i + 3]]);
            ([f(0), f(4), f(8)], [c[12], c[13], c[14]])
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip() {
        let points = vec![
            ([1.0, -2.5, 0.125], [1, 2, 3]),
            ([0.0, 0.0, 0.0], [255, 0, 9]),
        ];
        let bytes = write_ply(&points, "test");
        assert_eq!(read_ply(&bytes).expect("read"), points);
        // The bytes themselves: the header, then each point's 15 bytes.
        let header = "ply\nformat binary_little_endian 1.0\ncomment test\nelement vertex 2\n\
                      property float x\nproperty float y\nproperty float z\n\
                      property uchar red\nproperty uchar green\nproperty uchar blue\n\
                      end_header\n";
        let mut expected = header.as_bytes().to_vec();
        for (xyz, rgb) in &points {
            for c in xyz {
                expected.extend_from_slice(&c.to_le_bytes());
            }
            expected.extend_from_slice(rgb);
        }
        assert_eq!(bytes, expected);
    }

    #[test]
    #[should_panic(expected = "promised 2 points")]
    fn a_writer_given_fewer_points_than_promised_panics() {
        let mut ply = PlyWriter::new(2, "short");
        ply.push([0.0; 3], [0; 3]);
        let _ = ply.finish();
    }
}

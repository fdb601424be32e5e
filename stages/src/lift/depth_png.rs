//! A depth map's PNG (16-bit grayscale, not interlaced) decoded straight into metres, row by
//! row.
//!
//! The `png` crate still does the format's work: its [`png::StreamingDecoder`] parses the
//! chunks, checks their CRCs and inflates the image data. What is written here is only what
//! comes after: undoing each row's filter and turning its big-endian 16-bit values into metres.
//! Two reasons for doing that by hand:
//!
//! - Speed. `png` unfilters Paeth rows of 2-byte pixels at about 14 cycles a pixel on the
//!   machines of `docs/performance.md`: it packs a pixel's two bytes into one vector register,
//!   so each pixel's result waits on an unpack, a pack and a round trip through the stack
//!   before the next pixel can start. With the two bytes' chains kept in general registers
//!   (below), a pixel costs about half as much; a synthetic 1024² depth map, a third of whose
//!   rows are Paeth-filtered, unfilters in 1.25 ms instead of 1.95 ms.
//! - No images in between. Through `image`, a depth map was decoded into a zeroed byte buffer,
//!   copied into a `u16` image, then converted into metres: three full-size buffers where
//!   this keeps one row.
//!
//! Any other PNG (another colour type or bit depth, interlaced, with a `tRNS` chunk, which
//! `image` turns into an alpha channel), or another format under the name, is left to the
//! general reader ([`super::inputs`]),
//! which decodes it, or names what it is when it is not a depth map. The result is the general
//! reader's to the bit (`tests`: every filter type, odd widths, image data split over many
//! chunks, the real depth maps of `../shared/realdata`).

use std::fs::File;
use std::io::{BufRead, BufReader, ErrorKind};
use std::path::Path;

use png::{chunk, BitDepth, ColorType, Decoded, DecodingError, StreamingDecoder, UnfilterRegion};

use super::inputs::{extend_valid_metres, image_error, too_many_pixels};
use super::LiftError;

/// A depth map read from a PNG: row-major metres (NaN where there is no measurement) and how
/// many are measurements.
pub(super) struct DepthPng {
    pub width: usize,
    pub height: usize,
    pub metres: Vec<f32>,
    pub valid: usize,
}

/// Reads `path` when it is a non-interlaced 16-bit grayscale PNG without transparency, at
/// `scale` metres a unit, refusing it on its header when it has more than `max_pixels` pixels.
/// `Ok(None)`: another kind of PNG, for the general reader.
pub(super) fn read_depth_png(
    path: &Path,
    max_pixels: u64,
    scale: f32,
) -> Result<Option<DepthPng>, LiftError> {
    let file = File::open(path)
        .map_err(|e| LiftError::input(path, "$", format!("cannot open: {e}"), "check the path"))?;
    let mut reader = Reader {
        file: BufReader::with_capacity(64 * 1024, file),
        decoder: StreamingDecoder::new(),
    };
    let decode_error = |e: DecodingError| image_error(path, e);
    // Another format under a .png name (`image` guesses formats from their first bytes): the
    // general reader's, which names what it is.
    let start = reader.file.fill_buf().map_err(|e| image_error(path, e))?;
    if !start.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Ok(None);
    }
    while reader.decoder.info().is_none() {
        reader.next(None).map_err(decode_error)?;
    }
    let info = reader.decoder.info().expect("the header was read");
    let (width, height) = (info.width, info.height);
    if u64::from(width) * u64::from(height) > max_pixels {
        return Err(too_many_pixels(path, width, height, max_pixels));
    }
    if (info.color_type, info.bit_depth, info.interlaced)
        != (ColorType::Grayscale, BitDepth::Sixteen, false)
    {
        return Ok(None);
    }
    // The chunks before the image data (a tRNS among them) are read before it is looked at.
    loop {
        match reader.next(None).map_err(decode_error)? {
            Decoded::ChunkBegin(_, chunk::IDAT) => break,
            Decoded::ChunkComplete(chunk::IEND) => {
                return Err(image_error(path, "the file has no image data (IDAT)"))
            }
            _ => {}
        }
    }
    if reader
        .decoder
        .info()
        .is_some_and(|info| info.trns.is_some())
    {
        return Ok(None);
    }
    let (width, height) = (width as usize, height as usize);
    let stride = 2 * width;
    // Each row is its filter type and its bytes; the inflated rows are kept whole (the
    // inflater looks back into them), each unfiltered into `row` against `previous`.
    let row_len = stride + 1;
    let mut filtered = vec![0u8; height * row_len];
    let mut region = UnfilterRegion {
        available: 0,
        filled: 0,
    };
    let (mut previous, mut row) = (vec![0u8; stride], vec![0u8; stride]);
    let mut metres = Vec::with_capacity(width * height);
    let mut valid = 0;
    let mut flushed = false;
    for v in 0..height {
        let end = (v + 1) * row_len;
        while region.filled < end {
            if flushed {
                return Err(image_error(
                    path,
                    format!("the image data ends after {v} of its {height} rows"),
                ));
            }
            let decoded = reader
                .next(Some(&mut region.as_buf(&mut filtered)))
                .map_err(decode_error)?;
            flushed = matches!(decoded, Decoded::ImageDataFlushed);
        }
        let line = &filtered[end - row_len..end];
        row.copy_from_slice(&line[1..]);
        if !unfilter(line[0], &previous, &mut row) {
            return Err(image_error(
                path,
                format!(
                    "row {v} has filter type {}, which PNG does not define (0 to 4)",
                    line[0]
                ),
            ));
        }
        valid += extend_valid_metres(&row, scale, &mut metres);
        std::mem::swap(&mut previous, &mut row);
    }
    // The rest of the image data, so that its last chunk's CRC is checked as `png` checks it.
    while !flushed {
        flushed = matches!(
            reader.next(None).map_err(decode_error)?,
            Decoded::ImageDataFlushed
        );
    }
    Ok(Some(DepthPng {
        width,
        height,
        metres,
        valid,
    }))
}

/// The file and the decoder that reads it, as `png`'s own reader drives its decoder.
struct Reader {
    file: BufReader<File>,
    decoder: StreamingDecoder,
}

impl Reader {
    /// Feeds the decoder the buffered bytes until it has something to say.
    fn next(&mut self, image: Option<&mut png::UnfilterBuf<'_>>) -> Result<Decoded, DecodingError> {
        let buffered = self.file.fill_buf()?;
        if buffered.is_empty() {
            return Err(DecodingError::IoError(ErrorKind::UnexpectedEof.into()));
        }
        let (consumed, decoded) = self.decoder.update(buffered, image)?;
        self.file.consume(consumed);
        Ok(decoded)
    }
}

/// Undoes `filter` on a row of 2-byte pixels, `previous` the row above unfiltered (zeros for
/// the first row). `false` for a filter type PNG does not define.
///
/// Each byte of a pixel is predicted from the same byte of the pixel before it, so a row is
/// two independent chains of bytes; they are walked together, each in its own variable,
/// which the compiler keeps in general registers.
fn unfilter(filter: u8, previous: &[u8], row: &mut [u8]) -> bool {
    let pixels = row.chunks_exact_mut(2).zip(previous.chunks_exact(2));
    match filter {
        0 => {}
        // Sub: the byte to the left.
        1 => {
            let (mut a0, mut a1) = (0u8, 0u8);
            for (x, _) in pixels {
                a0 = x[0].wrapping_add(a0);
                a1 = x[1].wrapping_add(a1);
                (x[0], x[1]) = (a0, a1);
            }
        }
        // Up: the byte above.
        2 => {
            for (x, b) in row.iter_mut().zip(previous) {
                *x = x.wrapping_add(*b);
            }
        }
        // Average of the two, rounded down.
        3 => {
            let (mut a0, mut a1) = (0u16, 0u16);
            for (x, b) in pixels {
                a0 = u16::from(x[0].wrapping_add(((a0 + u16::from(b[0])) / 2) as u8));
                a1 = u16::from(x[1].wrapping_add(((a1 + u16::from(b[1])) / 2) as u8));
                (x[0], x[1]) = (a0 as u8, a1 as u8);
            }
        }
        // Paeth.
        4 => {
            let (mut a0, mut a1, mut c0, mut c1) = (0i32, 0i32, 0i32, 0i32);
            for (x, b) in pixels {
                let (b0, b1) = (i32::from(b[0]), i32::from(b[1]));
                a0 = (i32::from(x[0]) + paeth(a0, b0, c0)) & 0xff;
                a1 = (i32::from(x[1]) + paeth(a1, b1, c1)) & 0xff;
                (x[0], x[1]) = (a0 as u8, a1 as u8);
                (c0, c1) = (b0, b1);
            }
        }
        _ => return false,
    }
    true
}

/// The Paeth predictor of a byte from the bytes to its left (`a`), above (`b`) and above left
/// (`c`): whichever of the three is nearest to `a + b − c`, ties to `a`, then `b`. Written as
/// stb_image writes it (`png` too): two comparisons against one threshold, no absolute values.
#[inline(always)]
fn paeth(a: i32, b: i32, c: i32) -> i32 {
    let threshold = 3 * c - (a + b);
    let (lo, hi) = (a.min(b), a.max(b));
    let nearer = if hi <= threshold { lo } else { c };
    if threshold <= lo {
        hi
    } else {
        nearer
    }
}

#[cfg(test)]
mod tests {
    use super::super::inputs::{read_png, valid_metres, PngLimit};
    use super::*;
    use crate::image_io::inflated_image_data;
    use png::Filter;
    use rand::{Rng, SeedableRng};
    use std::path::PathBuf;

    const SCALE: f32 = 0.001;

    /// The predictor as the PNG specification writes it.
    fn paeth_reference(a: i32, b: i32, c: i32) -> i32 {
        let p = a + b - c;
        let (pa, pb, pc) = ((p - a).abs(), (p - b).abs(), (p - c).abs());
        if pa <= pb && pa <= pc {
            a
        } else if pb <= pc {
            b
        } else {
            c
        }
    }

    #[test]
    fn the_paeth_predictor_is_the_specification_s_for_every_byte_triple() {
        let mut differ = 0;
        for a in 0..256 {
            for b in 0..256 {
                for c in 0..256 {
                    assert_eq!(paeth(a, b, c), paeth_reference(a, b, c), "{a} {b} {c}");
                    // Control: the predictor is not one of its inputs throughout.
                    differ += usize::from(paeth(a, b, c) != a);
                }
            }
        }
        assert!(differ > 1 << 22, "{differ}");
    }

    /// A 16-bit grayscale PNG of `values`, every row filtered with `filter`, its image data in
    /// IDAT chunks of at most `chunk` bytes.
    fn encode(
        (width, height): (u32, u32),
        values: &[u16],
        filter: Filter,
        chunk: usize,
        trns: bool,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(ColorType::Grayscale);
        encoder.set_depth(BitDepth::Sixteen);
        encoder.set_filter(filter);
        if trns {
            encoder.set_trns(vec![0u8, 0]);
        }
        let mut writer = encoder.write_header().expect("header");
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
        let mut stream = writer.stream_writer_with_size(chunk).expect("stream");
        std::io::Write::write_all(&mut stream, &bytes).expect("data");
        stream.finish().expect("finish");
        writer.finish().expect("end");
        out
    }

    /// A depth map as read: width, height, the metres' bits, how many are valid.
    type Read = (usize, usize, Vec<u32>, usize);

    /// The general reader's values: `image`'s decoding, then [`valid_metres`].
    fn through_image(path: &Path) -> Result<Read, LiftError> {
        let image = read_png(path, PngLimit::MaxPixels(u64::MAX))?;
        let image = image.as_luma16().expect("16-bit grayscale");
        let (values, valid) = valid_metres(image.as_raw(), SCALE);
        let bits = values.iter().map(|v| v.to_bits()).collect();
        Ok((image.width() as usize, image.height() as usize, bits, valid))
    }

    /// [`read_depth_png`]'s values.
    fn through_rows(path: &Path) -> Result<Option<Read>, LiftError> {
        Ok(read_depth_png(path, u64::MAX, SCALE)?.map(|d| {
            let bits = d.metres.iter().map(|v| v.to_bits()).collect();
            (d.width, d.height, bits, d.valid)
        }))
    }

    /// Each row's filter type, from the file's inflated image data (a test of the files the
    /// tests write, independent of the readers compared).
    fn filter_types(file: &[u8], (width, height): (usize, usize)) -> Vec<u8> {
        let raw = inflated_image_data(file);
        (0..height).map(|v| raw[v * (2 * width + 1)]).collect()
    }

    fn values_of(pattern: usize, (width, height): (usize, usize), rng: &mut impl Rng) -> Vec<u16> {
        (0..width * height)
            .map(|p| {
                let (u, v) = (p % width, p / width);
                match pattern {
                    // Any value, zeros ("no measurement") among them.
                    0 => {
                        if rng.random_range(0..8) == 0 {
                            0
                        } else {
                            rng.random()
                        }
                    }
                    // A slanted table with noise and holes: what depth maps look like, and
                    // where Paeth's three neighbours differ.
                    1 => {
                        if rng.random_range(0..20) == 0 {
                            0
                        } else {
                            (600 + 3 * u + 7 * v) as u16 + rng.random_range(0..4)
                        }
                    }
                    // Large steps across byte boundaries (255 → 256 and back).
                    _ => (250 + ((u * 37 + v * 101) % 13) * 255) as u16,
                }
            })
            .collect()
    }

    #[test]
    fn every_filter_type_reads_as_the_general_reader_reads_it() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.png");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let filters = [
            (Filter::NoFilter, Some(0u8)),
            (Filter::Sub, Some(1)),
            (Filter::Up, Some(2)),
            (Filter::Avg, Some(3)),
            (Filter::Paeth, Some(4)),
            (Filter::Adaptive, None),
        ];
        let mut seen = [0usize; 5];
        let mut transformed = 0;
        let mut cases = 0;
        for (width, height) in [(1, 1), (1, 9), (9, 1), (2, 2), (7, 3), (33, 17), (257, 40)] {
            for pattern in 0..3 {
                let values = values_of(pattern, (width, height), &mut rng);
                for &(filter, expected) in &filters {
                    // Image data in one chunk, and split over chunks of 7 bytes.
                    for chunk in [1 << 20, 7] {
                        let size = (width as u32, height as u32);
                        let file = encode(size, &values, filter, chunk, false);
                        std::fs::write(&path, &file).expect("write");
                        let types = filter_types(&file, (width, height));
                        if let Some(expected) = expected {
                            // The encoder leaves the first row of a Up or Paeth image
                            // unchanged or filters it as it likes; the others are `expected`.
                            assert!(types[1..].iter().all(|&t| t == expected), "{types:?}");
                        }
                        for &t in &types {
                            seen[usize::from(t)] += 1;
                        }
                        let reference = through_image(&path).expect("image decodes");
                        let rows = through_rows(&path).expect("decodes").expect("16-bit gray");
                        assert_eq!(
                            rows, reference,
                            "{width}×{height}, pattern {pattern}, {filter:?}, chunks of {chunk}"
                        );
                        // Control: the filtered bytes are not the values, so rows left
                        // filtered (or unfiltered wrongly) would not compare equal.
                        let raw: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
                        let stored = stored_row_bytes(&file, (width, height));
                        transformed += usize::from(stored != raw);
                        cases += 1;
                    }
                }
            }
        }
        assert!(
            seen.iter().all(|&n| n > 0),
            "every filter type is exercised: {seen:?}"
        );
        assert!(transformed > cases / 2, "{transformed} of {cases}");
    }

    /// The rows' bytes as stored (still filtered), without their filter-type bytes.
    fn stored_row_bytes(file: &[u8], (width, height): (usize, usize)) -> Vec<u8> {
        let raw = inflated_image_data(file);
        (0..height)
            .flat_map(|v| raw[v * (2 * width + 1) + 1..(v + 1) * (2 * width + 1)].to_vec())
            .collect()
    }

    fn rgbd() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/realdata/rgbd")
    }

    #[test]
    fn the_real_depth_maps_read_as_the_general_reader_reads_them() {
        let dir = rgbd();
        assert!(
            dir.is_dir(),
            "{} is missing (../shared beside the repository)",
            dir.display()
        );
        let mut files = Vec::new();
        let mut stack = vec![dir];
        while let Some(dir) = stack.pop() {
            for entry in std::fs::read_dir(&dir).expect("list") {
                let path = entry.expect("entry").path();
                let name = path
                    .file_name()
                    .expect("name")
                    .to_string_lossy()
                    .into_owned();
                if path.is_dir() {
                    stack.push(path);
                } else if name.ends_with("depth.png") {
                    files.push(path);
                }
            }
        }
        files.sort();
        let mut rows_by_filter = [0usize; 5];
        for path in &files {
            let reference = through_image(path).expect("image decodes");
            let rows = through_rows(path).expect("decodes").expect("16-bit gray");
            assert!(rows == reference, "{}", path.display());
            let file = std::fs::read(path).expect("read");
            let types = filter_types(&file, (reference.0, reference.1));
            for &t in &types {
                rows_by_filter[usize::from(t)] += 1;
            }
        }
        // graspnet_example, ucn_demo (2), ycbv_real (2), ycbv_syn (2).
        assert!(files.len() >= 7, "{files:?}");
        // Their writers filter every row with Sub (3,600 rows on 2026-12-01): the other filter
        // types are the test above's.
        assert!(rows_by_filter[1] > 0, "{rows_by_filter:?}");
    }

    /// The PNG CRC-32 of a chunk's type and data.
    fn crc32(bytes: &[u8]) -> u32 {
        let mut crc = !0u32;
        for &byte in bytes {
            crc ^= u32::from(byte);
            for _ in 0..8 {
                crc = if crc & 1 != 0 {
                    (crc >> 1) ^ 0xEDB8_8320
                } else {
                    crc >> 1
                };
            }
        }
        !crc
    }

    /// A PNG of `width` × `height` 16-bit gray pixels whose image data is `raw` (filter bytes
    /// included), compressed as one IDAT chunk.
    fn raw_png(width: u32, height: u32, raw: &[u8]) -> Vec<u8> {
        fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let start = out.len();
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
            let crc = crc32(&out[start..]);
            out.extend_from_slice(&crc.to_be_bytes());
        }
        let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut header = Vec::new();
        header.extend_from_slice(&width.to_be_bytes());
        header.extend_from_slice(&height.to_be_bytes());
        header.extend_from_slice(&[16, 0, 0, 0, 0]);
        chunk(&mut out, b"IHDR", &header);
        if !raw.is_empty() {
            chunk(&mut out, b"IDAT", &fdeflate::compress_to_vec(raw));
        }
        chunk(&mut out, b"IEND", &[]);
        out
    }

    #[test]
    fn broken_depth_pngs_are_errors_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.png");
        let (width, height) = (5u32, 4u32);
        let row = |filter: u8| {
            let mut row = vec![filter];
            row.extend((0..width).flat_map(|u| (1000 + u as u16).to_be_bytes()));
            row
        };
        let rows = |filters: [u8; 4]| -> Vec<u8> { filters.iter().flat_map(|&f| row(f)).collect() };

        // Control: the hand-made file reads, and as the general reader reads it.
        std::fs::write(&path, raw_png(width, height, &rows([0, 1, 2, 4]))).expect("write");
        let read = through_rows(&path).expect("decodes").expect("16-bit gray");
        assert_eq!(read, through_image(&path).expect("image decodes"));

        let cases: [(&str, Vec<u8>, &str); 4] = [
            (
                "a filter type PNG does not define",
                raw_png(width, height, &rows([0, 1, 5, 0])),
                "row 2 has filter type 5",
            ),
            (
                "rows missing",
                raw_png(
                    width,
                    height,
                    &rows([0, 1, 2, 4])[..2 * (2 * width as usize + 1)],
                ),
                "ends after 2 of its 4 rows",
            ),
            (
                "no image data",
                raw_png(width, height, &[]),
                "no image data",
            ),
            (
                "the file cut short",
                raw_png(width, height, &rows([0, 1, 2, 4]))[..60].to_vec(),
                "cannot decode",
            ),
        ];
        for (what, file, says) in cases {
            std::fs::write(&path, &file).expect("write");
            let message = match through_rows(&path) {
                Err(e) => e.to_string(),
                Ok(_) => panic!("{what}: read"),
            };
            assert!(message.contains("depth.png"), "{what}: {message}");
            assert!(
                message.contains("cannot decode the image"),
                "{what}: {message}"
            );
            assert!(message.contains(says), "{what}: {message}");
            // The general reader refuses it too.
            assert!(through_image(&path).is_err(), "{what}");
        }

        // A header asking for more pixels than allowed: refused before any image data.
        std::fs::write(&path, raw_png(100_000, 100_000, &[])).expect("write");
        let message = match read_depth_png(&path, 1 << 20, SCALE) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("read"),
        };
        assert!(
            message.contains("more than [lift] max_image_pixels"),
            "{message}"
        );
    }

    #[test]
    fn other_pngs_are_left_to_the_general_reader() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.png");
        // With transparency, `image` gives two channels: not a depth map's PNG.
        let values = [1000u16, 0, 1200, 1300];
        std::fs::write(&path, encode((2, 2), &values, Filter::Sub, 1 << 20, true)).expect("write");
        assert!(through_rows(&path).expect("reads").is_none());
        // Control: the same image without the tRNS chunk is read here.
        std::fs::write(&path, encode((2, 2), &values, Filter::Sub, 1 << 20, false)).expect("write");
        assert!(through_rows(&path).expect("reads").is_some());
        // 8-bit gray and 16-bit RGB.
        image::GrayImage::new(3, 2).save(&path).expect("save");
        assert!(through_rows(&path).expect("reads").is_none());
        image::ImageBuffer::<image::Rgb<u16>, _>::new(3, 2)
            .save(&path)
            .expect("save");
        assert!(through_rows(&path).expect("reads").is_none());
        // A JPEG named depth.png, and a file too short to be anything.
        let jpeg = dir.path().join("photo.jpg");
        image::GrayImage::new(3, 2).save(&jpeg).expect("save");
        std::fs::copy(&jpeg, &path).expect("copy");
        assert!(through_rows(&path).expect("reads").is_none());
        std::fs::write(&path, b"\x89PN").expect("write");
        assert!(through_rows(&path).expect("reads").is_none());
    }
}

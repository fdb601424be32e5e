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
//!   copied into a `u16` image, then converted into metres; here each inflated row goes
//!   straight into metres.
//!
//! Any other PNG (another colour type or bit depth, interlaced, with a `tRNS` chunk, which
//! `image` turns into an alpha channel), or another format under the name, is left to the
//! general reader ([`super::inputs`]), which decodes it, or names what it is when it is not a
//! depth map. The result is the general reader's to the bit (`inputs`' `depth_png_tests`: every
//! filter type, odd widths, image data split over many chunks, the real depth maps of
//! `../shared/realdata`).

use std::fs::File;
use std::io::{BufRead, BufReader, ErrorKind};
use std::path::Path;

use png::{chunk, BitDepth, ColorType, Decoded, DecodingError, StreamingDecoder, UnfilterRegion};

/// Why a depth PNG was not read; the caller ([`super::inputs`]) words it for the user.
#[derive(Debug)]
pub(super) enum PngFault {
    /// The file cannot be opened.
    Open(std::io::Error),
    /// The file is not a complete, valid PNG: what is wrong.
    Decode(String),
    /// Its header asks for more than the allowed pixels: width and height.
    TooManyPixels(u32, u32),
}

/// A depth map read from a PNG: row-major metres (NaN where there is no measurement) and how
/// many are measurements.
pub(super) struct DepthPng {
    pub width: usize,
    pub height: usize,
    pub metres: Vec<f32>,
    pub valid: usize,
}

/// Reads `path` when it is a non-interlaced 16-bit grayscale PNG without transparency,
/// refusing it on its header when it has more than `max_pixels` pixels. `to_metres` appends a
/// row's big-endian values to the depth map as metres and returns how many are measurements.
/// `Ok(None)`: another kind of PNG, or not a PNG, for the general reader.
pub(super) fn read_depth_png(
    path: &Path,
    max_pixels: u64,
    mut to_metres: impl FnMut(&[u8], &mut Vec<f32>) -> usize,
) -> Result<Option<DepthPng>, PngFault> {
    let file = File::open(path).map_err(PngFault::Open)?;
    let mut reader = Reader {
        file: BufReader::with_capacity(64 * 1024, file),
        decoder: StreamingDecoder::new(),
    };
    let decode_error = |e: DecodingError| PngFault::Decode(e.to_string());
    // Another format under a .png name (`image` guesses formats from their first bytes): the
    // general reader's, which names what it is.
    let start = reader
        .file
        .fill_buf()
        .map_err(|e| PngFault::Decode(e.to_string()))?;
    if !start.starts_with(b"\x89PNG\r\n\x1a\n") {
        return Ok(None);
    }
    while reader.decoder.info().is_none() {
        reader.next(None).map_err(decode_error)?;
    }
    let info = reader.decoder.info().expect("the header was read");
    let (width, height) = (info.width, info.height);
    if u64::from(width) * u64::from(height) > max_pixels {
        return Err(PngFault::TooManyPixels(width, height));
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
                return Err(PngFault::Decode(
                    "the file has no image data (IDAT)".to_owned(),
                ))
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
                return Err(PngFault::Decode(format!(
                    "the image data ends after {v} of its {height} rows"
                )));
            }
            let decoded = reader
                .next(Some(&mut region.as_buf(&mut filtered)))
                .map_err(decode_error)?;
            flushed = matches!(decoded, Decoded::ImageDataFlushed);
        }
        let line = &filtered[end - row_len..end];
        row.copy_from_slice(&line[1..]);
        if !unfilter(line[0], &previous, &mut row) {
            return Err(PngFault::Decode(format!(
                "row {v} has filter type {}, which PNG does not define (0 to 4)",
                line[0]
            )));
        }
        valid += to_metres(&row, &mut metres);
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
    use super::*;

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
}

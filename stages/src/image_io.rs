//! PNG encoding and decoding of the few pixel layouts mesa uses: 8-bit RGB photos, 8-bit RGBA
//! textures, 8- or 16-bit single-channel label and depth images.
//!
//! Encoding is deterministic (fixed compression settings, no time or text chunks), so the same
//! pixels always give the same bytes.

use std::io::Cursor;

use thiserror::Error;

/// A decoding or encoding failure.
#[derive(Debug, Error)]
pub enum ImageError {
    /// The PNG stream could not be decoded.
    #[error("not a readable PNG: {0}")]
    Decode(#[from] png::DecodingError),
    /// The PNG stream could not be encoded.
    #[error("PNG encoding failed: {0}")]
    Encode(#[from] png::EncodingError),
    /// The pixel buffer does not match the dimensions.
    #[error("{len} samples for a {width}×{height}×{channels} image")]
    BufferSize {
        /// Samples given.
        len: usize,
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Channels per pixel.
        channels: usize,
    },
    /// A PNG whose layout is not the one asked for.
    #[error("PNG is {found} (expected {expected})")]
    Layout {
        /// What the file holds, like "8-bit RGBA".
        found: String,
        /// What the caller asked for.
        expected: &'static str,
    },
}

/// Pixel layouts mesa writes and reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PixelLayout {
    /// 8-bit single channel.
    Gray8,
    /// 16-bit single channel.
    Gray16,
    /// 8-bit RGB.
    Rgb8,
    /// 8-bit RGBA.
    Rgba8,
}

impl PixelLayout {
    fn channels(self) -> usize {
        match self {
            PixelLayout::Gray8 | PixelLayout::Gray16 => 1,
            PixelLayout::Rgb8 => 3,
            PixelLayout::Rgba8 => 4,
        }
    }
}

fn check_len(len: usize, width: u32, height: u32, channels: usize) -> Result<(), ImageError> {
    if len != width as usize * height as usize * channels {
        return Err(ImageError::BufferSize {
            len,
            width,
            height,
            channels,
        });
    }
    Ok(())
}

fn encode(
    width: u32,
    height: u32,
    color: png::ColorType,
    depth: png::BitDepth,
    data: &[u8],
) -> Result<Vec<u8>, ImageError> {
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(color);
        encoder.set_depth(depth);
        encoder.set_compression(png::Compression::Fast);
        let mut writer = encoder.write_header()?;
        writer.write_image_data(data)?;
        writer.finish()?;
    }
    Ok(out)
}

/// Encodes 8-bit RGB pixels (row-major, `width · height · 3` bytes).
pub fn encode_rgb8(width: u32, height: u32, rgb: &[u8]) -> Result<Vec<u8>, ImageError> {
    check_len(rgb.len(), width, height, 3)?;
    encode(
        width,
        height,
        png::ColorType::Rgb,
        png::BitDepth::Eight,
        rgb,
    )
}

/// Encodes 8-bit RGBA pixels (row-major, `width · height · 4` bytes).
pub fn encode_rgba8(width: u32, height: u32, rgba: &[u8]) -> Result<Vec<u8>, ImageError> {
    check_len(rgba.len(), width, height, 4)?;
    encode(
        width,
        height,
        png::ColorType::Rgba,
        png::BitDepth::Eight,
        rgba,
    )
}

/// Encodes an 8-bit single-channel image.
pub fn encode_gray8(width: u32, height: u32, values: &[u8]) -> Result<Vec<u8>, ImageError> {
    check_len(values.len(), width, height, 1)?;
    encode(
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        values,
    )
}

/// Encodes a 16-bit single-channel image (stored big-endian, as PNG requires).
pub fn encode_gray16(width: u32, height: u32, values: &[u16]) -> Result<Vec<u8>, ImageError> {
    check_len(values.len(), width, height, 1)?;
    let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
    encode(
        width,
        height,
        png::ColorType::Grayscale,
        png::BitDepth::Sixteen,
        &bytes,
    )
}

/// A decoded image: dimensions, layout and samples (16-bit samples widened to `u16`).
#[derive(Debug, Clone, PartialEq)]
pub struct DecodedImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// What the file held.
    pub layout: PixelLayout,
    /// Row-major samples, `channels` per pixel.
    pub samples: Vec<u16>,
}

impl DecodedImage {
    /// Samples per pixel.
    pub fn channels(&self) -> usize {
        self.layout.channels()
    }
}

/// Decodes a PNG holding 8- or 16-bit gray, 8-bit RGB or 8-bit RGBA pixels (palette and
/// sub-byte gray images are expanded to 8 bits).
pub fn decode_png(bytes: &[u8]) -> Result<DecodedImage, ImageError> {
    let mut decoder = png::Decoder::new(Cursor::new(bytes));
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info()?;
    let size = reader.output_buffer_size().ok_or(ImageError::Layout {
        found: "an image too large to decode".to_owned(),
        expected: "an image that fits in memory",
    })?;
    let mut buf = vec![0; size];
    let info = reader.next_frame(&mut buf)?;
    buf.truncate(info.buffer_size());
    let layout = match (info.color_type, info.bit_depth) {
        (png::ColorType::Grayscale, png::BitDepth::Eight) => PixelLayout::Gray8,
        (png::ColorType::Grayscale, png::BitDepth::Sixteen) => PixelLayout::Gray16,
        (png::ColorType::Rgb, png::BitDepth::Eight) => PixelLayout::Rgb8,
        (png::ColorType::Rgba, png::BitDepth::Eight) => PixelLayout::Rgba8,
        (color, depth) => {
            return Err(ImageError::Layout {
                found: format!("{depth:?}-bit {color:?}"),
                expected: "8/16-bit gray, 8-bit RGB or 8-bit RGBA",
            })
        }
    };
    let samples = if info.bit_depth == png::BitDepth::Sixteen {
        buf.chunks_exact(2)
            .map(|c| u16::from_be_bytes([c[0], c[1]]))
            .collect()
    } else {
        buf.iter().map(|&b| b as u16).collect()
    };
    Ok(DecodedImage {
        width: info.width,
        height: info.height,
        layout,
        samples,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gray16_round_trips_and_is_deterministic() {
        let values: Vec<u16> = (0..12u16).map(|v| v * 5000).collect();
        let a = encode_gray16(4, 3, &values).expect("encode");
        let b = encode_gray16(4, 3, &values).expect("encode");
        assert_eq!(a, b);
        let d = decode_png(&a).expect("decode");
        assert_eq!((d.width, d.height, d.layout), (4, 3, PixelLayout::Gray16));
        assert_eq!(d.samples, values);
    }

    #[test]
    fn rgb8_round_trips() {
        let rgb: Vec<u8> = (0..2 * 2 * 3).map(|v| (v * 20) as u8).collect();
        let d = decode_png(&encode_rgb8(2, 2, &rgb).expect("encode")).expect("decode");
        assert_eq!(d.layout, PixelLayout::Rgb8);
        assert_eq!(d.samples, rgb.iter().map(|&v| v as u16).collect::<Vec<_>>());
    }

    #[test]
    fn wrong_buffer_size_is_an_error() {
        assert!(matches!(
            encode_gray8(3, 3, &[0; 8]),
            Err(ImageError::BufferSize { len: 8, .. })
        ));
    }
}

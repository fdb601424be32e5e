//! The embedded images of an edited scene, checked by their headers only (never decoded): a
//! returned file whose image claims billions of pixels is damaged or hostile, and would take
//! gigabytes from whatever renders it next.

use super::IngestError;
use crate::glb_read::GlbDocument;

/// The largest width or height accepted, pixels (16384, the texture limit of common GPUs).
pub const MAX_IMAGE_SIDE_PX: u64 = 16_384;

/// The pixel size a PNG or JPEG header declares; `None` for another format or a header that
/// cannot be read.
pub fn declared_size(bytes: &[u8]) -> Option<(u64, u64)> {
    if bytes.starts_with(b"\x89PNG\r\n\x1a\n") {
        // The first chunk is IHDR: width and height, big-endian, at bytes 16..24.
        if bytes.get(12..16)? != b"IHDR" {
            return None;
        }
        let w = u32::from_be_bytes(bytes.get(16..20)?.try_into().ok()?);
        let h = u32::from_be_bytes(bytes.get(20..24)?.try_into().ok()?);
        return Some((u64::from(w), u64::from(h)));
    }
    if bytes.starts_with(&[0xFF, 0xD8]) {
        // Walk the markers to the first start-of-frame.
        let mut i = 2;
        while i + 4 <= bytes.len() {
            if bytes[i] != 0xFF {
                return None;
            }
            let marker = bytes[i + 1];
            if marker == 0xFF {
                i += 1;
                continue;
            }
            let length = usize::from(u16::from_be_bytes([bytes[i + 2], bytes[i + 3]]));
            let sof = matches!(marker, 0xC0..=0xCF) && !matches!(marker, 0xC4 | 0xC8 | 0xCC);
            if sof {
                let h = u16::from_be_bytes(bytes.get(i + 5..i + 7)?.try_into().ok()?);
                let w = u16::from_be_bytes(bytes.get(i + 7..i + 9)?.try_into().ok()?);
                return Some((u64::from(w), u64::from(h)));
            }
            if length < 2 {
                return None;
            }
            i += 2 + length;
        }
        return None;
    }
    None
}

/// Checks every image of the document: readable, and within [`MAX_IMAGE_SIDE_PX`].
pub fn check_images(document: &GlbDocument<'_>) -> Result<(), IngestError> {
    for i in 0..document.root().images.len() {
        let path = format!("images[{i}]");
        let (bytes, _mime) = document.image(i)?;
        if let Some((w, h)) = declared_size(&bytes) {
            if w == 0 || h == 0 || w > MAX_IMAGE_SIDE_PX || h > MAX_IMAGE_SIDE_PX {
                let decoded_gb = (w * h * 4) as f64 / 1e9;
                return Err(IngestError::Image {
                    path,
                    problem: format!(
                        "its header declares {w} × {h} pixels ({decoded_gb:.1} GB decoded), \
                         outside 1..={MAX_IMAGE_SIDE_PX} per side: the file is damaged or was \
                         not exported from the pack (re-export the scene from Blender)"
                    ),
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_give_the_declared_size() {
        let png = crate::image_io::encode_rgb8(3, 2, &[0; 18]).expect("png");
        assert_eq!(declared_size(&png), Some((3, 2)));
        // A JPEG's SOF0 after an APP0 segment.
        let jpeg = [
            0xFF, 0xD8, 0xFF, 0xE0, 0x00, 0x04, 0x00, 0x00, 0xFF, 0xC0, 0x00, 0x11, 0x08, 0x01,
            0x40, 0x02, 0x80, 0x03,
        ];
        assert_eq!(declared_size(&jpeg), Some((640, 320)));
        assert_eq!(declared_size(b"GIF89a"), None);
    }
}

//! Per-object snapshots: the photo cropped to an instance's mask with a margin, the pixels
//! outside the mask dimmed so that the instance stands out while its surroundings stay
//! readable.

use crate::image_io::{encode_rgb8_photo, ImageError};

/// A photo as RGB8, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Photo {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// One RGB triple per pixel.
    pub rgb: Vec<[u8; 3]>,
}

/// How much of the surroundings a snapshot keeps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Margin {
    /// Margin as a fraction of the mask box's larger side.
    pub fraction: f64,
    /// The smallest margin, pixels.
    pub min_px: u32,
}

/// The crop of `photo` around `pixels` (row-major indices of the mask) as a PNG, or `None`
/// when the mask is empty.
pub fn snapshot_png(
    photo: &Photo,
    pixels: &[u32],
    margin: Margin,
) -> Result<Option<Vec<u8>>, ImageError> {
    let (w, h) = (photo.width, photo.height);
    let n = w * h;
    // The mask's bounds, one division per pixel; pixels past the photo are left out.
    let (mut u0, mut v0, mut u1, mut v1) = (usize::MAX, usize::MAX, 0, 0);
    for &p in pixels {
        let p = p as usize;
        if p >= n {
            continue;
        }
        let (v, u) = (p / w, p % w);
        u0 = u0.min(u);
        v0 = v0.min(v);
        u1 = u1.max(u);
        v1 = v1.max(v);
    }
    if u0 == usize::MAX {
        return Ok(None);
    }
    let side = (u1 - u0 + 1).max(v1 - v0 + 1) as f64;
    let m = ((margin.fraction * side).round() as usize).max(margin.min_px as usize);
    let (cu0, cv0) = (u0.saturating_sub(m), v0.saturating_sub(m));
    let (cu1, cv1) = ((u1 + m).min(w - 1), (v1 + m).min(h - 1));
    let (cw, ch) = (cu1 - cu0 + 1, cv1 - cv0 + 1);
    // The crop, every pixel dimmed halfway to a mid grey (context without competing with the
    // instance), then the mask's pixels in their own colours.
    let mut rgb = vec![0u8; cw * ch * 3];
    for (v, out) in (cv0..=cv1).zip(rgb.chunks_exact_mut(cw * 3)) {
        let row = photo.rgb[v * w + cu0..=v * w + cu1].as_flattened();
        for (o, &c) in out.iter_mut().zip(row) {
            *o = ((u16::from(c) + 96) / 2) as u8;
        }
    }
    for &p in pixels {
        let p = p as usize;
        if p >= n {
            continue;
        }
        // Inside the bounds, hence the crop.
        let (v, u) = (p / w, p % w);
        let o = ((v - cv0) * cw + (u - cu0)) * 3;
        rgb[o..o + 3].copy_from_slice(&photo.rgb[p]);
    }
    encode_rgb8_photo(cw as u32, ch as u32, &rgb).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image_io::decode_png;

    #[test]
    fn the_crop_covers_the_mask_and_its_margin() {
        let photo = Photo {
            width: 40,
            height: 30,
            rgb: vec![[200, 10, 10]; 40 * 30],
        };
        // A 4×3 block at (10..14, 5..8).
        let pixels: Vec<u32> = (5..8)
            .flat_map(|v| (10..14).map(move |u| (v * 40 + u) as u32))
            .collect();
        let png = snapshot_png(
            &photo,
            &pixels,
            Margin {
                fraction: 0.0,
                min_px: 2,
            },
        )
        .expect("encodes")
        .expect("a snapshot");
        let image = decode_png(&png).expect("png");
        assert_eq!((image.width, image.height), (8, 7));
        // A mask pixel keeps its colour; a margin pixel is dimmed.
        let at = |u: usize, v: usize| {
            let i = (v * 8 + u) * 3;
            [image.samples[i], image.samples[i + 1], image.samples[i + 2]]
        };
        assert_eq!(at(3, 3), [200, 10, 10]);
        assert_eq!(at(0, 0), [148, 53, 53]);
        // Clamped at the border, and nothing for an empty mask.
        let corner = snapshot_png(
            &photo,
            &[0],
            Margin {
                fraction: 0.0,
                min_px: 5,
            },
        )
        .expect("encodes")
        .expect("a snapshot");
        let image = decode_png(&corner).expect("png");
        assert_eq!((image.width, image.height), (6, 6));
        assert!(snapshot_png(
            &photo,
            &[],
            Margin {
                fraction: 0.1,
                min_px: 1
            }
        )
        .expect("ok")
        .is_none());
    }
}

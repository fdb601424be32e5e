//! Procedural textures (sRGB RGBA8) for the demo assets and the room.
//!
//! Every texture is a pure function of its parameters: no random state, only an integer hash
//! for grain and speckle, so the asset library is the same on every run.

use crate::raster::Texture;

/// An sRGB colour.
pub(crate) type Srgb = [u8; 3];

/// A cheap integer hash in [0, 1) (for grain and speckle).
fn hash01(x: i64, y: i64, salt: u64) -> f32 {
    let mut h = (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ salt.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 33;
    h = h.wrapping_mul(0xFF51_AFD7_ED55_8CCD);
    h ^= h >> 33;
    (h >> 40) as f32 / (1u64 << 24) as f32
}

/// Smooth value noise in [0, 1) at a continuous point, periodic with period `(px, py)`
/// lattice cells so that textures tile without seams.
fn value_noise(x: f32, y: f32, px: i64, py: i64, salt: u64) -> f32 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let (sx, sy) = (fx * fx * (3.0 - 2.0 * fx), fy * fy * (3.0 - 2.0 * fy));
    let (xi, yi) = (x0 as i64, y0 as i64);
    let h = |x: i64, y: i64| hash01(x.rem_euclid(px.max(1)), y.rem_euclid(py.max(1)), salt);
    let a = h(xi, yi);
    let b = h(xi + 1, yi);
    let c = h(xi, yi + 1);
    let d = h(xi + 1, yi + 1);
    let top = a + (b - a) * sx;
    let bottom = c + (d - c) * sx;
    top + (bottom - top) * sy
}

fn mix(a: Srgb, b: Srgb, t: f32) -> Srgb {
    let t = t.clamp(0.0, 1.0);
    std::array::from_fn(|i| (a[i] as f32 + (b[i] as f32 - a[i] as f32) * t).round() as u8)
}

fn shade(c: Srgb, factor: f32) -> Srgb {
    c.map(|v| (v as f32 * factor).round().clamp(0.0, 255.0) as u8)
}

fn build(width: u32, height: u32, f: impl Fn(u32, u32) -> Srgb) -> Texture {
    let mut rgba = Vec::with_capacity(width as usize * height as usize * 4);
    for y in 0..height {
        for x in 0..width {
            let c = f(x, y);
            rgba.extend_from_slice(&[c[0], c[1], c[2], 255]);
        }
    }
    Texture {
        width,
        height,
        rgba,
    }
}

/// Horizontal bands along v (the height of a lathe surface): `colors` repeated `repeats`
/// times.
pub(crate) fn bands(colors: &[Srgb], repeats: u32) -> Texture {
    let n = (colors.len() as u32 * repeats).max(1);
    build(16, 128, |_, y| {
        colors[((y * n / 128) as usize) % colors.len()]
    })
}

/// Wood grain: stretched value-noise rings along u.
pub(crate) fn wood(light: Srgb, dark: Srgb, salt: u64) -> Texture {
    build(256, 256, |x, y| {
        let (u, v) = (x as f32 / 256.0, y as f32 / 256.0);
        let warp = value_noise(u * 3.0, v * 24.0, 3, 24, salt) * 2.5;
        let ring = ((v * 18.0 + warp) * std::f32::consts::TAU).sin() * 0.5 + 0.5;
        let fine = hash01(x as i64 / 2, y as i64, salt + 1) * 0.12;
        mix(light, dark, ring * 0.55 + fine)
    })
}

/// A book cover wrapped on a box: the whole texture is the front cover, with a title band,
/// a border and a speckle of print.
pub(crate) fn book_cover(cover: Srgb, band: Srgb, salt: u64) -> Texture {
    build(128, 128, |x, y| {
        let border = !(6..=121).contains(&x) || !(6..=121).contains(&y);
        if border {
            return shade(cover, 0.8);
        }
        if (30..52).contains(&y) && (14..114).contains(&x) {
            let letter = (x / 9 + y / 11) % 3 != 0 && (34..48).contains(&y) && x % 9 < 6;
            return if letter { cover } else { band };
        }
        if (70..74).contains(&y) && (30..98).contains(&x) {
            return band;
        }
        let speckle = hash01(x as i64, y as i64, salt) * 0.08;
        shade(cover, 0.96 + speckle)
    })
}

/// Keyboard keys: a grid of light keys on a dark plate.
pub(crate) fn keys(plate: Srgb, key: Srgb) -> Texture {
    build(256, 128, |x, y| {
        let (kx, ky) = (x % 16, y % 21);
        let row = y / 21;
        let shift = if row % 2 == 1 { 5 } else { 0 };
        let kx = (kx + shift) % 16;
        if (2..14).contains(&kx) && (2..18).contains(&ky) && y < 126 {
            shade(key, 1.0 - ky as f32 * 0.01)
        } else {
            plate
        }
    })
}

/// A laptop or phone screen: a gradient wallpaper with a few window rectangles.
pub(crate) fn screen(top: Srgb, bottom: Srgb, window: Srgb) -> Texture {
    build(128, 128, |x, y| {
        let in_window = ((16..70).contains(&x) && (20..64).contains(&y))
            || ((58..112).contains(&x) && (50..100).contains(&y));
        if in_window {
            if y % 8 == 0 {
                shade(window, 0.85)
            } else {
                window
            }
        } else {
            mix(top, bottom, y as f32 / 128.0)
        }
    })
}

/// A grid of small icons on a dark screen (a phone's home screen).
pub(crate) fn phone_screen() -> Texture {
    let palette: [Srgb; 5] = [
        [230, 90, 70],
        [80, 170, 230],
        [90, 200, 120],
        [245, 200, 70],
        [170, 110, 220],
    ];
    build(64, 128, |x, y| {
        let (cx, cy) = (x % 16, y % 18);
        if (3..13).contains(&cx) && (4..14).contains(&cy) && y > 10 && y < 118 {
            palette[((x / 16 + y / 18) % 5) as usize]
        } else {
            mix([20, 30, 60], [60, 30, 70], y as f32 / 128.0)
        }
    })
}

/// Polka dots on a background.
pub(crate) fn dots(background: Srgb, dot: Srgb, period: u32) -> Texture {
    build(128, 128, |x, y| {
        let (dx, dy) = (
            (x % period) as f32 - period as f32 / 2.0,
            (y % period) as f32 - period as f32 / 2.0,
        );
        if dx * dx + dy * dy < (period as f32 / 4.0).powi(2) {
            dot
        } else {
            background
        }
    })
}

/// A bottle label: a cream rectangle with a dark band and a crest, on the bottle colour.
pub(crate) fn label(paper: Srgb, ink: Srgb) -> Texture {
    build(128, 64, |x, y| {
        if (20..26).contains(&y) || (44..47).contains(&y) {
            ink
        } else if (30..40).contains(&y) && (50..78).contains(&x) {
            shade(ink, 1.3)
        } else {
            paper
        }
    })
}

/// Ruled paper: blue lines, a red margin.
pub(crate) fn ruled_paper() -> Texture {
    build(128, 128, |x, y| {
        if (18..20).contains(&x) {
            [220, 80, 80]
        } else if y % 10 == 0 && y > 12 {
            [130, 160, 220]
        } else {
            [246, 246, 240]
        }
    })
}

/// Stripes along u (for a towel).
pub(crate) fn stripes_u(colors: &[Srgb], period: u32) -> Texture {
    build(128, 128, |x, y| {
        let c = colors[((x / period.max(1)) as usize) % colors.len()];
        shade(c, 0.94 + hash01(x as i64, y as i64 / 2, 7) * 0.06)
    })
}

/// Remote control: dark body with a grid of round buttons and one red power button.
pub(crate) fn remote_buttons() -> Texture {
    build(64, 256, |x, y| {
        let (cx, cy) = (x % 16, y % 20);
        let (dx, dy) = (cx as f32 - 8.0, cy as f32 - 10.0);
        if y < 20 && (x as f32 - 32.0).powi(2) + (dy).powi(2) < 30.0 {
            [200, 40, 40]
        } else if y > 40 && y < 220 && dx * dx + dy * dy < 20.0 {
            [150, 150, 155]
        } else {
            [35, 35, 38]
        }
    })
}

/// A decorated rim for a plate: concentric bands in v (the lathe's profile direction).
pub(crate) fn rim_pattern(base: Srgb, ink: Srgb) -> Texture {
    build(64, 128, |x, y| {
        let v = y as f32 / 128.0;
        let in_rim = (0.42..0.52).contains(&v);
        let line = (0.4..0.41).contains(&v) || (0.53..0.54).contains(&v);
        if (in_rim && (x / 4) % 2 == 0) || line {
            ink
        } else {
            base
        }
    })
}

/// Fine stone-like speckle (a vanity or counter top).
pub(crate) fn stone(base: Srgb, vein: Srgb, salt: u64) -> Texture {
    build(256, 256, |x, y| {
        let (u, v) = (x as f32 / 32.0, y as f32 / 32.0);
        let n = value_noise(u, v, 8, 8, salt) * 0.6
            + value_noise(u * 3.0, v * 3.0, 24, 24, salt + 1) * 0.4;
        let veins = (1.0 - ((n * 9.0).sin().abs())).powi(8);
        let speckle = hash01(x as i64, y as i64, salt + 2) * 0.06;
        mix(shade(base, 0.97 + speckle), vein, veins * 0.6)
    })
}

/// Square floor tiles with grout.
pub(crate) fn tiles(tile: Srgb, grout: Srgb) -> Texture {
    build(128, 128, |x, y| {
        if x % 64 < 2 || y % 64 < 2 {
            grout
        } else {
            shade(tile, 0.95 + hash01(x as i64 / 64, y as i64 / 64, 3) * 0.1)
        }
    })
}

/// Faint plaster noise for a wall.
pub(crate) fn plaster(base: Srgb) -> Texture {
    build(128, 128, |x, y| {
        let n = value_noise(x as f32 / 8.0, y as f32 / 8.0, 16, 16, 11);
        shade(base, 0.97 + n * 0.05)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn textures_are_pure_functions() {
        assert_eq!(
            wood([200, 150, 100], [120, 80, 50], 1),
            wood([200, 150, 100], [120, 80, 50], 1)
        );
        assert_ne!(
            wood([200, 150, 100], [120, 80, 50], 1),
            wood([200, 150, 100], [120, 80, 50], 2)
        );
        let t = book_cover([150, 30, 30], [230, 200, 120], 4);
        assert_eq!(t.rgba.len(), 128 * 128 * 4);
        assert!(t.rgba.chunks(4).all(|p| p[3] == 255));
    }

    #[test]
    fn room_textures_tile_without_seams() {
        // The last column continues into the first: neighbours across the wrap differ no
        // more than neighbours inside.
        for t in [
            wood([200, 150, 100], [120, 80, 50], 5),
            stone([230, 230, 230], [150, 150, 150], 5),
            plaster([228, 224, 214]),
        ] {
            let w = t.width as usize;
            let px = |x: usize, y: usize| t.rgba[(y * w + x) * 4] as i32;
            let wrap: i32 = (0..t.height as usize)
                .map(|y| (px(w - 1, y) - px(0, y)).abs())
                .sum();
            let inside: i32 = (0..t.height as usize)
                .map(|y| (px(w / 2, y) - px(w / 2 + 1, y)).abs())
                .sum();
            assert!(
                wrap <= inside * 3 + t.height as i32 * 4,
                "wrap {wrap} inside {inside}"
            );
        }
    }

    #[test]
    fn hash_is_in_unit_interval() {
        for i in 0..1000 {
            let h = hash01(i, -i * 7, 3);
            assert!((0.0..1.0).contains(&h));
        }
    }
}

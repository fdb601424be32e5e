//! Readers of a scene's inputs (SPEC section 3): depth in every accepted form, the camera,
//! instance masks (label PNG, per-instance PNGs, COCO RLE), the photo.
//!
//! Every problem is a [`LiftError`] naming the file, the field and the fix.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageReader};
use mesa_schemas::artifacts::{CalibrationKind, DepthCalibration, InstanceEntry, InstancesJson};
use serde_json::Value;

use super::depth_png::{read_depth_png, DepthPng, PngFault};
use super::{LiftConfig, LiftError};

/// A depth map in metres; `NaN` where there is no measurement.
#[derive(Debug, Clone)]
pub struct DepthMap {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Row-major depths in metres.
    pub depth_m: Vec<f32>,
}

impl DepthMap {
    /// The depth at (u, v), `None` when invalid.
    pub fn at(&self, u: usize, v: usize) -> Option<f32> {
        let d = self.depth_m[v * self.width + u];
        d.is_finite().then_some(d)
    }
}

/// Pinhole intrinsics in pixels (OpenCV convention).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    /// Image width in pixels.
    pub width: usize,
    /// Image height in pixels.
    pub height: usize,
    /// Focal length x, pixels.
    pub fx: f64,
    /// Focal length y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Where they came from: `intrinsics` or `fov`.
    pub source: &'static str,
}

/// The camera of a scene with the depth calibration it may carry.
#[derive(Debug, Clone, Copy)]
pub struct Camera {
    /// The intrinsics.
    pub intrinsics: Intrinsics,
    /// An affine calibration when the depth map is relative.
    pub calibration: Option<DepthCalibration>,
}

/// Instance masks: for each mask id, the pixel indices (row-major) it covers.
#[derive(Debug, Clone, Default)]
pub struct Masks {
    /// Pixel indices by mask id, sorted.
    pub pixels: BTreeMap<u32, Vec<u32>>,
    /// The image's pixel count.
    pub len: usize,
    /// Which file the masks came from (for messages).
    pub source: String,
}

impl Masks {
    /// Pixels covered by no mask (background), sorted. Made on demand: only a scene without a
    /// support mask fits its table on them.
    pub fn background(&self) -> Vec<u32> {
        let (covered, _) = self.covered();
        (0..self.len as u32)
            .filter(|&p| !covered[p as usize])
            .collect()
    }

    /// Every `step`-th pixel of [`Masks::background`], from the first, with `step` the
    /// smallest that leaves at most `at_most` of them: what `background().iter().step_by(step)`
    /// gives, without listing the whole background first (a real frame's is most of its
    /// million pixels, of which the table fit keeps a fifth).
    pub fn background_sample(&self, at_most: usize) -> Vec<u32> {
        let (covered, count) = self.covered();
        let step = (self.len - count).div_ceil(at_most.max(1)).max(1);
        (0..self.len as u32)
            .filter(|&p| !covered[p as usize])
            .step_by(step)
            .collect()
    }

    /// Which pixels some mask covers, and how many do.
    fn covered(&self) -> (Vec<bool>, usize) {
        let mut covered = vec![false; self.len];
        let mut count = 0;
        for list in self.pixels.values() {
            for &p in list {
                count += usize::from(!covered[p as usize]);
                covered[p as usize] = true;
            }
        }
        (covered, count)
    }
}

fn image_error(path: &Path, e: impl std::fmt::Display) -> LiftError {
    LiftError::input(
        path,
        "$",
        format!("cannot decode the image: {e}"),
        "re-export it as a complete PNG",
    )
}

/// What a PNG may be, checked on its header before any pixel is decoded.
#[derive(Debug, Clone, Copy)]
pub enum PngLimit {
    /// At most this many pixels (`[lift] max_image_pixels`).
    MaxPixels(u64),
    /// Exactly this width and height (a mask or photo of the depth map's size).
    Size(usize, usize),
}

/// Opens a PNG fully (a truncated or corrupt file is an error naming it). Its size is read from
/// the header and checked against `limit` first, so a header claiming a huge image is refused
/// before anything is allocated; the decoder may then allocate what that size needs.
pub fn read_png(path: &Path, limit: PngLimit) -> Result<DynamicImage, LiftError> {
    let open = || {
        ImageReader::open(path)
            .map_err(|e| {
                LiftError::input(path, "$", format!("cannot open: {e}"), "check the path")
            })?
            .with_guessed_format()
            .map_err(|e| image_error(path, e))
    };
    let (w, h) = open()?
        .into_dimensions()
        .map_err(|e| image_error(path, e))?;
    match limit {
        PngLimit::MaxPixels(max) if u64::from(w) * u64::from(h) > max => {
            return Err(too_many_pixels(path, w, h, max));
        }
        PngLimit::Size(width, height) => check_size(path, w as usize, h as usize, width, height)?,
        PngLimit::MaxPixels(_) => {}
    }
    let mut reader = open()?;
    let mut limits = image::Limits::default();
    // 16-bit RGBA is 8 bytes a pixel; the decoder's own default (512 MiB) would refuse an
    // image the check above allowed, with a message about memory.
    limits.max_alloc = Some((u64::from(w) * u64::from(h)).saturating_mul(8) + (1 << 20));
    reader.limits(limits);
    reader.decode().map_err(|e| image_error(path, e))
}

/// The error for an image of `w` × `h` pixels, more than `max_image_pixels` (`max`).
fn too_many_pixels(path: &Path, w: u32, h: u32, max: u64) -> LiftError {
    LiftError::input(
        path,
        "size",
        format!(
            "is {w}×{h} = {} pixels, more than [lift] max_image_pixels = {max}",
            u64::from(w) * u64::from(h)
        ),
        "downscale the image (and the other inputs of the scene with it), or raise \
         max_image_pixels in mesa.toml",
    )
}

/// Reads `input/depth.png` (16-bit, `depth_png_scale_m` metres per unit) or
/// `input/depth.npy` (float32 or float64 metres, H×W or H×W×1), applying a relative-depth
/// calibration when the camera has one. Zero, negative, NaN and infinite values are "no
/// measurement".
pub fn read_depth(
    input: &Path,
    camera: &Camera,
    config: &LiftConfig,
) -> Result<(DepthMap, PathBuf), LiftError> {
    let png = input.join("depth.png");
    let npy = input.join("depth.npy");
    // How many values are valid, when the reading of a depth.png counted them already.
    let mut counted = None;
    let (width, height, mut raw, path) = match (png.exists(), npy.exists()) {
        (true, true) => {
            return Err(LiftError::input(
                &png,
                "$",
                "both depth.png and depth.npy exist",
                "keep exactly one depth map per scene",
            ))
        }
        (false, false) => {
            return Err(LiftError::input(
                &png,
                "$",
                "no depth map (neither depth.png nor depth.npy)",
                "add input/depth.png (16-bit millimetres) or input/depth.npy (float32 metres)",
            ))
        }
        (true, false) => {
            let scale = config.depth_png_scale_m as f32;
            // Through `read_depth_png` the values come out as lift keeps them; a calibration
            // is applied to the raw metres, so a calibrated depth.png takes the general path.
            let direct = if camera.calibration.is_none() {
                depth_png_metres(&png, config.max_image_pixels, scale)?
            } else {
                None
            };
            if let Some(depth) = direct {
                counted = Some(depth.valid);
                (depth.width, depth.height, depth.metres, png)
            } else {
                read_depth_image(&png, camera, config, &mut counted)?
            }
        }
        (false, true) => {
            let (w, h, values) = read_npy_depth(&npy)?;
            (w, h, values, npy)
        }
    };
    if let Some(calibration) = camera.calibration {
        for d in &mut raw {
            *d = apply_calibration(*d, calibration);
        }
    }
    let valid = counted.unwrap_or_else(|| {
        let mut valid = 0usize;
        for d in &mut raw {
            let ok;
            (*d, ok) = valid_depth(*d);
            valid += usize::from(ok);
        }
        valid
    });
    if valid == 0 {
        return Err(LiftError::input(
            &path,
            "$",
            "has no valid depth (every value is 0, negative, NaN or infinite)",
            "check the depth export; metric depth in metres (npy) or millimetres (png) is expected",
        ));
    }
    Ok((
        DepthMap {
            width,
            height,
            depth_m: raw,
        },
        path,
    ))
}

/// [`read_depth_png`] with the values as lift keeps them ([`extend_valid_metres`]), its faults
/// worded as the general reader words them.
fn depth_png_metres(
    png: &Path,
    max_pixels: u64,
    scale: f32,
) -> Result<Option<DepthPng>, LiftError> {
    read_depth_png(png, max_pixels, |row, metres| {
        extend_valid_metres(row, scale, metres)
    })
    .map_err(|fault| match fault {
        PngFault::Open(e) => {
            LiftError::input(png, "$", format!("cannot open: {e}"), "check the path")
        }
        PngFault::Decode(what) => image_error(png, what),
        PngFault::TooManyPixels(w, h) => too_many_pixels(png, w, h, max_pixels),
    })
}

/// A depth.png that [`read_depth_png`] leaves to the general reader, through `image`: an
/// interlaced one, a calibrated one, one with transparency (refused: not single-channel), or
/// one that is not 16-bit grayscale or not a PNG at all (refused, naming what it is).
fn read_depth_image(
    png: &Path,
    camera: &Camera,
    config: &LiftConfig,
    counted: &mut Option<usize>,
) -> Result<(usize, usize, Vec<f32>, PathBuf), LiftError> {
    let image = read_png(png, PngLimit::MaxPixels(config.max_image_pixels))?;
    let DynamicImage::ImageLuma16(buffer) = image else {
        return Err(LiftError::input(
            png,
            "$",
            format!("is {:?}, not a 16-bit single-channel PNG", image.color()),
            "write depth as 16-bit grayscale (uint16 millimetres), or as depth.npy",
        ));
    };
    let (w, h) = buffer.dimensions();
    let scale = config.depth_png_scale_m as f32;
    let units = buffer.as_raw();
    let values = if camera.calibration.is_none() {
        // The validity pass below, done in the same pass (same values, one walk of
        // the depth map instead of two).
        let (values, valid) = valid_metres(units, scale);
        *counted = Some(valid);
        values
    } else {
        units.iter().map(|&v| metres(v, scale)).collect()
    };
    Ok((w as usize, h as usize, values, png.to_owned()))
}

/// A depth.png's value in metres: 0 is "no measurement" (NaN).
#[inline(always)]
fn metres(v: u16, scale: f32) -> f32 {
    if v == 0 {
        f32::NAN
    } else {
        f32::from(v) * scale
    }
}

/// A depth.png's values in metres as lift keeps them ([`valid_depth`] of [`metres`]), and how
/// many are valid. Counted a block at a time in 32 bits, so that the loop vectorises whole;
/// compiled for AVX2 as well (eight values a vector instead of four), chosen at run time.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn valid_metres(units: &[u16], scale: f32) -> (Vec<f32>, usize) {
    let mut values = Vec::with_capacity(units.len());
    let mut valid = 0usize;
    for block in units.chunks(4096) {
        let mut count = 0u32;
        values.extend(block.iter().map(|&v| {
            let (d, ok) = valid_depth(metres(v, scale));
            count += u32::from(ok);
            d
        }));
        valid += count as usize;
    }
    (values, valid)
}

/// [`valid_metres`] of a row of big-endian 16-bit values (as a PNG stores them), appended to
/// `values`; returns how many are valid.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn extend_valid_metres(big_endian: &[u8], scale: f32, values: &mut Vec<f32>) -> usize {
    let mut valid = 0usize;
    for block in big_endian.chunks(8192) {
        let mut count = 0u32;
        values.extend(block.chunks_exact(2).map(|pair| {
            let (d, ok) = valid_depth(metres(u16::from_be_bytes([pair[0], pair[1]]), scale));
            count += u32::from(ok);
            d
        }));
        valid += count as usize;
    }
    valid
}

/// A depth as lift keeps it, and whether it is a measurement: anything but a positive finite
/// depth is "no measurement" (NaN). Without branches, so that the loops calling it vectorise.
#[inline(always)]
fn valid_depth(d: f32) -> (f32, bool) {
    let ok = d.is_finite() & (d > 0.0);
    (if ok { d } else { f32::NAN }, ok)
}

fn apply_calibration(value: f32, c: DepthCalibration) -> f32 {
    if !value.is_finite() {
        return f32::NAN;
    }
    let affine = c.scale * f64::from(value) + c.shift;
    match c.kind {
        CalibrationKind::Depth => affine as f32,
        CalibrationKind::Disparity if affine > 0.0 => (1.0 / affine) as f32,
        CalibrationKind::Disparity => f32::NAN,
    }
}

/// How many bytes more than its file holds a depth map's header may ask for before the file is
/// refused unread: ndarray-npy allocates the header's shape before it reads any data, so a
/// damaged header could ask for terabytes. Smaller truncated files still get ndarray-npy's own
/// message.
const NPY_SHORTFALL_LIMIT: u64 = 64 << 20;

/// The shape in an `.npy` header, parsed as ndarray-npy parses it (`None` when it cannot be,
/// and ndarray-npy will say why).
fn npy_header_shape(file: &mut std::fs::File, file_len: u64) -> Option<(Vec<usize>, u64)> {
    use std::io::Read as _;
    let mut start = [0u8; 12];
    file.read_exact(&mut start[..10]).ok()?;
    if &start[..6] != b"\x93NUMPY" {
        return None;
    }
    let (header_len, data_start) = match start[6] {
        1 => (u64::from(u16::from_le_bytes([start[8], start[9]])), 10),
        2 | 3 => {
            file.read_exact(&mut start[10..]).ok()?;
            let len = u32::from_le_bytes([start[8], start[9], start[10], start[11]]);
            (u64::from(len), 12)
        }
        _ => return None,
    };
    let data_start = data_start + header_len;
    if data_start > file_len {
        return None;
    }
    let mut header = vec![0u8; header_len as usize];
    file.read_exact(&mut header).ok()?;
    let text = std::str::from_utf8(header.strip_suffix(b"\n")?).ok()?;
    let py_literal::Value::Dict(entries) = text.parse::<py_literal::Value>().ok()? else {
        return None;
    };
    let shape = entries.iter().find_map(|(key, value)| match (key, value) {
        (py_literal::Value::String(k), py_literal::Value::Tuple(dims)) if k == "shape" => dims
            .iter()
            .map(|d| match d {
                py_literal::Value::Integer(n) => usize::try_from(n).ok(),
                _ => None,
            })
            .collect::<Option<Vec<usize>>>(),
        _ => None,
    })?;
    Some((shape, file_len - data_start))
}

fn read_npy_depth(path: &Path) -> Result<(usize, usize, Vec<f32>), LiftError> {
    use ndarray::ArrayD;
    use std::io::Seek as _;
    let mut file = std::fs::File::open(path)
        .map_err(|e| LiftError::input(path, "$", format!("cannot open: {e}"), "check the path"))?;
    let file_len = file.metadata().map(|m| m.len()).unwrap_or(u64::MAX);
    if let Some((shape, data_len)) = npy_header_shape(&mut file, file_len) {
        // float32, the smaller of the two types read; a length that overflows is ndarray-npy's
        // own error (it allocates nothing then).
        let needed = shape
            .iter()
            .try_fold(4u64, |n, d| n.checked_mul(*d as u64))
            .filter(|n| *n <= isize::MAX as u64);
        if let Some(needed) = needed.filter(|n| *n > data_len.saturating_add(NPY_SHORTFALL_LIMIT)) {
            return Err(LiftError::input(
                path,
                "shape",
                format!(
                    "has shape {shape:?}, {needed} bytes of float32 at least, but the file holds \
                     {data_len} bytes of data"
                ),
                "an H×W array of metres saved whole by numpy.save (the file is truncated or its \
                 header damaged)",
            ));
        }
    }
    file.rewind()
        .map_err(|e| LiftError::input(path, "$", format!("cannot open: {e}"), "check the path"))?;
    let array: ArrayD<f32> = match ndarray_npy::ReadNpyExt::read_npy(&file) {
        Ok(a) => a,
        Err(first) => {
            let file = std::fs::File::open(path).map_err(|e| {
                LiftError::input(path, "$", format!("cannot open: {e}"), "check the path")
            })?;
            match <ArrayD<f64> as ndarray_npy::ReadNpyExt>::read_npy(file) {
                Ok(a) => a.mapv(|v| v as f32),
                Err(_) => {
                    return Err(LiftError::input(
                        path,
                        "$",
                        format!("is not a float32/float64 .npy array: {first}"),
                        "save the depth with numpy.save(path, depth.astype(numpy.float32))",
                    ))
                }
            }
        }
    };
    let shape = array.shape().to_vec();
    let (h, w) = match shape.as_slice() {
        [h, w] | [h, w, 1] => (*h, *w),
        _ => {
            return Err(LiftError::input(
                path,
                "shape",
                format!("has shape {shape:?}"),
                "an H×W (or H×W×1) array of metres",
            ))
        }
    };
    Ok((w, h, row_major(array)))
}

/// The values of `array` in logical (row-major) order. A C-order array (what `numpy.save`
/// writes unless told otherwise) gives up its own buffer, uncopied: walking it with `iter`, as
/// any other memory order is, cost two thirds of reading a 1280×720 depth.npy.
fn row_major(array: ndarray::ArrayD<f32>) -> Vec<f32> {
    if !array.is_standard_layout() {
        return array.iter().copied().collect();
    }
    let len = array.len();
    // In standard layout the elements lie contiguous in logical order from the first one.
    let (mut values, first) = array.into_raw_vec_and_offset();
    let first = first.unwrap_or(0);
    values.truncate(first + len);
    values.drain(..first);
    values
}

/// Reads `input/camera.json`: intrinsics, or a horizontal FOV, or (when neither is present)
/// the configured default FOV.
pub fn read_camera(path: &Path, config: &LiftConfig) -> Result<Camera, LiftError> {
    let value = read_json(path)?;
    let number = |key: &str| -> Result<Option<f64>, LiftError> {
        match value.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .map(Some)
                .ok_or_else(|| {
                    let shown = mesa_schemas::json::describe_value(v);
                    LiftError::input(path, key, format!("is {shown}"), "a finite number")
                }),
        }
    };
    let size = |key: &str| -> Result<usize, LiftError> {
        match number(key)? {
            Some(x) if x >= 1.0 && x.fract() == 0.0 => Ok(x as usize),
            Some(x) => Err(LiftError::input(
                path,
                key,
                format!("is {x}"),
                "a positive integer (pixels)",
            )),
            None => Err(LiftError::input(
                path,
                key,
                "is missing",
                "the image size in pixels: {\"width\": W, \"height\": H, ...}",
            )),
        }
    };
    let width = size("width")?;
    let height = size("height")?;
    let calibration = match value.get("depth_calibration") {
        None | Some(Value::Null) => None,
        Some(v) => Some(
            serde_json::from_value::<DepthCalibration>(v.clone()).map_err(|e| {
                LiftError::input(
                    path,
                    "depth_calibration",
                    e.to_string(),
                    "{\"kind\": \"disparity\" | \"depth\", \"scale\": s, \"shift\": t}",
                )
            })?,
        ),
    };
    let intrinsics = [number("fx")?, number("fy")?, number("cx")?, number("cy")?];
    let intrinsics = match intrinsics {
        [Some(fx), Some(fy), Some(cx), Some(cy)] => {
            if fx <= 0.0 || fy <= 0.0 {
                return Err(LiftError::input(
                    path,
                    "fx",
                    format!("fx = {fx}, fy = {fy}"),
                    "positive focal lengths in pixels",
                ));
            }
            Intrinsics {
                width,
                height,
                fx,
                fy,
                cx,
                cy,
                source: "intrinsics",
            }
        }
        [None, None, None, None] => {
            let fov = match number("fov_x_deg")? {
                Some(fov) => fov,
                None => Some(config.default_fov_x_deg).filter(|f| *f > 0.0).ok_or_else(|| {
                    LiftError::input(
                        path,
                        "fx",
                        "has no intrinsics (fx, fy, cx, cy) and no fov_x_deg, and [lift] default_fov_x_deg is 0 (unset)",
                        "add fov_x_deg (degrees) or intrinsics to camera.json, or set [lift] default_fov_x_deg in mesa.toml",
                    )
                })?,
            };
            if !(fov > 1.0 && fov < 179.0) {
                return Err(LiftError::input(
                    path,
                    "fov_x_deg",
                    format!("is {fov}"),
                    "a horizontal field of view between 1 and 179 degrees",
                ));
            }
            let fx = (width as f64 / 2.0) / (fov.to_radians() / 2.0).tan();
            Intrinsics {
                width,
                height,
                fx,
                fy: fx,
                cx: width as f64 / 2.0,
                cy: height as f64 / 2.0,
                source: "fov",
            }
        }
        partial => {
            let names = ["fx", "fy", "cx", "cy"];
            let missing: Vec<&str> = names
                .iter()
                .zip(partial)
                .filter(|(_, v)| v.is_none())
                .map(|(n, _)| *n)
                .collect();
            return Err(LiftError::input(
                path,
                missing[0],
                format!("is missing ({} missing)", missing.join(", ")),
                "all four of fx, fy, cx, cy in pixels, or only fov_x_deg",
            ));
        }
    };
    Ok(Camera {
        intrinsics,
        calibration,
    })
}

/// The largest `camera.json` or `instances.json` read (64 MiB; RLE masks of a few dozen
/// instances are a few MiB).
pub const MAX_INPUT_JSON_BYTES: u64 = 64 << 20;

/// Reads a JSON file, naming it on failure: a regular file (a FIFO would block the read
/// forever, `/dev/zero` never ends) of at most [`MAX_INPUT_JSON_BYTES`].
pub fn read_json(path: &Path) -> Result<Value, LiftError> {
    let meta = std::fs::metadata(path).map_err(|e| {
        LiftError::input(
            path,
            "$",
            format!("cannot read: {e}"),
            "the file must exist and be UTF-8 JSON",
        )
    })?;
    if !meta.is_file() {
        return Err(LiftError::input(
            path,
            "$",
            "is not a regular file (a FIFO, device or folder)",
            "a regular JSON file",
        ));
    }
    if meta.len() > MAX_INPUT_JSON_BYTES {
        return Err(LiftError::input(
            path,
            "$",
            format!(
                "is {} bytes, over the limit of {MAX_INPUT_JSON_BYTES} bytes",
                meta.len()
            ),
            "a JSON file of at most 64 MiB: check it is the file meant",
        ));
    }
    let text = std::fs::read_to_string(path).map_err(|e| {
        LiftError::input(
            path,
            "$",
            format!("cannot read: {e}"),
            "the file must exist and be UTF-8 JSON",
        )
    })?;
    mesa_schemas::json::parse_lenient(&text)
        .map_err(|e| LiftError::input(path, "$", format!("is not valid JSON: {e}"), "valid JSON"))
}

/// Reads `input/instances.json`.
pub fn read_instances(path: &Path) -> Result<Vec<InstanceEntry>, LiftError> {
    let value = read_json(path)?;
    let problems = mesa_schemas::Kind::by_name("instances")
        .map(|k| k.validate_value(&value))
        .unwrap_or_default();
    if let Some(problem) = problems.first() {
        return Err(LiftError::input(
            path,
            problem.path.trim_start_matches("$."),
            problem.problem.clone(),
            problem.expected.clone(),
        ));
    }
    let parsed: InstancesJson = serde_json::from_value(value).map_err(|e| {
        LiftError::input(
            path,
            "instances",
            e.to_string(),
            "{\"instances\": [{\"id\", \"label\", \"description\", \"support\"}]}",
        )
    })?;
    let mut seen = BTreeMap::new();
    for (i, entry) in parsed.instances.iter().enumerate() {
        if let Some(first) = seen.insert(entry.id, i) {
            return Err(LiftError::input(
                path,
                &format!("instances[{i}].id"),
                format!("id {} is used twice (also instances[{first}])", entry.id),
                "one entry per mask id",
            ));
        }
        if entry.id == 0 && entry.rle.is_none() {
            return Err(LiftError::input(
                path,
                &format!("instances[{i}].id"),
                "id 0 is the background of a label mask",
                "ids from 1",
            ));
        }
    }
    Ok(parsed.instances)
}

/// Reads the masks of a scene: `masks.png` (8- or 16-bit labels), `masks/<id>.png` (binary,
/// overlaps allowed), or COCO RLE in `instances.json`. Checks each against the depth size and
/// the instance list, both ways.
pub fn read_masks(
    input: &Path,
    instances: &[InstanceEntry],
    width: usize,
    height: usize,
) -> Result<Masks, LiftError> {
    let label = input.join("masks.png");
    let folder = input.join("masks");
    let rle_count = instances.iter().filter(|i| i.rle.is_some()).count();
    // An empty masks/ folder is not a mask source.
    let folder_has_masks = std::fs::read_dir(&folder).is_ok_and(|mut entries| {
        entries.any(|e| e.is_ok_and(|e| e.path().extension().is_some_and(|x| x == "png")))
    });
    let sources =
        usize::from(label.exists()) + usize::from(folder_has_masks) + usize::from(rle_count > 0);
    if sources > 1 {
        return Err(LiftError::input(
            input,
            "masks",
            "more than one mask source (masks.png, masks/, RLE in instances.json)",
            "keep exactly one form of masks per scene",
        ));
    }
    let instances_path = input.join("instances.json");
    let mut pixels: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
    let source;
    if label.exists() {
        source = label.display().to_string();
        let image = read_png(&label, PngLimit::Size(width, height))?;
        check_size(
            &label,
            image.width() as usize,
            image.height() as usize,
            width,
            height,
        )?;
        pixels =
            match image {
                DynamicImage::ImageLuma8(b) => label_lists(b.as_raw()),
                DynamicImage::ImageLuma16(b) => label_lists(b.as_raw()),
                other => return Err(LiftError::input(
                    &label,
                    "$",
                    format!("is {:?}", other.color()),
                    "an 8- or 16-bit single-channel label image (0 = background, k = instance k)",
                )),
            };
        let known: std::collections::BTreeSet<u32> = instances.iter().map(|i| i.id).collect();
        if let Some(unknown) = pixels.keys().find(|id| !known.contains(id)) {
            return Err(LiftError::input(
                &label,
                &format!("label {unknown}"),
                format!(
                    "label {unknown} ({} pixels) has no entry in instances.json",
                    pixels[unknown].len()
                ),
                "add it to instances.json, or set its pixels to 0 (background)",
            ));
        }
    } else if folder_has_masks {
        source = folder.display().to_string();
        let mut files: Vec<PathBuf> = std::fs::read_dir(&folder)
            .map_err(|e| LiftError::input(&folder, "$", e.to_string(), "a readable folder"))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "png"))
            .collect();
        files.sort();
        for file in files {
            let stem = file
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let Ok(id) = stem.parse::<u32>() else {
                return Err(LiftError::input(
                    &file,
                    "$",
                    format!("file name \"{stem}\" is not a mask id"),
                    "masks/<id>.png with the id of instances.json",
                ));
            };
            if !instances.iter().any(|i| i.id == id) {
                return Err(LiftError::input(
                    &file,
                    "$",
                    format!("mask {id} has no entry in instances.json"),
                    "add it to instances.json or remove the file",
                ));
            }
            let image = read_png(&file, PngLimit::Size(width, height))?;
            check_size(
                &file,
                image.width() as usize,
                image.height() as usize,
                width,
                height,
            )?;
            let gray = image.into_luma16();
            let list: Vec<u32> = gray
                .into_raw()
                .into_iter()
                .enumerate()
                .filter(|(_, v)| *v != 0)
                .map(|(i, _)| i as u32)
                .collect();
            pixels.insert(id, list);
        }
    } else if rle_count > 0 {
        source = format!("{} (rle)", instances_path.display());
        for (i, entry) in instances.iter().enumerate() {
            let Some(rle) = &entry.rle else {
                return Err(LiftError::input(
                    &instances_path,
                    &format!("instances[{i}].rle"),
                    "is missing while other instances have one",
                    "an RLE mask for every instance",
                ));
            };
            let rle_error = |e: super::rle::RleError| {
                LiftError::input(
                    &instances_path,
                    &format!("instances[{i}].rle"),
                    e.to_string(),
                    "COCO RLE: {\"size\": [h, w], \"counts\": [...] or \"...\"}",
                )
            };
            // The size first: a mask of another size is refused before its runs are decoded.
            let (h, w) = super::rle::size(rle).map_err(rle_error)?;
            check_size(&instances_path, w, h, width, height)?;
            let mask = super::rle::decode(rle).map_err(rle_error)?;
            pixels.insert(entry.id, mask.pixels);
        }
    } else {
        return Err(LiftError::input(
            input,
            "masks",
            "no masks (masks.png, masks/<id>.png or RLE in instances.json)",
            "add instance masks",
        ));
    }
    for entry in instances {
        match pixels.get(&entry.id) {
            None => {
                return Err(LiftError::input(
                    &instances_path,
                    &format!("id {}", entry.id),
                    format!(
                        "instance {} (\"{}\") has no mask in {source}",
                        entry.id, entry.label
                    ),
                    "add its mask, or remove it from instances.json",
                ))
            }
            Some(list) if list.is_empty() => {
                return Err(LiftError::input(
                    &instances_path,
                    &format!("id {}", entry.id),
                    format!(
                        "the mask of instance {} (\"{}\") is empty",
                        entry.id, entry.label
                    ),
                    "remove the instance or fix its mask",
                ))
            }
            Some(_) => {}
        }
    }
    Ok(Masks {
        pixels,
        len: width * height,
        source,
    })
}

/// The pixels of each non-zero label of a label image, in row-major order. Labels come in runs
/// along rows, so the image is walked run by run: a count per label, then each list filled at
/// its exact size by whole runs (a map lookup, or even a counter's increment, per pixel cost
/// more than the rest of the masks' reading together).
fn label_lists<T: Copy + PartialEq + Into<u32>>(labels: &[T]) -> BTreeMap<u32, Vec<u32>> {
    fn for_each_run<T: Copy + PartialEq + Into<u32>>(
        labels: &[T],
        mut f: impl FnMut(usize, usize, usize),
    ) {
        let mut start = 0;
        while start < labels.len() {
            let end = run_end(labels, start);
            f(labels[start].into() as usize, start, end);
            start = end;
        }
    }
    let mut counts: Vec<usize> = Vec::new();
    for_each_run(labels, |id, start, end| {
        if id >= counts.len() {
            counts.resize(id + 1, 0);
        }
        counts[id] += end - start;
    });
    if let Some(background) = counts.first_mut() {
        *background = 0;
    }
    let mut lists: Vec<Vec<u32>> = counts.iter().map(|&n| Vec::with_capacity(n)).collect();
    for_each_run(labels, |id, start, end| {
        if id != 0 {
            lists[id].extend(start as u32..end as u32);
        }
    });
    lists
        .into_iter()
        .enumerate()
        .filter(|(id, list)| *id != 0 && !list.is_empty())
        .map(|(id, list)| (id as u32, list))
        .collect()
}

/// The end of the run of equal labels that starts at `start`: blocks of 32 labels compared
/// with the run's label at once (a loop without an exit, which the compiler vectorises), then
/// one by one in the block where the run ends. Walking label by label to the run's end was
/// most of the label image's reading.
fn run_end<T: Copy + PartialEq>(labels: &[T], start: usize) -> usize {
    const BLOCK: usize = 32;
    let label = labels[start];
    let mut at = start + 1;
    while let Some(block) = labels.get(at..at + BLOCK) {
        if !block.iter().fold(true, |same, &l| same & (l == label)) {
            break;
        }
        at += BLOCK;
    }
    labels[at..]
        .iter()
        .position(|&l| l != label)
        .map_or(labels.len(), |n| at + n)
}

fn check_size(
    path: &Path,
    w: usize,
    h: usize,
    width: usize,
    height: usize,
) -> Result<(), LiftError> {
    if (w, h) != (width, height) {
        return Err(LiftError::input(
            path,
            "size",
            format!("is {w}×{h} but the depth map is {width}×{height}"),
            "masks, photo and depth of the same size (resize with nearest-neighbour, or re-export)",
        ));
    }
    Ok(())
}

/// Reads the photo as RGB8 at the depth size; `None` when there is no `image.png`.
pub fn read_photo(input: &Path, width: usize, height: usize) -> Result<Option<Photo>, LiftError> {
    let path = input.join("image.png");
    if !path.exists() {
        return Ok(None);
    }
    if let Some(bytes) = rgb8_png(&path, width, height) {
        return Ok(Some(Photo(bytes)));
    }
    let image = read_png(&path, PngLimit::Size(width, height))?;
    check_size(
        &path,
        image.width() as usize,
        image.height() as usize,
        width,
        height,
    )?;
    // An RGB8 image is moved, not copied, into its raw bytes.
    Ok(Some(Photo(image.into_rgb8().into_raw())))
}

/// The bytes of a photo that is an 8-bit RGB PNG (or a palette PNG without transparency, which
/// expands to one) of `width` × `height` pixels, not interlaced, decoded by `png` row by row
/// into one buffer: what [`read_png`] and `into_rgb8` give for it, to the byte, since `image`
/// decodes a PNG with the same crate, settings and calls, without the zeroed 3-byte-a-pixel
/// buffer it decodes into and opening the file once instead of twice (its header is read
/// first, for the size). `None` for anything else (another kind of PNG, another size, not a
/// PNG, a damaged file): the general reader then decodes it, or says what is wrong with it.
fn rgb8_png(path: &Path, width: usize, height: usize) -> Option<Vec<u8>> {
    let file = std::io::BufReader::new(std::fs::File::open(path).ok()?);
    let bytes = width.checked_mul(height)?.checked_mul(3)?;
    // The decoder's own buffers (a row, the inflate window) besides the image.
    let limits = png::Limits {
        bytes: bytes.saturating_add(1 << 20),
    };
    let mut decoder = png::Decoder::new_with_limits(file, limits);
    // `image`'s settings: text chunks read, bit depths under 8 and palettes expanded.
    decoder.set_ignore_text_chunk(false);
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().ok()?;
    let info = reader.info();
    let size = (info.width as usize, info.height as usize);
    let kind = reader.output_color_type();
    if size != (width, height)
        || info.interlaced
        || kind != (png::ColorType::Rgb, png::BitDepth::Eight)
    {
        return None;
    }
    let row = reader.output_line_size(info.width)?;
    if row.checked_mul(height) != Some(bytes) {
        return None;
    }
    let mut rgb = Vec::with_capacity(bytes);
    for _ in 0..height {
        let at = rgb.len();
        rgb.resize(at + row, 0);
        reader.read_row(&mut rgb[at..]).ok()??;
    }
    // Past the last row, the rest of the image data is read and checked, as `image` does.
    match reader.next_row() {
        Ok(None) => Some(rgb),
        _ => None,
    }
}

/// The photo's RGB8 bytes, row-major.
#[derive(Debug, Clone)]
pub struct Photo(Vec<u8>);

impl Photo {
    /// The colour of pixel index `p`.
    pub fn rgb(&self, p: u32) -> [u8; 3] {
        let i = p as usize * 3;
        [self.0[i], self.0[i + 1], self.0[i + 2]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pixel lists of a label image the plain way: a map entry per non-zero pixel.
    fn lists_by_pixel(labels: &[u16]) -> BTreeMap<u32, Vec<u32>> {
        let mut out: BTreeMap<u32, Vec<u32>> = BTreeMap::new();
        for (i, &label) in labels.iter().enumerate() {
            if label != 0 {
                out.entry(u32::from(label)).or_default().push(i as u32);
            }
        }
        out
    }

    #[test]
    fn depth_png_values_are_converted_and_counted_as_one_by_one() {
        // Every 16-bit value, in an order that mixes zeros in, over more than one block; and
        // scales that make some products infinite, zero or negative.
        let units: Vec<u16> = (0..70_000u32)
            .map(|i| {
                if i % 7 == 0 {
                    0
                } else {
                    (i * 40_503 % 65_536) as u16
                }
            })
            .collect();
        for scale in [1e-3f32, 1.0, 1e36, 0.0, -1e-3, f32::MIN_POSITIVE / 4.0] {
            let (values, valid) = valid_metres(&units, scale);
            let expected: Vec<f32> = units
                .iter()
                .map(|&v| {
                    let d = if v == 0 {
                        f32::NAN
                    } else {
                        f32::from(v) * scale
                    };
                    if d.is_finite() && d > 0.0 {
                        d
                    } else {
                        f32::NAN
                    }
                })
                .collect();
            let bits = |v: &[f32]| v.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&values), bits(&expected), "scale {scale}");
            assert_eq!(
                valid,
                expected.iter().filter(|d| !d.is_nan()).count(),
                "scale {scale}"
            );
        }
    }

    #[test]
    fn label_lists_by_runs_are_the_lists_by_pixel() {
        // Runs of every length (1 included), labels up to 65535, a label that ends the image.
        let mut state = 0x9e37_79b9_7f4a_7c15_u64;
        let mut labels = Vec::new();
        while labels.len() < 20_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let label = match state % 5 {
                0 => 0,
                1 => 65_535,
                _ => (state >> 40) as u16 % 7,
            };
            // Runs shorter and longer than the 32-label blocks of `run_end`, and of many blocks.
            let run = 1 + (state >> 20) as usize % if state % 3 == 0 { 300 } else { 40 };
            labels.extend(std::iter::repeat_n(label, run));
        }
        labels.push(3);
        assert_eq!(label_lists(&labels), lists_by_pixel(&labels));
        let bytes: Vec<u8> = labels.iter().map(|&l| (l % 251) as u8).collect();
        let wide: Vec<u16> = bytes.iter().map(|&b| u16::from(b)).collect();
        assert_eq!(label_lists(&bytes), lists_by_pixel(&wide));
        // Control: the comparison sees a pixel moved from one label to another.
        let mut moved = labels.clone();
        let at = moved.iter().position(|&l| l == 3).expect("a 3");
        moved[at] = 4;
        assert_ne!(label_lists(&moved), lists_by_pixel(&labels));
        assert!(label_lists::<u8>(&[]).is_empty());
    }

    /// A depth.npy of `shape` with the given data bytes after numpy's own header.
    fn npy(shape: &str, data: &[u8]) -> Vec<u8> {
        npy_ordered(shape, false, data)
    }

    /// [`npy`] with the data in Fortran (column-major) order when `fortran`.
    fn npy_ordered(shape: &str, fortran: bool, data: &[u8]) -> Vec<u8> {
        let order = if fortran { "True" } else { "False" };
        let mut header =
            format!("{{'descr': '<f4', 'fortran_order': {order}, 'shape': {shape}, }}");
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(header.len() as u16).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn a_depth_header_asking_for_terabytes_is_refused_unread() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.npy");
        // 10^12 float32 values: ndarray-npy would allocate 4 TB before reading the 16 bytes.
        std::fs::write(&path, npy("(1000000, 1000000)", &[0; 16])).expect("write");
        let e = read_npy_depth(&path).expect_err("refused").to_string();
        assert!(
            e.contains("depth.npy: shape: has shape [1000000, 1000000], 4000000000000 bytes"),
            "{e}"
        );
        assert!(e.contains("the file holds 16 bytes of data"), "{e}");
    }

    #[test]
    fn a_slightly_truncated_depth_keeps_ndarray_npys_message() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.npy");
        std::fs::write(&path, npy("(2, 3)", &[0; 20])).expect("write");
        let e = read_npy_depth(&path).expect_err("refused").to_string();
        assert!(
            e.contains("is not a float32/float64 .npy array: reached EOF before reading all data"),
            "{e}"
        );
        std::fs::write(&path, npy("(2, 3)", &1f32.to_le_bytes().repeat(6))).expect("write");
        let (w, h, values) = read_npy_depth(&path).expect("reads");
        assert_eq!((w, h, values), (3, 2, vec![1.0; 6]));
    }

    #[test]
    fn depth_values_come_in_row_major_order_whatever_the_files_order() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("depth.npy");
        let bytes =
            |values: &[f32]| -> Vec<u8> { values.iter().flat_map(|v| v.to_le_bytes()).collect() };
        // The 2×3 array [[1, 2, 3], [4, 5, 6]], stored row by row and column by column.
        let row_major = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        std::fs::write(&path, npy_ordered("(2, 3)", false, &bytes(&row_major))).expect("write");
        assert_eq!(
            read_npy_depth(&path).expect("C order"),
            (3, 2, row_major.to_vec())
        );
        let column_major = [1.0, 4.0, 2.0, 5.0, 3.0, 6.0];
        std::fs::write(&path, npy_ordered("(2, 3)", true, &bytes(&column_major))).expect("write");
        assert_eq!(
            read_npy_depth(&path).expect("F order"),
            (3, 2, row_major.to_vec())
        );
        // An H×W×1 array reads as H×W, and one row or one column is the same either way.
        std::fs::write(&path, npy_ordered("(2, 3, 1)", true, &bytes(&column_major)))
            .expect("write");
        assert_eq!(
            read_npy_depth(&path).expect("F order, 3-d"),
            (3, 2, row_major.to_vec())
        );
        std::fs::write(&path, npy_ordered("(1, 3)", true, &bytes(&[7.0, 8.0, 9.0])))
            .expect("write");
        assert_eq!(
            read_npy_depth(&path).expect("one row"),
            (3, 1, vec![7.0, 8.0, 9.0])
        );
    }

    #[test]
    fn a_background_sample_is_every_step_th_background_pixel() {
        // Overlapping masks (per-instance mask files may overlap) over a 97-pixel image.
        let masks = Masks {
            pixels: BTreeMap::from([
                (1, vec![0, 1, 2, 10, 11, 50]),
                (2, vec![2, 3, 50, 51, 96]),
                (3, (60..80).collect()),
            ]),
            len: 97,
            source: String::new(),
        };
        let background = masks.background();
        assert_eq!(background.len(), 97 - 6 - 3 - 20);
        for at_most in [1, 2, 5, 7, 30, 67, 68, 1000] {
            let step = background.len().div_ceil(at_most).max(1);
            let expected: Vec<u32> = background.iter().copied().step_by(step).collect();
            assert!(expected.len() <= at_most, "{at_most}");
            assert_eq!(
                masks.background_sample(at_most),
                expected,
                "at most {at_most}"
            );
        }
        // Control: counting a pixel covered twice twice changes the step, and the sample.
        // (68 background pixels, 66 if the two pixels of two masks counted twice: at most 33,
        // a step of 3, not 2.)
        let step_if_counted_twice = (97 - 31usize).div_ceil(33);
        assert_eq!(step_if_counted_twice, 2);
        let wrong: Vec<u32> = background
            .iter()
            .copied()
            .step_by(step_if_counted_twice)
            .collect();
        assert_ne!(masks.background_sample(33), wrong);
        // Nothing covered, and everything covered.
        let empty = Masks {
            pixels: BTreeMap::new(),
            len: 10,
            source: String::new(),
        };
        assert_eq!(empty.background_sample(4), vec![0, 3, 6, 9]);
        let full = Masks {
            pixels: BTreeMap::from([(1, (0..10).collect())]),
            len: 10,
            source: String::new(),
        };
        assert!(full.background_sample(4).is_empty());
    }
}

/// [`read_depth_png`] against the general reader (here, not beside it: the reader's module
/// does not import this one).
#[cfg(test)]
mod depth_png_tests {
    use super::*;
    use crate::image_io::inflated_image_data;
    use png::{BitDepth, ColorType, Filter};
    use rand::{Rng, SeedableRng};

    const SCALE: f32 = 0.001;

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

    /// [`read_depth_png`]'s values, as [`read_depth`] takes them.
    fn through_rows(path: &Path) -> Result<Option<Read>, LiftError> {
        Ok(depth_png_metres(path, u64::MAX, SCALE)?.map(|d| {
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
        let message = match depth_png_metres(&path, 1 << 20, SCALE) {
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

#[cfg(test)]
mod photo_tests {
    use super::*;
    use png::{BitDepth, ColorType, Filter};
    use rand::{Rng, SeedableRng};

    /// A kind of PNG the photo reader is given: the colour type and bit depth, the samples,
    /// the `tRNS` chunk if any, and whether the fast path reads it.
    type Kind<'a> = ((ColorType, BitDepth), &'a [u8], Option<&'a [u8]>, bool);

    /// The palette of the indexed PNGs: black, red, green and a grey.
    const PALETTE: [u8; 12] = [0, 0, 0, 255, 0, 0, 0, 255, 0, 9, 8, 7];

    /// A PNG of `data` (rows of the colour type's samples), every row filtered with `filter`;
    /// an indexed one with [`PALETTE`]; with a `tRNS` chunk when `trns` is given.
    fn encode(
        (width, height): (u32, u32),
        (color, depth): (ColorType, BitDepth),
        data: &[u8],
        filter: Filter,
        trns: Option<&[u8]>,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        let mut encoder = png::Encoder::new(&mut out, width, height);
        encoder.set_color(color);
        encoder.set_depth(depth);
        encoder.set_filter(filter);
        if color == ColorType::Indexed {
            encoder.set_palette(PALETTE.to_vec());
        }
        if let Some(trns) = trns {
            encoder.set_trns(trns.to_vec());
        }
        let mut writer = encoder.write_header().expect("header");
        writer.write_image_data(data).expect("data");
        writer.finish().expect("end");
        out
    }

    /// The general reader's bytes: `image`'s decoding, then `into_rgb8`.
    fn through_image(path: &Path, size: (usize, usize)) -> Result<Vec<u8>, String> {
        read_png(path, PngLimit::Size(size.0, size.1))
            .map(|image| image.into_rgb8().into_raw())
            .map_err(|e| e.to_string())
    }

    fn photo_bytes(path: &Path, size: (usize, usize)) -> Result<Vec<u8>, String> {
        match read_photo(path.parent().expect("folder"), size.0, size.1) {
            Ok(photo) => Ok(photo.expect("a photo").0),
            Err(e) => Err(e.to_string()),
        }
    }

    #[test]
    fn rgb_photos_are_read_as_image_reads_them() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("image.png");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let filters = [
            Filter::NoFilter,
            Filter::Sub,
            Filter::Up,
            Filter::Avg,
            Filter::Paeth,
            Filter::Adaptive,
        ];
        let mut fast = 0;
        for (width, height) in [(1, 1), (5, 3), (64, 17), (257, 9)] {
            let size = (width as usize, height as usize);
            let pixels = size.0 * size.1;
            // Noise, and smooth gradients (where Paeth's neighbours differ).
            let noise: Vec<u8> = (0..3 * pixels).map(|_| rng.random()).collect();
            let smooth: Vec<u8> = (0..3 * pixels)
                .map(|i| ((i / 3 % size.0) * 3 + (i / 3 / size.0) * 5 + i % 3) as u8)
                .collect();
            let palette: Vec<u8> = (0..pixels).map(|_| rng.random_range(0..4)).collect();
            let rgba: Vec<u8> = (0..4 * pixels).map(|_| rng.random()).collect();
            let grey16: Vec<u8> = (0..2 * pixels).map(|_| rng.random()).collect();
            for filter in filters {
                const RGB8: (ColorType, BitDepth) = (ColorType::Rgb, BitDepth::Eight);
                const INDEXED: (ColorType, BitDepth) = (ColorType::Indexed, BitDepth::Eight);
                let kinds: [Kind; 7] = [
                    (RGB8, &noise, None, true),
                    (RGB8, &smooth, None, true),
                    // A palette without transparency expands to RGB; with it, to RGBA.
                    (INDEXED, &palette, None, true),
                    (INDEXED, &palette, Some(&[0, 128]), false),
                    ((ColorType::Rgba, BitDepth::Eight), &rgba, None, false),
                    (
                        (ColorType::Grayscale, BitDepth::Sixteen),
                        &grey16,
                        None,
                        false,
                    ),
                    (RGB8, &noise, Some(&[0, 1, 0, 2, 0, 3]), false),
                ];
                for (k, &(kind, data, trns, rgb8)) in kinds.iter().enumerate() {
                    let file = encode((width, height), kind, data, filter, trns);
                    std::fs::write(&path, &file).expect("write");
                    let expected = through_image(&path, size).expect("image reads it");
                    assert_eq!(
                        rgb8_png(&path, size.0, size.1).is_some(),
                        rgb8,
                        "kind {k}, {filter:?}, {size:?}: which reader"
                    );
                    fast += usize::from(rgb8);
                    assert_eq!(
                        photo_bytes(&path, size),
                        Ok(expected),
                        "kind {k}, {filter:?}"
                    );
                }
            }
        }
        // The control: the fast path was taken (else the comparison says nothing of it).
        assert_eq!(fast, 4 * 6 * 3);
    }

    #[test]
    fn damaged_or_other_photos_go_to_the_general_reader() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("image.png");
        let size = (40usize, 30usize);
        let data: Vec<u8> = (0..3 * size.0 * size.1)
            .map(|i| (i * 7 % 251) as u8)
            .collect();
        let rgb8 = (ColorType::Rgb, BitDepth::Eight);
        let file = encode((40, 30), rgb8, &data, Filter::Paeth, None);
        std::fs::write(&path, &file).expect("write");
        assert!(
            rgb8_png(&path, size.0, size.1).is_some(),
            "the control reads"
        );
        // Another size than the depth map's: the general reader names it.
        assert!(rgb8_png(&path, 41, 30).is_none());
        let wrong = photo_bytes(&path, (41, 30));
        assert!(wrong.is_err(), "{wrong:?}");
        assert_eq!(wrong, through_image(&path, (41, 30)));
        // Cut short: within the image data both refuse it; within the end chunk, after the
        // image data, `image` reads it, and so does the photo reader (it reads as far as
        // `image` does).
        for (cut, readable) in [(file.len() - 1, true), (file.len() / 2, false), (40, false)] {
            std::fs::write(&path, &file[..cut]).expect("write");
            assert_eq!(
                rgb8_png(&path, size.0, size.1).is_some(),
                readable,
                "cut at {cut}"
            );
            let general = through_image(&path, size);
            assert_eq!(general.is_ok(), readable, "cut at {cut}");
            assert_eq!(photo_bytes(&path, size), general, "cut at {cut}");
        }
        // A byte of the image data changed (its chunk's CRC no longer matches).
        let mut damaged = file.clone();
        let at = damaged.len() / 2;
        damaged[at] ^= 0x40;
        std::fs::write(&path, &damaged).expect("write");
        assert!(rgb8_png(&path, size.0, size.1).is_none());
        assert_eq!(photo_bytes(&path, size), through_image(&path, size));
        // Not a PNG: a JPEG under the name is the general reader's too.
        let mut jpeg = Vec::new();
        image::RgbImage::from_raw(40, 30, data.clone())
            .expect("image")
            .write_to(
                &mut std::io::Cursor::new(&mut jpeg),
                image::ImageFormat::Jpeg,
            )
            .expect("jpeg");
        std::fs::write(&path, &jpeg).expect("write");
        assert!(rgb8_png(&path, size.0, size.1).is_none());
        assert_eq!(photo_bytes(&path, size), through_image(&path, size));
    }
}

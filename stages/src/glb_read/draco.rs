//! `KHR_draco_mesh_compression`: a primitive whose geometry is a Draco stream in a buffer view,
//! decoded with `draco-oxide-decoder` (a pure-Rust port of Google's decoder).
//!
//! The extension maps glTF attribute names to Draco attribute unique ids
//! (`"attributes": {"POSITION": 1}`); the decoder keeps those ids, so POSITION is found by id,
//! not by order. The stream's faces are the primitive's triangles (the extension allows only
//! TRIANGLES and TRIANGLE_STRIP, and a decoded Draco mesh is always a triangle list).

use draco_oxide_core::attribute::ComponentDataType;
use serde_json::Value;

use super::accessor::Buffers;
use super::GlbError;

/// How to fix an asset whose Draco stream cannot be decoded.
pub(crate) const DRACO_FIX: &str = "re-export it without Draco compression (Blender's glTF \
     exporter: untick Data > Compression; glTF-Transform: read and write it with the Draco \
     extension unregistered)";

/// The decoded geometry of one Draco-compressed primitive.
pub(crate) struct DracoPrimitive {
    /// Vertex positions (as stored: the primitive's local frame).
    pub positions: Vec<[f64; 3]>,
    /// Triangles as indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
    /// The other attributes asked for that the stream holds as floats, by glTF name
    /// (`NORMAL`, `TEXCOORD_0`, ...): one element of `width` values per point, flattened.
    pub extra: Vec<(String, Vec<f64>, usize)>,
}

fn draco_error(path: &str, problem: impl Into<String>) -> GlbError {
    GlbError::Draco {
        path: path.to_owned(),
        problem: problem.into(),
    }
}

/// Decodes the Draco stream of a primitive whose `extensions.KHR_draco_mesh_compression` is
/// `extension`.
#[cfg(test)]
pub(crate) fn decode_primitive(
    root: &gltf_json::Root,
    buffers: &Buffers<'_>,
    extension: &Value,
    path: &str,
) -> Result<DracoPrimitive, GlbError> {
    decode_primitive_with(root, buffers, extension, path, &[], &|_| false)
}

/// [`decode_primitive`], also returning the attributes named in `wanted` (glTF attribute
/// names) that the stream holds as 32-bit floats (and NORMAL and TEXCOORD_n also as 8- or
/// 16-bit integers, `KHR_mesh_quantization`); others are left out. `normalized(name)` is the
/// `normalized` flag of the accessor of attribute `name`: the extension's accessors describe
/// the decoded data, so a normalized integer attribute is mapped to [0, 1] or [-1, 1] as
/// glTF 2.0 §3.11 says, and the node transform carries the rest of the dequantization.
pub(crate) fn decode_primitive_with(
    root: &gltf_json::Root,
    buffers: &Buffers<'_>,
    extension: &Value,
    path: &str,
    wanted: &[&str],
    normalized: &dyn Fn(&str) -> bool,
) -> Result<DracoPrimitive, GlbError> {
    let view_index = extension
        .get("bufferView")
        .and_then(Value::as_u64)
        .ok_or_else(|| draco_error(path, "the extension has no bufferView"))?
        as usize;
    let position_id = extension
        .get("attributes")
        .and_then(|a| a.get("POSITION"))
        .and_then(Value::as_u64)
        .ok_or_else(|| draco_error(path, "the extension maps no POSITION attribute"))?
        as usize;
    let view = root
        .buffer_views
        .get(view_index)
        .ok_or_else(|| draco_error(path, format!("bufferView {view_index} does not exist")))?;
    let buffer_index = view.buffer.value();
    let data = buffers
        .data
        .get(buffer_index)
        .and_then(|d| d.as_deref())
        .ok_or_else(|| draco_error(path, format!("buffer {buffer_index} has no data")))?;
    let start = view.byte_offset.map_or(0, |o| o.0) as usize;
    let len = view.byte_length.0 as usize;
    let stream = start
        .checked_add(len)
        .and_then(|end| data.get(start..end))
        .ok_or_else(|| {
            draco_error(
                path,
                format!(
                    "bufferView {view_index} spans bytes {start}..{} of a buffer of {} bytes",
                    start.saturating_add(len),
                    data.len()
                ),
            )
        })?;
    // The decoder is an alpha: a malformed stream must not take the whole run down.
    let decoded =
        std::panic::catch_unwind(|| draco_oxide_decoder::Decoder::new().decode_mesh(stream))
            .map_err(|_| draco_error(path, "the Draco decoder failed on this stream"))?
            .map_err(|e| draco_error(path, e.to_string()))?;
    let attribute = decoded
        .get_attributes()
        .iter()
        .find(|a| a.get_id().as_usize() == position_id)
        .ok_or_else(|| {
            draco_error(
                path,
                format!("the stream has no attribute with the POSITION id {position_id}"),
            )
        })?;
    let positions: Vec<[f64; 3]> = match attribute_values(attribute, normalized("POSITION")) {
        Some((values, 3)) => values.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        _ => {
            return Err(draco_error(
                path,
                format!(
                    "POSITION decodes to {} components of {:?} (expected 3 floats, or 3 8- or \
                     16-bit integers with KHR_mesh_quantization)",
                    attribute.get_num_components(),
                    attribute.get_component_type()
                ),
            ))
        }
    };
    let points = positions.len();
    let mut triangles = Vec::with_capacity(decoded.faces.len());
    for face in &decoded.faces {
        let mut tri = [0u32; 3];
        for (slot, corner) in tri.iter_mut().zip(face.iter()) {
            let index = usize::from(*corner);
            if index >= points {
                return Err(draco_error(
                    path,
                    format!("a face refers to point {index} of {points}"),
                ));
            }
            // Bounded by `points`, a usize from a Vec length.
            *slot = u32::try_from(index).map_err(|_| draco_error(path, "more than 2^32 points"))?;
        }
        triangles.push(tri);
    }
    let mut extra = Vec::new();
    for name in wanted {
        let Some(id) = extension
            .get("attributes")
            .and_then(|a| a.get(*name))
            .and_then(Value::as_u64)
        else {
            continue;
        };
        let Some(attribute) = decoded
            .get_attributes()
            .iter()
            .find(|a| a.get_id().as_usize() as u64 == id)
        else {
            continue;
        };
        // Integer NORMAL and TEXCOORD_n are KHR_mesh_quantization's; other integer attributes
        // (colours, joints) are left to the uncompressed readers, as before.
        let quantizable = *name == "NORMAL" || name.starts_with("TEXCOORD_");
        if attribute.get_component_type() != ComponentDataType::F32 && !quantizable {
            continue;
        }
        if attribute.len() != points {
            continue;
        }
        if let Some((values, width)) = attribute_values(attribute, normalized(name)) {
            if (2..=4).contains(&width) && values.len() == points * width {
                extra.push(((*name).to_owned(), values, width));
            }
        }
    }
    Ok(DracoPrimitive {
        positions,
        triangles,
        extra,
    })
}

/// An attribute's value at every point as f64, flattened, and its components per point:
/// floats as they are, integers as their value or, when `normalized`, mapped to [0, 1]
/// (unsigned) or [-1, 1] (signed, `max(c / (2^(n-1) - 1), -1)`) as glTF 2.0 §3.11 says.
/// `None` for component types glTF has no attribute of (64-bit) or a point map out of range.
fn attribute_values(
    attribute: &draco_oxide_core::attribute::Attribute,
    normalized: bool,
) -> Option<(Vec<f64>, usize)> {
    let width = attribute.get_num_components();
    let kind = attribute.get_component_type();
    let (size, max) = match kind {
        ComponentDataType::F32 => (4, None),
        ComponentDataType::I8 => (1, Some(127.0)),
        ComponentDataType::U8 => (1, Some(255.0)),
        ComponentDataType::I16 => (2, Some(32767.0)),
        ComponentDataType::U16 => (2, Some(65535.0)),
        ComponentDataType::U32 | ComponentDataType::I32 => (4, None),
        _ => return None,
    };
    if width == 0 {
        return None;
    }
    let bytes = attribute.get_data_as_bytes();
    let stride = size * width;
    let stored = bytes.len() / stride;
    let map = attribute.point_map_as_slice();
    let points = attribute.len();
    let mut out = Vec::with_capacity(points.checked_mul(width)?);
    for point in 0..points {
        let value = match map {
            Some(map) => usize::from(*map.get(point)?),
            None => point,
        };
        if value >= stored {
            return None;
        }
        for c in 0..width {
            let at = value * stride + c * size;
            let b = &bytes[at..at + size];
            let x = match kind {
                ComponentDataType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                ComponentDataType::U32 => f64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                ComponentDataType::I32 => f64::from(i32::from_le_bytes([b[0], b[1], b[2], b[3]])),
                ComponentDataType::I16 => f64::from(i16::from_le_bytes([b[0], b[1]])),
                ComponentDataType::U16 => f64::from(u16::from_le_bytes([b[0], b[1]])),
                ComponentDataType::I8 => f64::from(b[0] as i8),
                _ => f64::from(b[0]),
            };
            out.push(match (normalized, max) {
                (true, Some(max)) => (x / max).max(-1.0),
                _ => x,
            });
        }
    }
    Some((out, width))
}

#[cfg(test)]
mod tests {
    use super::*;
    use sha2::{Digest, Sha256};

    use crate::shared_glb as glb;

    /// The Draco primitives of a GLB, decoded in file order.
    fn decode_all(bytes: &[u8]) -> Vec<DracoPrimitive> {
        let chunks = super::super::container::split(bytes, &mut Vec::new()).expect("container");
        let root: gltf_json::Root = serde_json::from_slice(chunks.json).expect("json");
        let buffers = Buffers {
            data: vec![chunks.bin.map(std::borrow::Cow::Borrowed)],
        };
        let mut out = Vec::new();
        for (m, mesh) in root.meshes.iter().enumerate() {
            for (p, primitive) in mesh.primitives.iter().enumerate() {
                let extension = primitive
                    .extensions
                    .as_ref()
                    .and_then(|e| e.others.get("KHR_draco_mesh_compression"))
                    .expect("a Draco primitive");
                let path = format!("meshes[{m}].primitives[{p}]");
                out.push(decode_primitive(&root, &buffers, extension, &path).expect("decodes"));
            }
        }
        out
    }

    /// A digest of a triangle soup that does not depend on vertex numbering: each triangle as
    /// its three f32 corner positions, rotated to start at the smallest corner (orientation
    /// kept), sorted.
    fn soup_digest(primitive: &DracoPrimitive) -> String {
        let mut triangles: Vec<Vec<u8>> = primitive
            .triangles
            .iter()
            .map(|t| {
                let corners: Vec<Vec<u8>> = t
                    .iter()
                    .map(|i| {
                        primitive.positions[*i as usize]
                            .iter()
                            // Decoded as f32: the conversion back is exact.
                            .flat_map(|v| (*v as f32).to_le_bytes())
                            .collect()
                    })
                    .collect();
                let first = (0..3).min_by_key(|r| &corners[*r]).unwrap_or(0);
                (0..3)
                    .flat_map(|r| corners[(first + r) % 3].clone())
                    .collect()
            })
            .collect();
        triangles.sort();
        let digest = Sha256::digest(triangles.concat());
        digest.iter().take(8).map(|b| format!("{b:02x}")).collect()
    }

    /// Face counts and triangle-soup digests of Google's own decoder (draco3d 1.5.7, the
    /// reference WASM build, run on the same files): draco-oxide must give the same triangles
    /// with bit-identical positions. A change here means the decoder changed its output.
    #[test]
    fn draco_primitives_match_googles_decoder() {
        let cases: [(&str, &[(usize, &str)]); 2] = [
            ("Box_Draco.glb", &[(12, "6ba7527046413ec1")]),
            (
                "laptop_blender_draco.glb",
                &[
                    (312, "1691fd863b476a11"),
                    (183, "ec80b02f9b9e1f15"),
                    (214, "8045f31936917004"),
                    (22544, "3abc95abf9c6b439"),
                    (311, "b26c234828a5858c"),
                    (8, "863b67282b05fd17"),
                    (206, "1813f194ee69f894"),
                    (384, "4cb9aa092f028156"),
                    (20928, "f82e000b07daee3a"),
                    (8449, "248f67c4900b6809"),
                    (35472, "79c2a923ce33fb98"),
                ],
            ),
        ];
        for (file, expected) in cases {
            let decoded = decode_all(&glb(file));
            assert_eq!(decoded.len(), expected.len(), "{file}");
            for (i, (primitive, (faces, digest))) in decoded.iter().zip(expected).enumerate() {
                assert_eq!(primitive.triangles.len(), *faces, "{file} primitive {i}");
                assert_eq!(soup_digest(primitive), *digest, "{file} primitive {i}");
            }
        }
    }
}

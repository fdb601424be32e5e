//! Accessor reading with every offset checked against the data actually present: dense
//! accessors (any `byteStride`), accessors without a buffer view (zeros), sparse accessors,
//! every component type, normalized integers.

use std::borrow::Cow;

use gltf_json::accessor::{ComponentType, Type};
use gltf_json::validation::Checked;
use gltf_json::Root;

use super::GlbError;

/// The bytes of each buffer: the BIN chunk, a data URI, or nothing (a placeholder buffer).
pub(crate) struct Buffers<'a> {
    pub data: Vec<Option<Cow<'a, [u8]>>>,
}

fn data_error(path: impl Into<String>, problem: impl Into<String>) -> GlbError {
    GlbError::Data {
        path: path.into(),
        problem: problem.into(),
    }
}

/// Components per element of an accessor type.
pub(crate) fn components(kind: Type) -> usize {
    match kind {
        Type::Scalar => 1,
        Type::Vec2 => 2,
        Type::Vec3 => 3,
        Type::Vec4 | Type::Mat2 => 4,
        Type::Mat3 => 9,
        Type::Mat4 => 16,
    }
}

fn component_size(kind: ComponentType) -> usize {
    match kind {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// Reads one component at `bytes[0..size]`, mapping normalized integers to [0, 1] / [-1, 1]
/// as the glTF specification says.
fn component(bytes: &[u8], kind: ComponentType, normalized: bool) -> f64 {
    match kind {
        ComponentType::F32 => {
            f64::from(f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
        }
        ComponentType::U32 => {
            f64::from(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]))
        }
        ComponentType::U16 => {
            let v = f64::from(u16::from_le_bytes([bytes[0], bytes[1]]));
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        ComponentType::I16 => {
            let v = f64::from(i16::from_le_bytes([bytes[0], bytes[1]]));
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        ComponentType::U8 => {
            let v = f64::from(bytes[0]);
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        ComponentType::I8 => {
            let v = f64::from(bytes[0] as i8);
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
    }
}

/// The byte range `[start, start + len)` of a buffer view inside its buffer's data, checked.
pub(crate) fn view_bytes<'b>(
    root: &Root,
    buffers: &'b Buffers<'_>,
    view_index: usize,
    path: &str,
) -> Result<(&'b [u8], Option<usize>), GlbError> {
    let view = root.buffer_views.get(view_index).ok_or_else(|| {
        data_error(
            path,
            format!(
                "bufferView {view_index} does not exist ({} views)",
                root.buffer_views.len()
            ),
        )
    })?;
    let buffer_index = view.buffer.value();
    let data = match buffers.data.get(buffer_index) {
        Some(Some(data)) => data.as_ref(),
        Some(None) => {
            let meshopt = view
                .extensions
                .as_ref()
                .is_some_and(|e| e.others.contains_key("EXT_meshopt_compression"));
            if meshopt {
                return Err(GlbError::UnsupportedExtension {
                    extension: "EXT_meshopt_compression".to_owned(),
                    fix: super::MESHOPT_FIX,
                });
            }
            return Err(data_error(
                path,
                format!(
                    "bufferView {view_index} reads buffer {buffer_index}, which has no data (a \
                     buffer without uri other than the first has no bytes in a GLB)"
                ),
            ));
        }
        None => {
            return Err(data_error(
                path,
                format!(
                    "bufferView {view_index} reads buffer {buffer_index}, which does not exist"
                ),
            ))
        }
    };
    let start = view.byte_offset.map_or(0, |o| o.0) as usize;
    let len = view.byte_length.0 as usize;
    let bytes = start
        .checked_add(len)
        .and_then(|end| data.get(start..end))
        .ok_or_else(|| {
            data_error(
                path,
                format!(
                    "bufferView {view_index} spans bytes {start}..{} of buffer {buffer_index}, \
                     which has {} bytes",
                    start.saturating_add(len),
                    data.len()
                ),
            )
        })?;
    Ok((bytes, view.byte_stride.map(|s| s.0)))
}

/// Reads `count` elements of `width` components each from a view, starting at `offset`.
#[allow(clippy::too_many_arguments)]
fn read_dense(
    bytes: &[u8],
    stride: Option<usize>,
    offset: usize,
    count: usize,
    width: usize,
    kind: ComponentType,
    normalized: bool,
    path: &str,
) -> Result<Vec<f64>, GlbError> {
    let size = component_size(kind);
    let element = size * width;
    let stride = stride.unwrap_or(element);
    if stride < element {
        return Err(data_error(
            path,
            format!("byteStride {stride} is smaller than one element ({element} bytes)"),
        ));
    }
    if count > 0 {
        let last = (count - 1)
            .checked_mul(stride)
            .and_then(|v| v.checked_add(offset))
            .and_then(|v| v.checked_add(element));
        match last {
            Some(end) if end <= bytes.len() => {}
            _ => {
                return Err(data_error(
                    path,
                    format!(
                        "{count} elements of {element} bytes every {stride} bytes from byte \
                         {offset} overrun the bufferView ({} bytes)",
                        bytes.len()
                    ),
                ))
            }
        }
    }
    // One loop per component type, so that the common case (floats) is a plain copy.
    Ok(match kind {
        ComponentType::F32 => gather::<4>(bytes, stride, offset, count, width, |b| {
            f64::from(f32::from_le_bytes(b))
        }),
        ComponentType::U32 | ComponentType::I16 | ComponentType::U16 if !normalized => match size {
            4 => gather::<4>(bytes, stride, offset, count, width, |b| {
                component(&b, kind, false)
            }),
            _ => gather::<2>(bytes, stride, offset, count, width, |b| {
                component(&b, kind, false)
            }),
        },
        _ => {
            let mut out = Vec::with_capacity(count * width);
            for i in 0..count {
                let at = offset + i * stride;
                for c in 0..width {
                    let s = at + c * size;
                    out.push(component(&bytes[s..s + size], kind, normalized));
                }
            }
            out
        }
    })
}

/// `count` elements of `width` components of `N` bytes each, every `stride` bytes from
/// `offset` (checked by the caller), each component converted by `convert`.
fn gather<const N: usize>(
    bytes: &[u8],
    stride: usize,
    offset: usize,
    count: usize,
    width: usize,
    convert: impl Fn([u8; N]) -> f64,
) -> Vec<f64> {
    let mut out = Vec::with_capacity(count * width);
    for i in 0..count {
        let at = offset + i * stride;
        let element = &bytes[at..at + N * width];
        out.extend(
            element
                .chunks_exact(N)
                .map(|c| convert(c.try_into().expect("N bytes"))),
        );
    }
    out
}

/// An accessor's elements as f64, flattened (`count × components` values), and the number of
/// components per element.
pub(crate) fn read_accessor(
    root: &Root,
    buffers: &Buffers<'_>,
    index: usize,
    path: &str,
) -> Result<(Vec<f64>, usize), GlbError> {
    let accessor = root.accessors.get(index).ok_or_else(|| {
        data_error(
            path,
            format!(
                "accessor {index} does not exist ({} accessors)",
                root.accessors.len()
            ),
        )
    })?;
    let here = format!("{path} (accessor {index})");
    let kind = match accessor.component_type {
        Checked::Valid(t) => t.0,
        Checked::Invalid => return Err(data_error(&here, "invalid componentType")),
    };
    let shape = match accessor.type_ {
        Checked::Valid(t) => t,
        Checked::Invalid => return Err(data_error(&here, "invalid type")),
    };
    if matches!(shape, Type::Mat2 | Type::Mat3) && component_size(kind) < 4 {
        // Column padding rules of small matrices: never used by the attributes mesa reads.
        return Err(data_error(
            &here,
            "MAT2/MAT3 of 8- or 16-bit components are not read by mesa",
        ));
    }
    let width = components(shape);
    let count = accessor.count.0 as usize;
    let total = count
        .checked_mul(width)
        .filter(|n| *n <= 1 << 31)
        .ok_or_else(|| data_error(&here, format!("count {count} is too large")))?;
    // Without a bufferView the values are zeros (then sparse values): nothing bounds the
    // count but the JSON, so it is bounded here (64 M values, 512 MB of f64).
    if accessor.buffer_view.is_none() && total > 1 << 26 {
        return Err(data_error(
            &here,
            format!(
                "count {count} without a bufferView is too large (at most {} values)",
                1 << 26
            ),
        ));
    }
    let mut values = match accessor.buffer_view {
        Some(view) => {
            let (bytes, stride) = view_bytes(root, buffers, view.value(), &here)?;
            let offset = accessor.byte_offset.map_or(0, |o| o.0) as usize;
            read_dense(
                bytes,
                stride,
                offset,
                count,
                width,
                kind,
                accessor.normalized,
                &here,
            )?
        }
        None => vec![0.0; total],
    };
    if let Some(sparse) = &accessor.sparse {
        let n = sparse.count.0 as usize;
        if n > count {
            return Err(data_error(
                &here,
                format!("sparse.count {n} exceeds the accessor's count {count}"),
            ));
        }
        let index_kind = match sparse.indices.component_type {
            Checked::Valid(t) => t.0,
            Checked::Invalid => {
                return Err(data_error(&here, "invalid sparse.indices.componentType"))
            }
        };
        let (bytes, _) = view_bytes(
            root,
            buffers,
            sparse.indices.buffer_view.value(),
            &format!("{here}.sparse.indices"),
        )?;
        let indices = read_dense(
            bytes,
            None,
            sparse.indices.byte_offset.0 as usize,
            n,
            1,
            index_kind,
            false,
            &format!("{here}.sparse.indices"),
        )?;
        let (bytes, _) = view_bytes(
            root,
            buffers,
            sparse.values.buffer_view.value(),
            &format!("{here}.sparse.values"),
        )?;
        let replacements = read_dense(
            bytes,
            None,
            sparse.values.byte_offset.0 as usize,
            n,
            width,
            kind,
            accessor.normalized,
            &format!("{here}.sparse.values"),
        )?;
        for (k, target) in indices.iter().enumerate() {
            // Indices are unsigned integers read exactly as f64.
            let target = *target as usize;
            if target >= count {
                return Err(data_error(
                    &here,
                    format!("sparse index {target} is out of range (count {count})"),
                ));
            }
            values[target * width..(target + 1) * width]
                .copy_from_slice(&replacements[k * width..(k + 1) * width]);
        }
    }
    Ok((values, width))
}

/// Reads an index accessor (SCALAR of u8, u16 or u32).
pub(crate) fn read_indices(
    root: &Root,
    buffers: &Buffers<'_>,
    index: usize,
    path: &str,
) -> Result<Vec<u32>, GlbError> {
    let accessor = root.accessors.get(index).ok_or_else(|| {
        data_error(
            path,
            format!(
                "accessor {index} does not exist ({} accessors)",
                root.accessors.len()
            ),
        )
    })?;
    let here = format!("{path} (accessor {index})");
    match (accessor.component_type, accessor.type_) {
        (
            Checked::Valid(gltf_json::accessor::GenericComponentType(
                ComponentType::U8 | ComponentType::U16 | ComponentType::U32,
            )),
            Checked::Valid(Type::Scalar),
        ) => {}
        _ => {
            return Err(data_error(
                &here,
                "indices must be a SCALAR of UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT",
            ))
        }
    }
    let (values, _) = read_accessor(root, buffers, index, path)?;
    // Unsigned integers of at most 32 bits, read exactly as f64.
    Ok(values.into_iter().map(|v| v as u32).collect())
}

//! The GLB container (glTF 2.0 "Binary glTF"): a 12-byte header, a JSON chunk, an optional
//! BIN chunk. Problems carry the Khronos glTF-Validator's issue code, so a report can be
//! compared with the validator's own.

use super::GlbError;

/// The chunks of a GLB file.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Chunks<'a> {
    /// The JSON chunk's bytes (trailing padding spaces included).
    pub json: &'a [u8],
    /// The BIN chunk's bytes, when there is one.
    pub bin: Option<&'a [u8]>,
}

const MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

fn u32_at(bytes: &[u8], offset: usize) -> Option<u32> {
    let slice = bytes.get(offset..offset.checked_add(4)?)?;
    Some(u32::from_le_bytes([slice[0], slice[1], slice[2], slice[3]]))
}

/// The fix of a damaged container.
const DAMAGED_FIX: &str =
    "the file is damaged or was not written completely: re-export or re-download it";

fn container(code: &'static str, offset: usize, problem: String) -> GlbError {
    GlbError::Container {
        code,
        offset,
        problem,
        fix: DAMAGED_FIX,
    }
}

fn chunk_name(kind: u32) -> String {
    match kind {
        CHUNK_JSON => "JSON".to_owned(),
        CHUNK_BIN => "BIN".to_owned(),
        other => format!("0x{other:08x}"),
    }
}

/// Splits a GLB file into its chunks; `warnings` receives what the validator reports as
/// warnings or infos (trailing bytes, unknown chunks, an empty BIN chunk).
///
/// The file is read as the validator reads it, as a stream: chunk headers and data from the
/// bytes present, each chunk's length checked against the declared total length
/// (`GLB_CHUNK_TOO_BIG`) and then against the bytes present
/// (`GLB_UNEXPECTED_END_OF_CHUNK_DATA`); a file that ends at a chunk boundary before its
/// declared length is `GLB_LENGTH_MISMATCH`. The first error the validator reports is the
/// one returned.
pub(crate) fn split<'a>(
    bytes: &'a [u8],
    warnings: &mut Vec<String>,
) -> Result<Chunks<'a>, GlbError> {
    if bytes.len() < 12 {
        if bytes.len() >= 4 && &bytes[..4] != MAGIC {
            return Err(not_glb(bytes));
        }
        return Err(container(
            "GLB_UNEXPECTED_END_OF_HEADER",
            bytes.len(),
            format!(
                "the file has {} bytes, fewer than the 12-byte GLB header",
                bytes.len()
            ),
        ));
    }
    if &bytes[..4] != MAGIC {
        return Err(not_glb(bytes));
    }
    // Checked above: at least 12 bytes.
    let version = u32_at(bytes, 4).unwrap_or(0);
    if version == 1 {
        return Err(GlbError::Container {
            code: "GLB_INVALID_VERSION",
            offset: 4,
            problem: "GLB version 1 is glTF 1.0 (KHR_binary_glTF): mesa reads glTF 2.0".to_owned(),
            fix: GLTF1_FIX,
        });
    }
    if version != 2 {
        return Err(container(
            "GLB_INVALID_VERSION",
            4,
            format!("GLB version {version} (expected 2, glTF 2.0)"),
        ));
    }
    let declared = u32_at(bytes, 8).unwrap_or(0) as usize;
    if declared <= 12 {
        return Err(container(
            "GLB_LENGTH_TOO_SMALL",
            8,
            format!("the header declares {declared} bytes: no room for a JSON chunk"),
        ));
    }
    let mut json: Option<&[u8]> = None;
    let mut bin: Option<&[u8]> = None;
    let mut offset = 12;
    let mut index = 0usize;
    while offset < declared {
        if bytes.len() < offset + 8 {
            if bytes.len() == offset {
                return Err(container(
                    "GLB_LENGTH_MISMATCH",
                    offset,
                    format!(
                        "the header declares {declared} bytes but the file has {} (it is \
                         truncated)",
                        bytes.len()
                    ),
                ));
            }
            return Err(container(
                "GLB_UNEXPECTED_END_OF_CHUNK_HEADER",
                offset,
                format!(
                    "{} bytes left where an 8-byte chunk header should be",
                    bytes.len() - offset
                ),
            ));
        }
        // Both read within the 8 bytes checked just above.
        let length = u32_at(bytes, offset).unwrap_or(0) as usize;
        let kind = u32_at(bytes, offset + 4).unwrap_or(0);
        let start = offset + 8;
        if index == 0 && kind != CHUNK_JSON {
            return Err(container(
                "GLB_UNEXPECTED_FIRST_CHUNK",
                offset,
                format!(
                    "the first chunk is of type {} (expected the JSON chunk first)",
                    chunk_name(kind)
                ),
            ));
        }
        if length % 4 != 0 {
            return Err(container(
                "GLB_CHUNK_LENGTH_UNALIGNED",
                offset,
                format!(
                    "the {} chunk has {length} bytes, not a multiple of 4 (glTF 2.0 pads every \
                     chunk to 4 bytes)",
                    chunk_name(kind)
                ),
            ));
        }
        let end = start.saturating_add(length);
        if end > declared {
            return Err(container(
                "GLB_CHUNK_TOO_BIG",
                offset,
                format!(
                    "the {} chunk declares {length} bytes, which do not fit the {declared} \
                     bytes the header declares",
                    chunk_name(kind)
                ),
            ));
        }
        if end > bytes.len() {
            return Err(container(
                "GLB_UNEXPECTED_END_OF_CHUNK_DATA",
                bytes.len(),
                format!(
                    "the {} chunk declares {length} bytes but the file ends after {} (it is \
                     truncated)",
                    chunk_name(kind),
                    bytes.len() - start
                ),
            ));
        }
        let body = &bytes[start..end];
        match kind {
            CHUNK_JSON => {
                if json.is_some() {
                    return Err(container(
                        "GLB_DUPLICATE_CHUNK",
                        offset,
                        "a second JSON chunk (expected exactly one)".to_owned(),
                    ));
                }
                if body.is_empty() {
                    return Err(container(
                        "GLB_EMPTY_CHUNK",
                        offset,
                        "the JSON chunk is empty".to_owned(),
                    ));
                }
                json = Some(body);
            }
            CHUNK_BIN => {
                if bin.is_some() {
                    return Err(container(
                        "GLB_DUPLICATE_CHUNK",
                        offset,
                        "a second BIN chunk (expected at most one)".to_owned(),
                    ));
                }
                if index != 1 {
                    return Err(container(
                        "GLB_UNEXPECTED_BIN_CHUNK",
                        offset,
                        format!(
                            "the BIN chunk is chunk {} (expected it second, right after the \
                             JSON chunk)",
                            index + 1
                        ),
                    ));
                }
                if body.is_empty() {
                    warnings.push(format!(
                        "GLB_EMPTY_BIN_CHUNK: the BIN chunk at byte {offset} is empty"
                    ));
                }
                bin = Some(body);
            }
            other => warnings.push(format!(
                "GLB_UNKNOWN_CHUNK_TYPE: chunk of type 0x{other:08x} at byte {offset} is ignored"
            )),
        }
        index += 1;
        offset = end;
    }
    if declared < bytes.len() {
        warnings.push(format!(
            "GLB_EXTRA_DATA: {} bytes after the declared end of the GLB ({declared} bytes) are ignored",
            bytes.len() - declared
        ));
    }
    let json = json.ok_or_else(|| {
        container(
            "GLB_UNEXPECTED_END_OF_CHUNK_HEADER",
            12,
            "no JSON chunk".to_owned(),
        )
    })?;
    Ok(Chunks { json, bin })
}

/// How to read a glTF 1.0 file.
const GLTF1_FIX: &str = "convert it with gltf-pipeline, `npx gltf-pipeline -i in.glb -o \
     out.glb`, or re-export it from its source as glTF 2.0 Binary";

fn not_glb(bytes: &[u8]) -> GlbError {
    let start = bytes.iter().copied().find(|b| !b.is_ascii_whitespace());
    if start == Some(b'{') {
        return GlbError::NotGlb {
            code: "not_glb",
            problem: "this is a glTF JSON file (.gltf), not a binary GLB".to_owned(),
        };
    }
    let shown: Vec<String> = bytes.iter().take(4).map(|b| format!("{b:02x}")).collect();
    GlbError::NotGlb {
        code: "GLB_INVALID_MAGIC",
        problem: format!(
            "GLB_INVALID_MAGIC: the file starts with {} (expected \"glTF\")",
            shown.join(" ")
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glb(chunks: &[(u32, &[u8])]) -> Vec<u8> {
        let mut body = Vec::new();
        for (kind, data) in chunks {
            body.extend_from_slice(&(data.len() as u32).to_le_bytes());
            body.extend_from_slice(&kind.to_le_bytes());
            body.extend_from_slice(data);
        }
        let mut out = b"glTF".to_vec();
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&((12 + body.len()) as u32).to_le_bytes());
        out.extend_from_slice(&body);
        out
    }

    fn code(bytes: &[u8]) -> String {
        match split(bytes, &mut Vec::new()) {
            Ok(_) => "ok".to_owned(),
            Err(e) => e.code().to_owned(),
        }
    }

    #[test]
    fn a_json_and_a_bin_chunk() {
        let bytes = glb(&[(CHUNK_JSON, b"{}  "), (CHUNK_BIN, &[1, 2, 3, 4])]);
        let chunks = split(&bytes, &mut Vec::new()).expect("valid");
        assert_eq!(chunks.json, b"{}  ");
        assert_eq!(chunks.bin, Some(&[1u8, 2, 3, 4][..]));
    }

    #[test]
    fn header_problems_have_their_validator_codes() {
        assert_eq!(code(b""), "GLB_UNEXPECTED_END_OF_HEADER");
        assert_eq!(code(b"glTF\x02\x00"), "GLB_UNEXPECTED_END_OF_HEADER");
        assert_eq!(code(b"{\"asset\": {}}"), "not_glb");
        let mut v1 = glb(&[(CHUNK_JSON, b"{}  ")]);
        v1[4] = 1;
        assert_eq!(code(&v1), "GLB_INVALID_VERSION");
        let mut v3 = glb(&[(CHUNK_JSON, b"{}  ")]);
        v3[4] = 3;
        assert_eq!(code(&v3), "GLB_INVALID_VERSION");
        let mut long = glb(&[(CHUNK_JSON, b"{}  ")]);
        long[8] += 4;
        assert_eq!(code(&long), "GLB_LENGTH_MISMATCH");
        let only_header = glb(&[]);
        assert_eq!(code(&only_header), "GLB_LENGTH_TOO_SMALL");
    }

    #[test]
    fn chunk_problems_have_their_validator_codes() {
        assert_eq!(
            code(&glb(&[(CHUNK_BIN, b"abcd"), (CHUNK_JSON, b"{}  ")])),
            "GLB_UNEXPECTED_FIRST_CHUNK"
        );
        assert_eq!(code(&glb(&[(CHUNK_JSON, b"")])), "GLB_EMPTY_CHUNK");
        assert_eq!(
            code(&glb(&[(CHUNK_JSON, b"{}  "), (CHUNK_JSON, b"{}  ")])),
            "GLB_DUPLICATE_CHUNK"
        );
        let mut big = glb(&[(CHUNK_JSON, b"{}  ")]);
        big[12] = 200;
        assert_eq!(code(&big), "GLB_CHUNK_TOO_BIG");
        assert_eq!(
            code(&glb(&[(CHUNK_JSON, b"{} ")])),
            "GLB_CHUNK_LENGTH_UNALIGNED"
        );
        assert_eq!(
            code(&glb(&[
                (CHUNK_JSON, b"{}  "),
                (0x1234_5678, b"xxxx"),
                (CHUNK_BIN, b"abcd")
            ])),
            "GLB_UNEXPECTED_BIN_CHUNK"
        );
        // The declared length holds the BIN chunk but the file ends inside it.
        let whole = glb(&[(CHUNK_JSON, b"{}  "), (CHUNK_BIN, b"abcdefgh")]);
        assert_eq!(
            code(&whole[..whole.len() - 4]),
            "GLB_UNEXPECTED_END_OF_CHUNK_DATA"
        );
        // ... inside its header, or right before it.
        assert_eq!(code(&whole[..28]), "GLB_UNEXPECTED_END_OF_CHUNK_HEADER");
        assert_eq!(code(&whole[..24]), "GLB_LENGTH_MISMATCH");
        // Controls: the same files without the defect.
        assert_eq!(code(&whole), "ok");
        assert_eq!(code(&glb(&[(CHUNK_JSON, b"{}  ")])), "ok");
    }

    #[test]
    fn trailing_bytes_and_unknown_chunks_are_warnings() {
        let mut bytes = glb(&[(CHUNK_JSON, b"{}  "), (0x1234_5678, b"xxxx")]);
        bytes.push(0);
        let mut warnings = Vec::new();
        split(&bytes, &mut warnings).expect("valid");
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(
            warnings[0].starts_with("GLB_UNKNOWN_CHUNK_TYPE"),
            "{warnings:?}"
        );
        assert!(warnings[1].starts_with("GLB_EXTRA_DATA"), "{warnings:?}");
    }
}

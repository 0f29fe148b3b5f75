//! Container checks that run before any byte reaches the gltf crate: the GLB header and chunk
//! table (the crate panics on some short or inconsistent GLBs), buffer sources, and every
//! accessor's byte range, all with checked arithmetic and caps.

use std::path::Path;

use super::GltfError;

/// Largest glTF/GLB file (or external buffer) the importer reads, in bytes.
pub const MAX_FILE_BYTES: u64 = 1 << 30;
/// Largest element count of any accessor (positions, keyframes, indices…).
pub const MAX_ACCESSOR_COUNT: usize = 1 << 24;
/// Largest element count of a sparse accessor without a buffer view: its base is generated
/// zeros, so nothing in the file bounds it.
pub const MAX_SPARSE_ZERO_COUNT: usize = 1 << 20;

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

fn u32_at(bytes: &[u8], at: usize) -> Option<u32> {
    let b = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// Checks a GLB's 12-byte header and its chunk table (one JSON chunk, then at most one BIN
/// chunk, each inside the declared length). JSON files pass through unchanged (only an empty
/// file is refused here; serde reports the rest).
pub(crate) fn check_container(bytes: &[u8], file: &str) -> Result<(), GltfError> {
    let bad = |reason: String| GltfError::Container {
        file: file.to_owned(),
        reason,
    };
    if bytes.is_empty() {
        return Err(bad("file is empty".into()));
    }
    let is_glb = bytes.starts_with(GLB_MAGIC) || (bytes.len() < 4 && GLB_MAGIC.starts_with(bytes));
    if !is_glb {
        return Ok(());
    }
    if bytes.len() < 12 {
        return Err(bad(format!(
            "GLB header needs 12 bytes, file has {}",
            bytes.len()
        )));
    }
    let version = u32_at(bytes, 4).unwrap_or(0);
    if version != 2 {
        return Err(bad(format!(
            "GLB header: version {version}, only 2 is supported"
        )));
    }
    let length = u32_at(bytes, 8).unwrap_or(0) as usize;
    if length != bytes.len() {
        return Err(bad(format!(
            "GLB header: length {length} but the file has {} bytes",
            bytes.len()
        )));
    }
    let mut at = 12usize;
    let mut index = 0usize;
    while at < length {
        let header_end = at.checked_add(8).filter(|&e| e <= length).ok_or_else(|| {
            bad(format!(
                "GLB chunk {index}: header at byte {at} runs past the end ({length} bytes)"
            ))
        })?;
        let chunk_len = u32_at(bytes, at).unwrap_or(0) as usize;
        let chunk_type = u32_at(bytes, at + 4).unwrap_or(0);
        let end = header_end.checked_add(chunk_len).filter(|&e| e <= length).ok_or_else(|| {
            bad(format!("GLB chunk {index}: length {chunk_len} at byte {at} runs past the end ({length} bytes)"))
        })?;
        match (index, chunk_type) {
            (0, CHUNK_JSON) => {}
            (0, t) => {
                return Err(bad(format!(
                    "GLB chunk 0 has type {t:#010x}, expected JSON"
                )));
            }
            (1, CHUNK_BIN) => {}
            (i, t) => {
                // The gltf crate refuses any chunk after JSON that is not BIN and ignores
                // anything after BIN; refuse both so the file means one thing.
                return Err(bad(format!(
                    "GLB chunk {i} has type {t:#010x}, expected BIN and nothing after it"
                )));
            }
        }
        at = end;
        index += 1;
    }
    if index == 0 {
        return Err(bad("GLB has no JSON chunk".into()));
    }
    Ok(())
}

/// Decodes `%XX` escapes in a relative URI.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Reads a file of at most [`MAX_FILE_BYTES`], naming `file` in errors.
pub(crate) fn read_capped(path: &Path, file: &str) -> Result<Vec<u8>, GltfError> {
    let io = |source| GltfError::Io {
        file: file.to_owned(),
        source,
    };
    let len = std::fs::metadata(path).map_err(io)?.len();
    if len > MAX_FILE_BYTES {
        return Err(GltfError::TooLarge {
            file: file.to_owned(),
            field: "file size".into(),
            count: len,
            cap: MAX_FILE_BYTES,
        });
    }
    std::fs::read(path).map_err(io)
}

/// Loads every buffer: the GLB BIN chunk, base64 data URIs, or files relative to `base_dir`.
/// Each must hold at least its declared `byteLength`.
pub(crate) fn load_buffers(
    doc: &gltf::Document,
    blob: Option<Vec<u8>>,
    base_dir: Option<&Path>,
    file: &str,
) -> Result<Vec<Vec<u8>>, GltfError> {
    use base64::Engine as _;
    let mut blob = blob;
    let mut out = Vec::new();
    for buffer in doc.buffers() {
        let field = format!("buffers[{}]", buffer.index());
        let bad = |reason: String| GltfError::Field {
            file: file.to_owned(),
            field: field.clone(),
            reason,
        };
        let data = match buffer.source() {
            gltf::buffer::Source::Bin => blob
                .take()
                .ok_or_else(|| bad("refers to the GLB BIN chunk, which is absent".into()))?,
            gltf::buffer::Source::Uri(uri) => {
                if let Some(rest) = uri.strip_prefix("data:") {
                    let (_, payload) = rest
                        .split_once(";base64,")
                        .ok_or_else(|| bad("data URI is not base64".into()))?;
                    if payload.len() as u64 > MAX_FILE_BYTES {
                        return Err(bad("data URI larger than the file cap".into()));
                    }
                    base64::engine::general_purpose::STANDARD
                        .decode(payload)
                        .map_err(|e| bad(format!("data URI: {e}")))?
                } else {
                    let dir = base_dir.ok_or_else(|| {
                        bad(format!("external URI `{uri}` but no base folder is known"))
                    })?;
                    let rel = percent_decode(uri)
                        .ok_or_else(|| bad(format!("URI `{uri}` has a bad %-escape")))?;
                    read_capped(&dir.join(&rel), &format!("{file}: {field} `{rel}`"))?
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(bad(format!(
                "byteLength {} but only {} bytes are present",
                buffer.length(),
                data.len()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// Checks that every buffer view lies inside its buffer and every accessor inside its view (or,
/// for a sparse accessor, that its indices and values do), with checked arithmetic, and that
/// counts stay under the caps. After this the gltf crate's readers cannot index out of range.
pub(crate) fn check_accessors(
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
    file: &str,
) -> Result<(), GltfError> {
    let err = |field: String, reason: String| GltfError::Field {
        file: file.to_owned(),
        field,
        reason,
    };
    for view in doc.views() {
        let field = format!("bufferViews[{}]", view.index());
        let data_len = buffers.get(view.buffer().index()).map_or(0, Vec::len);
        let end = view.offset().checked_add(view.length());
        if end.is_none_or(|e| e > data_len) {
            return Err(err(
                field,
                format!(
                    "bytes {}+{} exceed the buffer's {data_len}",
                    view.offset(),
                    view.length()
                ),
            ));
        }
    }
    // An element range `offset + stride·(count−1) + size` must fit in `len`.
    let fits = |offset: usize, stride: usize, count: usize, size: usize, len: usize| -> bool {
        count >= 1
            && stride
                .checked_mul(count - 1)
                .and_then(|x| x.checked_add(offset))
                .and_then(|x| x.checked_add(size))
                .is_some_and(|end| end <= len)
    };
    for acc in doc.accessors() {
        let field = format!("accessors[{}]", acc.index());
        let count = acc.count();
        if count == 0 || count > MAX_ACCESSOR_COUNT {
            return Err(err(
                field,
                format!("count {count} outside 1..={MAX_ACCESSOR_COUNT}"),
            ));
        }
        let size = acc.size();
        if let Some(view) = acc.view() {
            let stride = view.stride().unwrap_or(size);
            if stride < size && count > 1 {
                return Err(err(
                    field,
                    format!("byteStride {stride} smaller than the element size {size}"),
                ));
            }
            if !fits(acc.offset(), stride, count, size, view.length()) {
                return Err(err(
                    field,
                    format!(
                        "{count} elements at offset {} overrun bufferView {}",
                        acc.offset(),
                        view.index()
                    ),
                ));
            }
        } else if acc.sparse().is_none() {
            return Err(err(
                field,
                "has neither a bufferView nor sparse data".into(),
            ));
        } else if count > MAX_SPARSE_ZERO_COUNT {
            return Err(err(
                field,
                format!("sparse count {count} above the cap {MAX_SPARSE_ZERO_COUNT}"),
            ));
        }
        if let Some(sparse) = acc.sparse() {
            let n = sparse.count();
            if n == 0 || n > count {
                return Err(err(field, format!("sparse count {n} outside 1..={count}")));
            }
            let iview = sparse.indices().view();
            let isize = match sparse.indices().index_type() {
                gltf::accessor::sparse::IndexType::U8 => 1,
                gltf::accessor::sparse::IndexType::U16 => 2,
                gltf::accessor::sparse::IndexType::U32 => 4,
            };
            if !fits(sparse.indices().offset(), isize, n, isize, iview.length()) {
                return Err(err(field, "sparse indices overrun their bufferView".into()));
            }
            let vview = sparse.values().view();
            if !fits(sparse.values().offset(), size, n, size, vview.length()) {
                return Err(err(field, "sparse values overrun their bufferView".into()));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn glb(json: &[u8], bin: Option<&[u8]>) -> Vec<u8> {
        let mut out = b"glTF".to_vec();
        out.extend(2u32.to_le_bytes());
        out.extend(0u32.to_le_bytes());
        out.extend((json.len() as u32).to_le_bytes());
        out.extend(CHUNK_JSON.to_le_bytes());
        out.extend(json);
        if let Some(bin) = bin {
            out.extend((bin.len() as u32).to_le_bytes());
            out.extend(CHUNK_BIN.to_le_bytes());
            out.extend(bin);
        }
        let n = out.len() as u32;
        out[8..12].copy_from_slice(&n.to_le_bytes());
        out
    }

    #[test]
    fn accepts_a_well_formed_glb_and_json() {
        check_container(&glb(b"{}  ", Some(&[0; 8])), "x").unwrap();
        check_container(&glb(b"{}  ", None), "x").unwrap();
        check_container(b"{\"asset\":{}}", "x").unwrap();
    }

    #[test]
    fn refuses_each_broken_header_field() {
        let good = glb(b"{}  ", Some(&[0; 8]));
        for n in 1..good.len() {
            assert!(
                check_container(&good[..n], "x").is_err(),
                "prefix {n} accepted"
            );
        }
        let mut v = good.clone();
        v[4] = 1;
        assert!(
            check_container(&v, "x")
                .unwrap_err()
                .to_string()
                .contains("version")
        );
        let mut v = good.clone();
        v[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(
            check_container(&v, "x")
                .unwrap_err()
                .to_string()
                .contains("runs past")
        );
        let mut v = good.clone();
        v[16] = b'X';
        assert!(
            check_container(&v, "x")
                .unwrap_err()
                .to_string()
                .contains("expected JSON")
        );
        let mut v = good;
        let bin_type_at = 12 + 8 + 4 + 4;
        v[bin_type_at] = b'Z';
        assert!(
            check_container(&v, "x")
                .unwrap_err()
                .to_string()
                .contains("expected BIN")
        );
        assert!(check_container(b"", "x").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin").as_deref(), Some("a b.bin"));
        assert_eq!(percent_decode("a%2"), None);
        assert_eq!(percent_decode("plain"), Some("plain".into()));
    }
}

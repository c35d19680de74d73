//! glTF 2.0 (`.gltf` JSON and `.glb` binary): reader on `gltf`, writer on `gltf-json`.
//!
//! Read: the first primitive of the first mesh, `POSITION` (`VEC3` float) and its indices
//! (unsigned byte, short or int; a primitive without indices is read as `0, 1, 2, ...`). Only
//! `TRIANGLES` mode is accepted. Node transforms, skins and morph targets are ignored: positions
//! are as stored in the mesh. Buffers may be the GLB binary chunk, a file next to the `.gltf`
//! (percent-encoded relative URI), or a base64 `data:` URI.
//!
//! Write: one buffer (positions as `f32`, then `u32` indices), two buffer views, a `POSITION`
//! accessor with the `min`/`max` the specification requires, one mesh, node and scene. `.glb`
//! puts the buffer in the binary chunk; `.gltf` embeds it as a base64 `data:` URI.

use std::borrow::Cow;
use std::path::Path;

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::buffer::Source;
use ::gltf::mesh::{Mode, Semantic};
use glam::Vec3;
use gltf_json as json;
use json::validation::{Checked::Valid, USize64};

use super::error::{Location, MeshError};
use super::{Mesh, check_indices, first_non_finite, write_atomic};

/// Reads the first primitive of the first mesh of a `.gltf` or `.glb` file.
pub fn read_gltf(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| MeshError::io(path, e))?;
    parse_gltf(&bytes, Some(path))
}

/// The first primitive of the first mesh of the `.gltf` or `.glb` bytes `bytes`. `path` is the
/// file they came from: errors name it, and a buffer stored in another file is read next to
/// it. Without a `path` (bytes from the network, a fuzzer) such a buffer is an error.
pub fn parse_gltf(bytes: &[u8], path: Option<&Path>) -> Result<Mesh, MeshError> {
    let at = || path.map(Location::file).unwrap_or_default();
    // gltf-json 1.4's validation indexes `accessors` with a primitive's POSITION before it
    // has checked that index (a fuzzer's finding, `fuzz/` mesh_gltf): a panic there is a bad
    // file, as the reader of any other malformed file would say.
    let gltf = std::panic::catch_unwind(|| ::gltf::Gltf::from_slice(bytes))
        .map_err(|_| {
            MeshError::format(
                at(),
                "not a valid glTF file: a reference to an accessor, buffer or view that does not exist",
            )
        })?
        .map_err(|e| MeshError::format(at(), format!("not a valid glTF file: {e}")))?;

    let mut buffers: Vec<Cow<'_, [u8]>> = Vec::new();
    for buffer in gltf.buffers() {
        let i = buffer.index();
        let data: Cow<'_, [u8]> = match buffer.source() {
            Source::Bin => Cow::Borrowed(gltf.blob.as_deref().ok_or_else(|| {
                MeshError::format(
                    at(),
                    format!("buffer {i} refers to the GLB binary chunk, but there is none"),
                )
            })?),
            Source::Uri(uri) => {
                if let Some(data) = uri.strip_prefix("data:") {
                    let (_, payload) = data.split_once(";base64,").ok_or_else(|| {
                        MeshError::format(
                            at(),
                            format!("buffer {i}: only base64 data URIs are supported"),
                        )
                    })?;
                    Cow::Owned(base64_decode(payload).map_err(|message| {
                        MeshError::format(at(), format!("buffer {i}: data URI: {message}"))
                    })?)
                } else {
                    let Some(path) = path else {
                        return Err(MeshError::format(
                            at(),
                            format!(
                                "buffer {i} is in another file ({uri}), and there is no folder to read it from"
                            ),
                        ));
                    };
                    let file = path
                        .parent()
                        .unwrap_or(Path::new(""))
                        .join(percent_decode(uri));
                    Cow::Owned(std::fs::read(&file).map_err(|e| MeshError::io(&file, e))?)
                }
            }
        };
        if data.len() < buffer.length() {
            return Err(MeshError::format(
                at(),
                format!(
                    "buffer {i}: {} bytes, but its byteLength is {}",
                    data.len(),
                    buffer.length()
                ),
            ));
        }
        buffers.push(data);
    }
    // The accessors are checked before they are read (`check_accessor`); a panic of the
    // third-party reader past those checks is still a bad file, not a crash.
    let mesh = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        mesh_from_document(&gltf.document, &buffers)
    }))
    .unwrap_or_else(|_| {
        Err(MeshError::format(
            at(),
            "not a valid glTF file: an accessor the glTF reader could not read",
        ))
    });
    match path {
        Some(path) => mesh.map_err(|e| e.in_file(path)),
        None => mesh,
    }
}

/// Checks that `accessor` (the `what` accessor) can be read as the glTF reader reads it: at
/// least one element, dense (no sparse part), in a buffer view, its stride no shorter than an
/// element, its last element inside the view. gltf 1.4 computes `offset + stride * (count - 1)`
/// unchecked (a fuzzer's finding, `fuzz/regressions/mesh_gltf/position-count-zero.gltf`: a
/// count of 0 underflows).
fn check_accessor(accessor: &::gltf::Accessor<'_>, what: &str) -> Result<(), MeshError> {
    let fail = |message: String| {
        MeshError::format(
            Location::default(),
            format!("{what} accessor {}: {message}", accessor.index()),
        )
    };
    let count = accessor.count();
    if count == 0 {
        return Err(fail("count is 0".to_owned()));
    }
    if accessor.sparse().is_some() {
        return Err(fail("sparse accessors are not supported".to_owned()));
    }
    let view = accessor
        .view()
        .ok_or_else(|| fail("no bufferView (all zeros) is not supported".to_owned()))?;
    let size = accessor.size();
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(fail(format!(
            "bufferView {} has byteStride {stride}, shorter than an element ({size} bytes)",
            view.index()
        )));
    }
    let end = stride
        .checked_mul(count - 1)
        .and_then(|n| n.checked_add(accessor.offset()))
        .and_then(|n| n.checked_add(size));
    match end {
        Some(end) if end <= view.length() => Ok(()),
        _ => Err(fail(format!(
            "{count} elements from byteOffset {} with stride {stride} run past bufferView {} ({} bytes)",
            accessor.offset(),
            view.index(),
            view.length()
        ))),
    }
}

/// The first primitive of the first mesh of `document`, whose buffers are `buffers`.
fn mesh_from_document(
    document: &::gltf::Document,
    buffers: &[Cow<'_, [u8]>],
) -> Result<Mesh, MeshError> {
    let at = Location::default;
    let fail = |message: String| MeshError::format(at(), message);
    let gmesh = document
        .meshes()
        .next()
        .ok_or_else(|| fail("no meshes".to_owned()))?;
    let primitive = gmesh
        .primitives()
        .next()
        .ok_or_else(|| fail("mesh 0 has no primitives".to_owned()))?;
    if primitive.mode() != Mode::Triangles {
        return Err(fail(format!(
            "mesh 0 primitive 0 has mode {:?}; only Triangles is supported",
            primitive.mode()
        )));
    }
    let accessor = primitive
        .get(&Semantic::Positions)
        .ok_or_else(|| fail("mesh 0 primitive 0 has no POSITION attribute".to_owned()))?;
    if accessor.data_type() != DataType::F32
        || accessor.dimensions() != Dimensions::Vec3
        || accessor.normalized()
    {
        return Err(fail(format!(
            "POSITION accessor {} is {:?} {:?}{}, expected Vec3 F32",
            accessor.index(),
            accessor.dimensions(),
            accessor.data_type(),
            if accessor.normalized() {
                " normalized"
            } else {
                ""
            },
        )));
    }
    check_accessor(&accessor, "POSITION")?;
    let reader = primitive.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| {
            fail(format!(
                "POSITION accessor {}: data missing or outside its buffer",
                accessor.index()
            ))
        })?
        .map(Vec3::from_array)
        .collect();
    if positions.len() != accessor.count() {
        return Err(fail(format!(
            "POSITION accessor {}: {} values in the buffer, count is {}",
            accessor.index(),
            positions.len(),
            accessor.count()
        )));
    }
    for (vertex, &p) in positions.iter().enumerate() {
        if let Some((axis, value)) = first_non_finite(p) {
            return Err(MeshError::NonFinite {
                at: at(),
                vertex,
                axis,
                value,
            });
        }
    }

    let indices: Vec<u32> = match primitive.indices() {
        None => (0..positions.len() as u32).collect(),
        Some(acc) => {
            let integer = matches!(
                acc.data_type(),
                DataType::U8 | DataType::U16 | DataType::U32
            );
            if !integer || acc.dimensions() != Dimensions::Scalar {
                return Err(fail(format!(
                    "index accessor {} is {:?} {:?}, expected Scalar U8, U16 or U32",
                    acc.index(),
                    acc.dimensions(),
                    acc.data_type()
                )));
            }
            check_accessor(&acc, "index")?;
            let indices: Vec<u32> = reader
                .read_indices()
                .ok_or_else(|| {
                    fail(format!(
                        "index accessor {}: data missing or outside its buffer",
                        acc.index()
                    ))
                })?
                .into_u32()
                .collect();
            if indices.len() != acc.count() {
                return Err(fail(format!(
                    "index accessor {}: {} values in the buffer, count is {}",
                    acc.index(),
                    indices.len(),
                    acc.count()
                )));
            }
            indices
        }
    };
    if !indices.len().is_multiple_of(3) {
        return Err(fail(format!(
            "{} indices is not a multiple of 3 (Triangles mode)",
            indices.len()
        )));
    }
    let triangles: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    check_indices(&triangles, positions.len(), &at())?;
    Ok(Mesh {
        positions,
        triangles,
    })
}

/// Writes a binary glTF (`.glb`), atomically. Refuses an invalid mesh, and an empty one (glTF
/// accessors must have at least one element).
pub fn write_glb(path: impl AsRef<Path>, mesh: &Mesh) -> Result<(), MeshError> {
    let path = path.as_ref();
    let bytes = glb_bytes(mesh).map_err(|e| e.in_file(path))?;
    write_atomic(path, |out| out.write_all(&bytes))
}

/// Writes a JSON glTF (`.gltf`) with the buffer embedded as a base64 `data:` URI, atomically.
pub fn write_gltf(path: impl AsRef<Path>, mesh: &Mesh) -> Result<(), MeshError> {
    let path = path.as_ref();
    let bytes = gltf_json_bytes(mesh).map_err(|e| e.in_file(path))?;
    write_atomic(path, |out| out.write_all(&bytes))
}

/// The bytes of a `.glb` file holding `mesh`.
pub fn glb_bytes(mesh: &Mesh) -> Result<Vec<u8>, MeshError> {
    let bin = binary_buffer(mesh)?;
    let root = document(mesh, bin.len(), None);
    let json = json::serialize::to_vec(&root).map_err(|e| {
        MeshError::format(Location::default(), format!("serialising glTF JSON: {e}"))
    })?;
    let glb = ::gltf::binary::Glb {
        header: ::gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            // `to_vec` computes the real length (with chunk padding) itself.
            length: 0,
        },
        json: Cow::Owned(json),
        bin: Some(Cow::Owned(bin)),
    };
    glb.to_vec()
        .map_err(|e| MeshError::format(Location::default(), format!("writing GLB: {e}")))
}

/// The bytes of a `.gltf` file holding `mesh`, buffer embedded.
pub fn gltf_json_bytes(mesh: &Mesh) -> Result<Vec<u8>, MeshError> {
    let bin = binary_buffer(mesh)?;
    let uri = format!(
        "data:application/octet-stream;base64,{}",
        base64_encode(&bin)
    );
    let root = document(mesh, bin.len(), Some(uri));
    json::serialize::to_vec_pretty(&root)
        .map_err(|e| MeshError::format(Location::default(), format!("serialising glTF JSON: {e}")))
}

/// Positions (little-endian `f32`), then indices (little-endian `u32`). 12 bytes per vertex
/// keeps the index view 4-byte aligned, as accessors require.
fn binary_buffer(mesh: &Mesh) -> Result<Vec<u8>, MeshError> {
    mesh.validate()?;
    if mesh.positions.is_empty() || mesh.triangles.is_empty() {
        return Err(MeshError::format(
            Location::default(),
            format!(
                "glTF cannot hold a mesh with {} vertices and {} triangles (accessors need at \
                 least one element)",
                mesh.positions.len(),
                mesh.triangles.len()
            ),
        ));
    }
    let mut bin = Vec::with_capacity(mesh.positions.len() * 12 + mesh.triangles.len() * 12);
    for p in &mesh.positions {
        for v in p.to_array() {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    for t in &mesh.triangles {
        for i in t {
            bin.extend_from_slice(&i.to_le_bytes());
        }
    }
    Ok(bin)
}

/// The glTF document describing [`binary_buffer`]'s layout.
fn document(mesh: &Mesh, buffer_len: usize, uri: Option<String>) -> json::Root {
    let positions_len = mesh.positions.len() * 12;
    let mut root = json::Root {
        asset: json::Asset {
            generator: Some("crease".to_owned()),
            ..Default::default()
        },
        ..Default::default()
    };
    let buffer = root.push(json::Buffer {
        byte_length: USize64::from(buffer_len),
        name: None,
        uri,
        extensions: None,
        extras: Default::default(),
    });
    let view = |offset: usize, len: usize, target| json::buffer::View {
        buffer,
        byte_length: USize64::from(len),
        byte_offset: Some(USize64::from(offset)),
        byte_stride: None,
        name: None,
        target: Some(Valid(target)),
        extensions: None,
        extras: Default::default(),
    };
    let positions_view = root.push(view(0, positions_len, json::buffer::Target::ArrayBuffer));
    let indices_view = root.push(view(
        positions_len,
        buffer_len - positions_len,
        json::buffer::Target::ElementArrayBuffer,
    ));
    let (lo, hi) = mesh.bounding_box();
    let accessor =
        |view, count: usize, component, type_, bounds: Option<(Vec3, Vec3)>| json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(count),
            component_type: Valid(json::accessor::GenericComponentType(component)),
            extensions: None,
            extras: Default::default(),
            type_: Valid(type_),
            min: bounds.map(|(lo, _)| json::Value::from(lo.to_array().to_vec())),
            max: bounds.map(|(_, hi)| json::Value::from(hi.to_array().to_vec())),
            name: None,
            normalized: false,
            sparse: None,
        };
    let positions = root.push(accessor(
        positions_view,
        mesh.positions.len(),
        json::accessor::ComponentType::F32,
        json::accessor::Type::Vec3,
        Some((lo, hi)),
    ));
    let indices = root.push(accessor(
        indices_view,
        mesh.triangles.len() * 3,
        json::accessor::ComponentType::U32,
        json::accessor::Type::Scalar,
        None,
    ));
    let primitive = json::mesh::Primitive {
        attributes: [(Valid(json::mesh::Semantic::Positions), positions)].into(),
        extensions: None,
        extras: Default::default(),
        indices: Some(indices),
        material: None,
        mode: Valid(json::mesh::Mode::Triangles),
        targets: None,
    };
    let gmesh = root.push(json::Mesh {
        extensions: None,
        extras: Default::default(),
        name: None,
        primitives: vec![primitive],
        weights: None,
    });
    let node = root.push(json::Node {
        mesh: Some(gmesh),
        ..Default::default()
    });
    let scene = root.push(json::Scene {
        extensions: None,
        extras: Default::default(),
        name: None,
        nodes: vec![node],
    });
    root.scene = Some(scene);
    root
}

const BASE64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

/// Standard base64 with padding (RFC 4648 §4).
fn base64_encode(bytes: &[u8]) -> String {
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for k in 0..4 {
            if k <= chunk.len() {
                out.push(BASE64[(n >> (18 - 6 * k)) as usize & 63] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Decodes standard base64; padding optional, whitespace not allowed.
fn base64_decode(text: &str) -> Result<Vec<u8>, String> {
    let text = text.trim_end_matches('=');
    let mut out = Vec::with_capacity(text.len() * 3 / 4);
    let mut acc = 0u32;
    let mut bits = 0;
    for (i, c) in text.bytes().enumerate() {
        let v = match c {
            b'A'..=b'Z' => c - b'A',
            b'a'..=b'z' => c - b'a' + 26,
            b'0'..=b'9' => c - b'0' + 52,
            b'+' => 62,
            b'/' => 63,
            _ => return Err(format!("invalid base64 character {:?} at {i}", c as char)),
        };
        acc = (acc << 6) | u32::from(v);
        bits += 6;
        if bits >= 8 {
            bits -= 8;
            out.push((acc >> bits) as u8);
            acc &= (1 << bits) - 1;
        }
    }
    if bits >= 6 {
        return Err("truncated base64 data".to_owned());
    }
    Ok(out)
}

/// Decodes `%XX` escapes in a relative URI (glTF URIs are percent-encoded).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_matches_rfc4648_vectors() {
        // RFC 4648 §10.
        let cases = [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ];
        for (plain, encoded) in cases {
            assert_eq!(base64_encode(plain.as_bytes()), encoded);
            assert_eq!(base64_decode(encoded).unwrap(), plain.as_bytes());
        }
        assert!(base64_decode("Zm9v!").is_err());
        assert!(base64_decode("Z").is_err());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("my%20mesh.bin"), "my mesh.bin");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("a%zzb"), "a%zzb");
    }

    fn tri() -> Mesh {
        Mesh {
            positions: vec![Vec3::new(-1.0, 0.5, 2.0), Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn glb_has_position_min_max_and_reads_back() {
        let bytes = glb_bytes(&tri()).unwrap();
        let gltf = ::gltf::Gltf::from_slice(&bytes).unwrap();
        let acc = gltf.accessors().next().unwrap();
        assert_eq!(acc.min().unwrap(), serde_json::json!([-1.0, 0.0, 0.0]));
        assert_eq!(acc.max().unwrap(), serde_json::json!([1.0, 1.0, 2.0]));
        assert_eq!(bytes.len() % 4, 0);
        let buffers = vec![Cow::Borrowed(gltf.blob.as_deref().unwrap())];
        assert_eq!(mesh_from_document(&gltf.document, &buffers).unwrap(), tri());
    }

    #[test]
    fn empty_mesh_is_refused() {
        let e = glb_bytes(&Mesh::default()).unwrap_err().to_string();
        assert!(e.contains("0 vertices and 0 triangles"), "{e}");
    }

    /// A hand-written document: non-indexed triangle strip, then the same as triangles.
    fn doc_with(mode: u32, indexed: bool) -> Vec<u8> {
        let mut bin = Vec::new();
        for v in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
        for i in [2u16, 1, 0, 0] {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        let indices = if indexed { r#", "indices": 1"# } else { "" };
        format!(
            r#"{{"asset": {{"version": "2.0"}},
            "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{b64}"}}],
            "bufferViews": [{{"buffer": 0, "byteLength": 36}},
                            {{"buffer": 0, "byteOffset": 36, "byteLength": 6}}],
            "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                            "min": [0, 0, 0], "max": [1, 1, 0]}},
                          {{"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}}],
            "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}, "mode": {mode}{indices}}}]}}]}}"#,
            len = bin.len(),
            b64 = base64_encode(&bin),
        )
        .into_bytes()
    }

    fn read_doc(bytes: &[u8]) -> Result<Mesh, MeshError> {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.gltf");
        std::fs::write(&path, bytes).unwrap();
        read_gltf(&path)
    }

    #[test]
    fn non_indexed_and_u16_indexed_data_uri_documents() {
        let m = read_doc(&doc_with(4, false)).unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        let m = read_doc(&doc_with(4, true)).unwrap();
        assert_eq!(m.triangles, vec![[2, 1, 0]]);
        assert_eq!(m.positions[1], Vec3::X);
    }

    #[test]
    fn non_triangle_mode_is_a_clear_error() {
        let e = read_doc(&doc_with(5, false)).unwrap_err().to_string();
        assert!(
            e.ends_with(
                "t.gltf: mesh 0 primitive 0 has mode TriangleStrip; only Triangles is supported"
            ),
            "{e}"
        );
    }
}

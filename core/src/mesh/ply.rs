//! Stanford PLY: reader (ASCII, binary little- and big-endian) and writer, on `ply-rs-bw`.
//!
//! Read: element `vertex` with scalar properties `x`, `y`, `z` of any numeric type (`double` is
//! rounded to the nearest `f32`); optional element `face` with a list property `vertex_indices`
//! or `vertex_index` of any integer type, polygons fan-triangulated as `(0, i, i + 1)`. Other
//! properties and elements are skipped. Write: `float x y z` and `list uchar uint
//! vertex_indices`.

use std::io::{self, Write};
use std::path::Path;

use glam::Vec3;
use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{
    Addable, BeginList, ElementDef, Encoding, Header, Property, PropertyAccess,
    PropertyAccessResult, PropertyDef, PropertyType, ScalarType,
};
use ply_rs_bw::writer::Writer;

use super::error::{Location, MeshError};
use super::{Mesh, first_non_finite, write_atomic};

/// The encoding of a PLY file to write.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlyFormat {
    /// Human-readable text; coordinates in `f32`'s shortest round-trip form.
    Ascii,
    /// Binary, little-endian: the common binary PLY, and the default.
    #[default]
    BinaryLittleEndian,
    /// Binary, big-endian.
    BinaryBigEndian,
}

/// Names a face's vertex list may have.
const FACE_LIST_NAMES: [&str; 2] = ["vertex_indices", "vertex_index"];

/// Reads a PLY file (ASCII or binary, either byte order).
pub fn read_ply(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| MeshError::io(path, e))?;
    parse_ply(&bytes).map_err(|e| e.in_file(path))
}

/// Parses PLY bytes. Errors carry the line for ASCII files but no file (see [`read_ply`]).
pub fn parse_ply(bytes: &[u8]) -> Result<Mesh, MeshError> {
    let mut reader = Reader::new(bytes);
    let header = Parser::<Skip>::new()
        .read_header(&mut reader)
        .map_err(|e| ply_error(e, true))?;
    let ascii = header.encoding == Encoding::Ascii;
    check_header(&header)?;

    // ASCII PLY has one element per line, so lines are counted from the end of the header.
    let mut lines_before = if ascii { header_line_count(bytes) } else { 0 };
    let mut vertices: Vec<VertexElem> = Vec::new();
    let mut faces: Vec<FaceElem> = Vec::new();
    let mut vertex_first_line = 0;
    let mut face_first_line = 0;
    for (name, def) in &header.elements {
        match name.as_str() {
            "vertex" => {
                vertex_first_line = lines_before + 1;
                vertices = Parser::<VertexElem>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| {
                        let nan = if ascii {
                            find_ascii_non_finite(bytes, vertex_first_line, def)
                        } else {
                            None
                        };
                        nan.unwrap_or_else(|| ply_error(e, ascii))
                    })?;
            }
            "face" => {
                face_first_line = lines_before + 1;
                faces = Parser::<FaceElem>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_error(e, ascii))?;
                finish_signed(&mut faces);
            }
            _ => {
                Parser::<Skip>::new()
                    .read_payload_for_element(&mut reader, def, &header)
                    .map_err(|e| ply_error(e, ascii))?;
            }
        }
        lines_before += def.count;
    }
    let at = |first_line: usize, i: usize| Location {
        path: None,
        line: ascii.then_some(first_line + i),
    };

    let mut mesh = Mesh {
        positions: Vec::with_capacity(vertices.len()),
        triangles: Vec::with_capacity(faces.len()),
    };
    for (vertex, v) in vertices.iter().enumerate() {
        let p = Vec3::from_array(v.p);
        if let Some((axis, value)) = first_non_finite(p) {
            return Err(MeshError::NonFinite {
                at: at(vertex_first_line, vertex),
                vertex,
                axis,
                value,
            });
        }
        mesh.positions.push(p);
    }
    let vertex_count = mesh.positions.len();
    for (face, f) in faces.iter().enumerate() {
        if let Some(negative) = f.negative {
            return Err(MeshError::format(
                at(face_first_line, face),
                format!("face {face}: negative vertex index {negative}"),
            ));
        }
        let list = &f.indices;
        if list.len() < 3 {
            return Err(MeshError::format(
                at(face_first_line, face),
                format!(
                    "face {face}: expected at least 3 vertices, got {}",
                    list.len()
                ),
            ));
        }
        for k in 1..list.len() - 1 {
            let t = [list[0], list[k], list[k + 1]];
            if let Some(&index) = t.iter().find(|&&i| i as usize >= vertex_count) {
                return Err(MeshError::IndexOutOfRange {
                    at: at(face_first_line, face),
                    triangle: mesh.triangles.len(),
                    index: u64::from(index),
                    vertex_count,
                });
            }
            mesh.triangles.push(t);
        }
    }
    Ok(mesh)
}

/// Checks the header declares what we read: scalar `x y z` on `vertex`, an integer list on
/// `face`.
fn check_header(header: &Header) -> Result<(), MeshError> {
    let at = Location::default;
    let Some(vertex) = header.elements.get("vertex") else {
        let names: Vec<_> = header.elements.keys().collect();
        return Err(MeshError::format(
            at(),
            format!("no 'vertex' element (elements: {names:?})"),
        ));
    };
    for axis in ["x", "y", "z"] {
        match vertex.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(other) => {
                return Err(MeshError::format(
                    at(),
                    format!("vertex property '{axis}' is {other:?}, expected a scalar"),
                ));
            }
            None => {
                let names: Vec<_> = vertex.properties.keys().collect();
                return Err(MeshError::format(
                    at(),
                    format!("vertex element has no property '{axis}' (properties: {names:?})"),
                ));
            }
        }
    }
    if let Some(face) = header.elements.get("face") {
        let list = FACE_LIST_NAMES
            .iter()
            .find_map(|n| face.properties.get(*n))
            .ok_or_else(|| {
                let names: Vec<_> = face.properties.keys().collect();
                MeshError::format(
                    at(),
                    format!(
                        "face element has neither 'vertex_indices' nor 'vertex_index' \
                         (properties: {names:?})"
                    ),
                )
            })?;
        match &list.data_type {
            PropertyType::List(_, ScalarType::Float | ScalarType::Double)
            | PropertyType::Scalar(_) => {
                return Err(MeshError::format(
                    at(),
                    format!(
                        "face property '{}' is {:?}, expected a list of integers",
                        list.name, list.data_type
                    ),
                ));
            }
            PropertyType::List(..) => {}
        }
    }
    Ok(())
}

/// Lines up to and including `end_header`.
fn header_line_count(bytes: &[u8]) -> usize {
    let mut lines = 0;
    for line in bytes.split(|&b| b == b'\n') {
        lines += 1;
        if line.trim_ascii() == b"end_header" {
            break;
        }
    }
    lines
}

/// The ASCII grammar of `ply-rs-bw` rejects `nan` and `inf` tokens. When reading the vertices
/// fails, look for such a token in an `x`, `y` or `z` column to give the usual non-finite error.
fn find_ascii_non_finite(bytes: &[u8], first_line: usize, def: &ElementDef) -> Option<MeshError> {
    // Column of each axis, valid while every property before it is a scalar (one token each).
    let mut columns = Vec::new();
    for (k, p) in def.properties.values().enumerate() {
        match p.data_type {
            PropertyType::Scalar(_) => {
                if let Some(axis) = axis_index(&p.name) {
                    columns.push((k, ['x', 'y', 'z'][axis]));
                }
            }
            PropertyType::List(..) => break,
        }
    }
    let text = String::from_utf8_lossy(bytes);
    for (vertex, line) in text
        .lines()
        .skip(first_line - 1)
        .take(def.count)
        .enumerate()
    {
        let tokens: Vec<&str> = line.split_ascii_whitespace().collect();
        for &(column, axis) in &columns {
            let value = tokens.get(column).and_then(|t| t.parse::<f32>().ok());
            if let Some(value) = value.filter(|v| !v.is_finite()) {
                return Some(MeshError::NonFinite {
                    at: Location {
                        path: None,
                        line: Some(first_line + vertex),
                    },
                    vertex,
                    axis,
                    value,
                });
            }
        }
    }
    None
}

/// Maps a `ply-rs-bw` error to a [`MeshError::Format`]; `lines_meaningful` is false for errors
/// in a binary payload, where its line counter means nothing.
fn ply_error(e: ParseError, lines_meaningful: bool) -> MeshError {
    let line = e.line().filter(|_| lines_meaningful);
    let mut message = e.to_string();
    if let Some(l) = e.line() {
        let prefix = format!("Line {l}: ");
        if let Some(rest) = message.strip_prefix(&prefix) {
            message = rest.to_owned();
        }
    }
    // The library's messages span lines ("\n\tString: '<line with its newline>'"); keep ours
    // on one.
    let message = message.replace("\n\t", "; ").replace(['\n', '\r'], "");
    MeshError::format(Location { path: None, line }, message)
}

fn axis_index(name: &str) -> Option<usize> {
    match name {
        "x" => Some(0),
        "y" => Some(1),
        "z" => Some(2),
        _ => None,
    }
}

/// A vertex as parsed: only the coordinates are kept.
#[derive(Debug, Default)]
struct VertexElem {
    p: [f32; 3],
}

impl PropertyAccess for VertexElem {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        match (axis_index(name), property.to_f32_lossy()) {
            (Some(i), Some(v)) => {
                self.p[i] = v;
                PropertyAccessResult::Set
            }
            _ => PropertyAccessResult::Ignored,
        }
    }

    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match axis_index(name) {
            Some(i) => {
                self.p[i] = value;
                PropertyAccessResult::Set
            }
            None => PropertyAccessResult::Ignored,
        }
    }

    fn set_double(&mut self, name: &str, value: f64) -> PropertyAccessResult {
        // Nearest f32: the mesh stores f32.
        self.set_float(name, value as f32)
    }
}

/// A face as parsed: its vertex list, or the first negative index found in it.
#[derive(Debug, Default)]
struct FaceElem {
    indices: Vec<u32>,
    signed: Vec<i32>,
    negative: Option<i64>,
}

impl FaceElem {
    fn take_signed<T: Copy + Into<i64>>(&mut self, values: &[T]) -> PropertyAccessResult {
        self.indices.clear();
        for &v in values {
            let v: i64 = v.into();
            match u32::try_from(v) {
                Ok(i) => self.indices.push(i),
                Err(_) => {
                    self.negative.get_or_insert(v);
                }
            }
        }
        PropertyAccessResult::Set
    }
}

fn is_face_list(name: &str) -> bool {
    FACE_LIST_NAMES.contains(&name)
}

impl PropertyAccess for FaceElem {
    fn new() -> Self {
        Self::default()
    }

    fn begin_list_uint(&mut self, name: &str, _len: usize) -> BeginList<'_, u32> {
        if is_face_list(name) {
            BeginList::Fill(&mut self.indices)
        } else {
            BeginList::UseSetter
        }
    }

    fn begin_list_int(&mut self, name: &str, _len: usize) -> BeginList<'_, i32> {
        if is_face_list(name) {
            BeginList::Fill(&mut self.signed)
        } else {
            BeginList::UseSetter
        }
    }

    fn set_list_uchar(&mut self, name: &str, values: Vec<u8>) -> PropertyAccessResult {
        if !is_face_list(name) {
            return PropertyAccessResult::Ignored;
        }
        self.indices = values.into_iter().map(u32::from).collect();
        PropertyAccessResult::Set
    }

    fn set_list_ushort(&mut self, name: &str, values: Vec<u16>) -> PropertyAccessResult {
        if !is_face_list(name) {
            return PropertyAccessResult::Ignored;
        }
        self.indices = values.into_iter().map(u32::from).collect();
        PropertyAccessResult::Set
    }

    fn set_list_char(&mut self, name: &str, values: Vec<i8>) -> PropertyAccessResult {
        if !is_face_list(name) {
            return PropertyAccessResult::Ignored;
        }
        self.take_signed(&values)
    }

    fn set_list_short(&mut self, name: &str, values: Vec<i16>) -> PropertyAccessResult {
        if !is_face_list(name) {
            return PropertyAccessResult::Ignored;
        }
        self.take_signed(&values)
    }
}

/// Signed `int` lists are filled in place; convert them once parsing is done.
fn finish_signed(faces: &mut [FaceElem]) {
    for f in faces {
        if !f.signed.is_empty() {
            let signed = std::mem::take(&mut f.signed);
            f.take_signed(&signed);
        }
    }
}

/// An element we do not need: every property is ignored.
#[derive(Debug)]
struct Skip;

impl PropertyAccess for Skip {
    fn new() -> Self {
        Skip
    }
}

/// Writes a PLY file in the given encoding, atomically. Refuses a mesh that fails
/// [`Mesh::validate`].
pub fn write_ply(path: impl AsRef<Path>, mesh: &Mesh, format: PlyFormat) -> Result<(), MeshError> {
    let path = path.as_ref();
    mesh.validate().map_err(|e| e.in_file(path))?;
    write_atomic(path, |out| write_ply_to(out, mesh, format))
}

/// Writes PLY to any writer (no validation; see [`write_ply`]).
pub fn write_ply_to(mut out: &mut dyn Write, mesh: &Mesh, format: PlyFormat) -> io::Result<()> {
    let mut header = Header::new();
    header.encoding = match format {
        PlyFormat::Ascii => Encoding::Ascii,
        PlyFormat::BinaryLittleEndian => Encoding::BinaryLittleEndian,
        PlyFormat::BinaryBigEndian => Encoding::BinaryBigEndian,
    };
    header.comments.push("written by crease".to_owned());
    let mut vertex = ElementDef::new("vertex".to_owned());
    for axis in ["x", "y", "z"] {
        vertex.properties.add(PropertyDef::new(
            axis.to_owned(),
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    vertex.count = mesh.positions.len();
    let mut face = ElementDef::new("face".to_owned());
    face.properties.add(PropertyDef::new(
        "vertex_indices".to_owned(),
        PropertyType::List(ScalarType::UChar, ScalarType::UInt),
    ));
    face.count = mesh.triangles.len();
    header.elements.add(vertex.clone());
    header.elements.add(face.clone());

    Writer::<VertexOut>::new().write_header(&mut out, &header)?;
    let vertices: Vec<VertexOut> = mesh.positions.iter().map(|&p| VertexOut(p)).collect();
    Writer::<VertexOut>::new().write_payload_of_element(&mut out, &vertices, &vertex, &header)?;
    drop(vertices);
    let faces: Vec<FaceOut> = mesh.triangles.iter().map(|&t| FaceOut(t)).collect();
    Writer::<FaceOut>::new().write_payload_of_element(&mut out, &faces, &face, &header)?;
    Ok(())
}

/// A vertex to write.
#[derive(Debug)]
struct VertexOut(Vec3);

impl PropertyAccess for VertexOut {
    fn new() -> Self {
        VertexOut(Vec3::ZERO)
    }

    fn get_float(&self, name: &str) -> Option<f32> {
        axis_index(name).map(|i| self.0[i])
    }
}

/// A triangle to write.
#[derive(Debug)]
struct FaceOut([u32; 3]);

impl PropertyAccess for FaceOut {
    fn new() -> Self {
        FaceOut([0; 3])
    }

    fn get_list_uint(&self, name: &str) -> Option<&[u32]> {
        is_face_list(name).then_some(&self.0[..])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASCII_QUAD: &str = "ply\nformat ascii 1.0\ncomment test\nelement vertex 4\n\
        property float x\nproperty float y\nproperty float z\nelement face 1\n\
        property list uchar int vertex_index\nend_header\n\
        0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3\n";

    #[test]
    fn ascii_quad_is_triangulated() {
        let m = parse_ply(ASCII_QUAD.as_bytes()).unwrap();
        assert_eq!(m.positions.len(), 4);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert_eq!(m.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn ascii_nan_reports_line_and_vertex() {
        let text = ASCII_QUAD.replace("1 1 0\n", "1 nan 0\n");
        let e = parse_ply(text.as_bytes()).unwrap_err();
        // Header is 10 lines; vertex 2 is on line 13.
        assert_eq!(
            e.to_string(),
            "line 13: vertex 2 has a non-finite y coordinate (NaN)"
        );
        let text = ASCII_QUAD.replace("0 1 0\n", "0 1 -inf\n");
        let e = parse_ply(text.as_bytes()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 14: vertex 3 has a non-finite z coordinate (-inf)"
        );
    }

    #[test]
    fn ascii_overflow_to_inf_reports_line() {
        let text = ASCII_QUAD.replace("1 0 0\n", "1e39 0 0\n");
        let e = parse_ply(text.as_bytes()).unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 12: vertex 1 has a non-finite x coordinate (inf)"
        );
    }

    fn binary_with(format: PlyFormat, mesh: &Mesh) -> Vec<u8> {
        let mut buf = Vec::new();
        write_ply_to(&mut buf, mesh, format).unwrap();
        buf
    }

    fn square() -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn binary_nan_reports_vertex_without_line() {
        let mut m = square();
        m.positions[3].x = f32::NAN;
        for format in [PlyFormat::BinaryLittleEndian, PlyFormat::BinaryBigEndian] {
            let e = parse_ply(&binary_with(format, &m)).unwrap_err();
            assert_eq!(
                e.to_string(),
                "in-memory mesh: vertex 3 has a non-finite x coordinate (NaN)"
            );
        }
    }

    #[test]
    fn all_encodings_round_trip_in_memory() {
        for format in [
            PlyFormat::Ascii,
            PlyFormat::BinaryLittleEndian,
            PlyFormat::BinaryBigEndian,
        ] {
            assert_eq!(
                parse_ply(&binary_with(format, &square())).unwrap(),
                square()
            );
        }
    }

    #[test]
    fn double_coordinates_and_short_signed_lists() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\n\
            property double y\nproperty double z\nproperty uchar red\nelement face 1\n\
            property list uchar short vertex_indices\nelement edge 1\nproperty int a\n\
            end_header\n0.1 0 0 255\n1 0 0 0\n0 1 0 7\n3 2 1 0\n9\n";
        let m = parse_ply(text.as_bytes()).unwrap();
        assert_eq!(m.positions[0].x, 0.1f32);
        assert_eq!(m.triangles, vec![[2, 1, 0]]);
    }

    #[test]
    fn bad_faces_are_reported() {
        let neg = ASCII_QUAD.replace("4 0 1 2 3", "3 0 -1 2");
        assert_eq!(
            parse_ply(neg.as_bytes()).unwrap_err().to_string(),
            "line 15: face 0: negative vertex index -1"
        );
        let short = ASCII_QUAD.replace("4 0 1 2 3", "2 0 1");
        assert_eq!(
            parse_ply(short.as_bytes()).unwrap_err().to_string(),
            "line 15: face 0: expected at least 3 vertices, got 2"
        );
        let range = ASCII_QUAD.replace("4 0 1 2 3", "4 0 1 2 4");
        assert_eq!(
            parse_ply(range.as_bytes()).unwrap_err().to_string(),
            "line 15: triangle 1 refers to vertex 4, but there are only 4 vertices"
        );
    }

    #[test]
    fn header_problems_are_reported() {
        let no_z = ASCII_QUAD.replace("property float z\n", "");
        let e = parse_ply(no_z.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("vertex element has no property 'z'"), "{e}");
        let no_list = ASCII_QUAD.replace("vertex_index", "corners");
        let e = parse_ply(no_list.as_bytes()).unwrap_err().to_string();
        assert!(
            e.contains("neither 'vertex_indices' nor 'vertex_index'"),
            "{e}"
        );
        let e = parse_ply(b"plx\n").unwrap_err().to_string();
        assert!(e.starts_with("line 1: "), "{e}");
    }

    #[test]
    fn truncated_binary_is_an_error() {
        let buf = binary_with(PlyFormat::BinaryLittleEndian, &square());
        assert!(parse_ply(&buf[..buf.len() - 3]).is_err());
    }
}

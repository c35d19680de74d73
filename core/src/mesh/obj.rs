//! Wavefront OBJ: reader and writer.
//!
//! The reader is a small line parser rather than `tobj`: `tobj` renumbers vertices in the order
//! faces first use them (and drops unused ones), even with `single_index: false`, while example
//! meshes must keep file order because they correspond by vertex index. (On the horse reference,
//! the first face starts at vertex 8431, so `tobj` would make that vertex number 0.) Parsing
//! ourselves also gives every error its line number. A test checks our triangles against `tobj`'s
//! corner by corner.
//!
//! Read: `v x y z [w]` (divided by `w` when present; a 6-value `v` with colours keeps the first
//! three), `f` with `v`, `v/vt`, `v//vn` or `v/vt/vn` tokens, 1-based or negative (relative)
//! indices, polygons fan-triangulated as `(0, i, i + 1)`. All objects and groups go into one mesh
//! (OBJ indices are file-global, so no offsetting is needed). Everything else (`vt`, `vn`, `o`,
//! `g`, `s`, `usemtl`, `mtllib`, `l`, `p`, comments, also after a statement) is ignored.

use std::io::{self, Write};
use std::path::Path;

use glam::Vec3;

use super::error::{Location, MeshError};
use super::{Mesh, first_non_finite, write_atomic};

/// Reads an OBJ file. Vertices keep file order; polygons are fan-triangulated.
pub fn read_obj(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
    let path = path.as_ref();
    let bytes = std::fs::read(path).map_err(|e| MeshError::io(path, e))?;
    // Names and comments may be Latin-1; the statements we read are ASCII.
    let text = String::from_utf8_lossy(&bytes);
    parse_obj(&text).map_err(|e| e.in_file(path))
}

/// Parses OBJ text. Errors carry the line but no file (see [`read_obj`] for that).
pub fn parse_obj(text: &str) -> Result<Mesh, MeshError> {
    let mut mesh = Mesh::default();
    // Faces may name vertices defined further down; such indices are checked at the end.
    let mut forward: Vec<(usize, usize, u64)> = Vec::new();
    let mut face: Vec<u32> = Vec::with_capacity(8);

    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let at = || Location {
            path: None,
            line: Some(line_no),
        };
        // Some exporters put comments after statements.
        let statement = line.split('#').next().unwrap_or("");
        let mut words = statement.split_ascii_whitespace();
        match words.next() {
            Some("v") => {
                let vertex = mesh.positions.len();
                let mut values = [0.0f32; 4];
                let mut n = 0;
                for word in words.by_ref().take(4) {
                    values[n] = word.parse().map_err(|_| {
                        MeshError::format(
                            at(),
                            format!("vertex {vertex}: {word:?} is not a number"),
                        )
                    })?;
                    n += 1;
                }
                if n < 3 {
                    return Err(MeshError::format(
                        at(),
                        format!("vertex {vertex}: expected 3 coordinates, got {n}"),
                    ));
                }
                let mut p = Vec3::new(values[0], values[1], values[2]);
                if let Some((axis, value)) = first_non_finite(p) {
                    return Err(MeshError::NonFinite {
                        at: at(),
                        vertex,
                        axis,
                        value,
                    });
                }
                // Exactly 4 values is `x y z w`; 6 (or more) is `x y z r g b`.
                if n == 4 && words.next().is_none() {
                    let w = values[3];
                    if w == 0.0 || !w.is_finite() {
                        return Err(MeshError::format(
                            at(),
                            format!("vertex {vertex}: weight w = {w} (expected finite, non-zero)"),
                        ));
                    }
                    if w != 1.0 {
                        p /= w;
                        // A tiny weight can overflow finite coordinates (fuzz finding
                        // `mesh_obj/weight-divides-to-infinity.obj`).
                        if let Some((axis, value)) = first_non_finite(p) {
                            return Err(MeshError::format(
                                at(),
                                format!(
                                    "vertex {vertex}: {axis} / w is {value}, not finite (w = {w})"
                                ),
                            ));
                        }
                    }
                }
                mesh.positions.push(p);
            }
            Some("f") => {
                face.clear();
                let count = mesh.positions.len();
                for word in words {
                    let v = word.split('/').next().unwrap_or("");
                    let index: i64 = v.parse().map_err(|_| {
                        MeshError::format(at(), format!("face: {word:?} is not a vertex index"))
                    })?;
                    let zero_based = match index {
                        0 => {
                            return Err(MeshError::format(
                                at(),
                                "face: vertex index 0 (OBJ indices start at 1)",
                            ));
                        }
                        i if i > 0 => i - 1,
                        i => count as i64 + i,
                    };
                    let Ok(zero_based) = u32::try_from(zero_based) else {
                        return Err(MeshError::format(
                            at(),
                            format!(
                                "face: vertex index {index} is out of range ({count} vertices so \
                                 far)"
                            ),
                        ));
                    };
                    face.push(zero_based);
                }
                if face.len() < 3 {
                    return Err(MeshError::format(
                        at(),
                        format!("face: expected at least 3 vertices, got {}", face.len()),
                    ));
                }
                for k in 1..face.len() - 1 {
                    let t = [face[0], face[k], face[k + 1]];
                    // The furthest corner, not the first late one (fuzz finding
                    // `mesh_obj/forward-index-past-the-first-late-corner.obj`).
                    let furthest = t.iter().copied().max().unwrap_or(0);
                    if furthest as usize >= count {
                        forward.push((line_no, mesh.triangles.len(), u64::from(furthest)));
                    }
                    mesh.triangles.push(t);
                }
            }
            _ => {}
        }
    }

    let vertex_count = mesh.positions.len();
    if let Some(&(line, triangle, index)) = forward
        .iter()
        .find(|&&(_, _, index)| index as usize >= vertex_count)
    {
        return Err(MeshError::IndexOutOfRange {
            at: Location {
                path: None,
                line: Some(line),
            },
            triangle,
            index,
            vertex_count,
        });
    }
    Ok(mesh)
}

/// Writes an OBJ file (`v x y z` lines, then 1-based `f a b c` lines), atomically. Coordinates
/// use `f32`'s shortest round-trip form, so reading the file back gives identical bits.
pub fn write_obj(path: impl AsRef<Path>, mesh: &Mesh) -> Result<(), MeshError> {
    let path = path.as_ref();
    mesh.validate().map_err(|e| e.in_file(path))?;
    write_atomic(path, |out| write_obj_to(out, mesh))
}

/// Writes OBJ text to any writer (no validation; see [`write_obj`]).
pub fn write_obj_to(out: &mut dyn Write, mesh: &Mesh) -> io::Result<()> {
    writeln!(
        out,
        "# crease: {} vertices, {} triangles",
        mesh.positions.len(),
        mesh.triangles.len()
    )?;
    for p in &mesh.positions {
        // `{}` on f32 prints the shortest decimal that parses back to the same f32.
        writeln!(out, "v {} {} {}", p.x, p.y, p.z)?;
    }
    for t in &mesh.triangles {
        writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quads_and_polygons_are_fan_triangulated_in_file_order() {
        let m = parse_obj(
            "# quad then pentagon\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 2 2\n\
             f 1 2 3 4\ng b\nf 5/1 4/2/3 3//1 2 1\n",
        )
        .unwrap();
        assert_eq!(m.positions.len(), 5);
        assert_eq!(m.positions[4], Vec3::splat(2.0));
        assert_eq!(
            m.triangles,
            vec![[0, 1, 2], [0, 2, 3], [4, 3, 2], [4, 2, 1], [4, 1, 0]]
        );
    }

    #[test]
    fn negative_indices_are_relative_to_vertices_so_far() {
        let m = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -1 -2 -3\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2], [3, 2, 1]]);
    }

    #[test]
    fn forward_references_are_allowed_but_range_checked() {
        let m = parse_obj("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
        let e = parse_obj("v 0 0 0\nv 1 0 0\n\nf 1 2 4\nv 0 1 0\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 4: triangle 0 refers to vertex 3, but there are only 3 vertices"
        );
    }

    #[test]
    fn nan_and_inf_report_the_line_vertex_and_axis() {
        let text = "# c\nv 0 0 0\nv 1 0 0\n\nv 0 nan 0\nf 1 2 3\n";
        let e = parse_obj(text).unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 5: vertex 2 has a non-finite y coordinate (NaN)"
        );
        // 1e39 overflows f32 to +inf.
        let e = parse_obj("v 0 0 1e39\n").unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 1: vertex 0 has a non-finite z coordinate (inf)"
        );
    }

    #[test]
    fn malformed_statements_name_the_line() {
        let cases = [
            ("v 0 0\n", "line 1: vertex 0: expected 3 coordinates, got 2"),
            ("v 0 x 0\n", "line 1: vertex 0: \"x\" is not a number"),
            (
                "v 0 0 0\nf 1 2\n",
                "line 2: face: expected at least 3 vertices, got 2",
            ),
            (
                "v 0 0 0\nf 0 1 1\n",
                "line 2: face: vertex index 0 (OBJ indices start at 1)",
            ),
            (
                "v 0 0 0\nf 1 1 a\n",
                "line 2: face: \"a\" is not a vertex index",
            ),
            (
                "v 0 0 0\nf 1 1 -2\n",
                "line 2: face: vertex index -2 is out of range (1 vertices so far)",
            ),
            (
                "v 0 0 0 0\n",
                "line 1: vertex 0: weight w = 0 (expected finite, non-zero)",
            ),
        ];
        for (text, want) in cases {
            assert_eq!(parse_obj(text).unwrap_err().to_string(), want, "{text:?}");
        }
    }

    #[test]
    fn w_divides_and_colours_are_ignored() {
        let m = parse_obj("v 2 4 6 2\nv 1 2 3 0.5 0.5 0.5\n").unwrap();
        assert_eq!(
            m.positions,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 2.0, 3.0)]
        );
    }

    #[test]
    fn crlf_whitespace_and_trailing_comments_are_accepted() {
        let m = parse_obj("v  0 0 0\r\nv\t1 0 0 # x\r\nv 0 1 0 \r\nf 1 2 3#face\r\n").unwrap();
        assert_eq!(m.positions.len(), 3);
        assert_eq!(m.triangles, vec![[0, 1, 2]]);
    }

    #[test]
    fn written_text_reads_back_bit_exact() {
        let m = Mesh {
            positions: vec![
                Vec3::new(0.1, -0.0, 1e-30),
                Vec3::new(f32::MAX, f32::MIN_POSITIVE, -3.4028235e38),
                Vec3::new(1.0 / 3.0, 2.0f32.sqrt(), 1e-45),
            ],
            triangles: vec![[0, 1, 2], [2, 1, 0]],
        };
        let mut buf = Vec::new();
        write_obj_to(&mut buf, &m).unwrap();
        let back = parse_obj(std::str::from_utf8(&buf).unwrap()).unwrap();
        assert_eq!(back.triangles, m.triangles);
        for (a, b) in back.positions.iter().zip(&m.positions) {
            for k in 0..3 {
                assert_eq!(a[k].to_bits(), b[k].to_bits());
            }
        }
    }
}

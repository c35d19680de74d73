//! Triangle meshes: the [`Mesh`] type, file formats and topology helpers.
//!
//! Layout:
//! - this file: [`Mesh`], format dispatch by extension ([`Mesh::read`], [`Mesh::write`]),
//!   [`Mesh::validate`].
//! - [`error`]: [`MeshError`] and [`Location`] (file + line in every message).
//! - [`obj`], [`ply`], [`gltf`]: one module per file format, readers and writers.
//! - [`topology`]: vertex normals, unique edges, vertex adjacency ([`Adjacency`]).
//! - [`examples`]: [`ExampleSet`], a folder or TOML manifest of meshes sharing one topology.
//! - [`subdivision`]: Loop subdivision as a sparse matrix `S` (the detail layer's `S · base`).
//! - [`test_meshes`]: the fixture meshes every test shares (tube, grid, tetrahedron); only in
//!   tests (core's own, or any crate's with the `test-meshes` feature).
//!
//! Every reader keeps the file's vertex order (examples correspond by vertex index) and returns a
//! mesh that passes [`Mesh::validate`]: indices in range, coordinates finite.

use std::io::{self, Write};
use std::path::Path;

use glam::Vec3;

pub mod error;
pub mod examples;
pub mod gltf;
pub mod obj;
pub mod ply;
pub mod subdivision;
// `doc` too, so the docs (and the Layout's link) show it whatever the features.
#[cfg(any(test, feature = "test-meshes", doc))]
pub mod test_meshes;
pub mod topology;

pub use error::{Location, MeshError};
pub use examples::{ExampleSet, LoadProgress, NamedMesh};
pub use ply::PlyFormat;
pub use topology::{Adjacency, compute_vertex_normals};

/// A triangle mesh: positions and counter-clockwise triangles indexing them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Triangles as vertex indices.
    pub triangles: Vec<[u32; 3]>,
}

impl Mesh {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Axis-aligned bounding box `(min, max)`; `(ZERO, ZERO)` for an empty mesh.
    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        let mut it = self.positions.iter();
        let Some(&first) = it.next() else {
            return (Vec3::ZERO, Vec3::ZERO);
        };
        it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)))
    }

    /// Largest side of the bounding box: the unit of the papers' error measure (HZY11 Table 2
    /// scales it to 1).
    pub fn bbox_diagonal_scale(&self) -> f32 {
        let (lo, hi) = self.bounding_box();
        (hi - lo).max_element()
    }

    /// Reads a mesh, choosing the format by extension (case-insensitive): `.obj`, `.ply`,
    /// `.gltf`, `.glb`. The result passes [`Mesh::validate`].
    pub fn read(path: impl AsRef<Path>) -> Result<Mesh, MeshError> {
        let path = path.as_ref();
        match MeshFormat::from_path(path)? {
            MeshFormat::Obj => obj::read_obj(path),
            MeshFormat::Ply => ply::read_ply(path),
            MeshFormat::Gltf | MeshFormat::Glb => gltf::read_gltf(path),
        }
    }

    /// Writes the mesh, choosing the format by extension (case-insensitive): OBJ text, binary
    /// little-endian PLY, glTF with an embedded buffer, or GLB. The file is written to a
    /// temporary file beside it and renamed into place, so a reader never sees half a mesh.
    /// Refuses a mesh that fails [`Mesh::validate`] (it could not be read back).
    pub fn write(&self, path: impl AsRef<Path>) -> Result<(), MeshError> {
        let path = path.as_ref();
        match MeshFormat::from_path(path)? {
            MeshFormat::Obj => obj::write_obj(path, self),
            MeshFormat::Ply => ply::write_ply(path, self, PlyFormat::BinaryLittleEndian),
            MeshFormat::Gltf => gltf::write_gltf(path, self),
            MeshFormat::Glb => gltf::write_glb(path, self),
        }
    }

    /// Checks that every triangle index is below [`Mesh::vertex_count`] and every coordinate is
    /// finite. Reports the first problem (vertices before triangles) with an in-memory
    /// [`Location`].
    pub fn validate(&self) -> Result<(), MeshError> {
        for (vertex, p) in self.positions.iter().enumerate() {
            if let Some((axis, value)) = first_non_finite(*p) {
                return Err(MeshError::NonFinite {
                    at: Location::default(),
                    vertex,
                    axis,
                    value,
                });
            }
        }
        check_indices(&self.triangles, self.positions.len(), &Location::default())
    }
}

/// The mesh file formats, known by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// Stanford PLY (`.ply`), ASCII or binary.
    Ply,
    /// glTF 2.0 JSON (`.gltf`).
    Gltf,
    /// glTF 2.0 binary (`.glb`).
    Glb,
}

impl MeshFormat {
    /// The extensions recognised, lower case, without the dot.
    pub const EXTENSIONS: [&'static str; 4] = ["obj", "ply", "gltf", "glb"];

    /// The format of `path` by its extension (case-insensitive), or `None`.
    pub fn detect(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(MeshFormat::Obj),
            "ply" => Some(MeshFormat::Ply),
            "gltf" => Some(MeshFormat::Gltf),
            "glb" => Some(MeshFormat::Glb),
            _ => None,
        }
    }

    /// Like [`MeshFormat::detect`], but an unknown extension is a [`MeshError::UnknownFormat`].
    pub fn from_path(path: &Path) -> Result<MeshFormat, MeshError> {
        Self::detect(path).ok_or_else(|| MeshError::UnknownFormat {
            path: path.to_path_buf(),
            ext: path
                .extension()
                .map(|e| e.to_string_lossy().into_owned())
                .unwrap_or_default(),
        })
    }
}

/// The first coordinate of `p` that is NaN or infinite, with its axis name.
pub(crate) fn first_non_finite(p: Vec3) -> Option<(char, f32)> {
    if p.is_finite() {
        return None;
    }
    ['x', 'y', 'z']
        .into_iter()
        .zip(p.to_array())
        .find(|(_, v)| !v.is_finite())
}

/// Checks every index of `triangles` against `vertex_count`.
pub(crate) fn check_indices(
    triangles: &[[u32; 3]],
    vertex_count: usize,
    at: &Location,
) -> Result<(), MeshError> {
    for (triangle, t) in triangles.iter().enumerate() {
        if let Some(&index) = t.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(MeshError::IndexOutOfRange {
                at: at.clone(),
                triangle,
                index: u64::from(index),
                vertex_count,
            });
        }
    }
    Ok(())
}

/// Writes `path` atomically (see [`crate::atomic::write_atomic_with`]), naming the path in the
/// error.
pub(crate) fn write_atomic(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> Result<(), MeshError> {
    crate::atomic::write_atomic_with(path, write).map_err(|e| MeshError::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri() -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            triangles: vec![[0, 1, 2]],
        }
    }

    #[test]
    fn validate_accepts_good_mesh_and_empty_mesh() {
        tri().validate().unwrap();
        Mesh::default().validate().unwrap();
    }

    #[test]
    fn validate_reports_out_of_range_index() {
        let mut m = tri();
        m.triangles.push([0, 2, 3]);
        let e = m.validate().unwrap_err();
        assert!(
            matches!(
                e,
                MeshError::IndexOutOfRange {
                    triangle: 1,
                    index: 3,
                    vertex_count: 3,
                    ..
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn validate_reports_nan_and_inf_with_axis() {
        let mut m = tri();
        m.positions[2].z = f32::NAN;
        let e = m.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "in-memory mesh: vertex 2 has a non-finite z coordinate (NaN)"
        );
        m.positions[1].y = f32::NEG_INFINITY;
        let e = m.validate().unwrap_err();
        assert_eq!(
            e.to_string(),
            "in-memory mesh: vertex 1 has a non-finite y coordinate (-inf)"
        );
    }

    #[test]
    fn format_detection_is_case_insensitive() {
        assert_eq!(
            MeshFormat::detect(Path::new("a/B.OBJ")),
            Some(MeshFormat::Obj)
        );
        assert_eq!(
            MeshFormat::detect(Path::new("x.Glb")),
            Some(MeshFormat::Glb)
        );
        assert_eq!(MeshFormat::detect(Path::new("x.txt")), None);
        assert_eq!(MeshFormat::detect(Path::new("noext")), None);
        let e = Mesh::read("cactusBottomMask.txt").unwrap_err();
        assert!(matches!(e, MeshError::UnknownFormat { .. }), "{e}");
        assert!(e.to_string().contains("\"txt\""), "{e}");
    }

    #[test]
    fn write_atomic_leaves_no_temp_file_and_replaces_target() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.obj");
        std::fs::write(&path, "old").unwrap();
        tri().write(&path).unwrap();
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("m.obj")]);
        assert_eq!(Mesh::read(&path).unwrap(), tri());
    }

    #[test]
    fn failed_write_leaves_target_untouched() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("m.obj");
        std::fs::write(&path, "old").unwrap();
        let mut bad = tri();
        bad.positions[0].x = f32::NAN;
        assert!(bad.write(&path).is_err());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}

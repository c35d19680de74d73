//! [`MeshError`]: everything that can go wrong reading, writing, validating or assembling meshes.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where a problem was found: a file, and for text formats the 1-based line.
///
/// Displays as `path line N`, `path`, or `in-memory mesh` when neither is known (a mesh that did
/// not come from a file, e.g. checked with [`Mesh::validate`](super::Mesh::validate)).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Location {
    /// The file, when the mesh came from one.
    pub path: Option<PathBuf>,
    /// The 1-based line in a text file (OBJ, ASCII PLY, TOML).
    pub line: Option<usize>,
}

impl Location {
    /// A whole file, no line.
    pub fn file(path: impl Into<PathBuf>) -> Self {
        Self {
            path: Some(path.into()),
            line: None,
        }
    }

    /// A line of a file.
    pub fn line(path: impl Into<PathBuf>, line: usize) -> Self {
        Self {
            path: Some(path.into()),
            line: Some(line),
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.path, self.line) {
            (Some(p), Some(l)) => write!(f, "{} line {l}", p.display()),
            (Some(p), None) => write!(f, "{}", p.display()),
            (None, Some(l)) => write!(f, "line {l}"),
            (None, None) => f.write_str("in-memory mesh"),
        }
    }
}

/// An error from the [`mesh`](super) module. Every message names the file (and line, for text
/// formats), the field, and what was expected versus found.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened, read, written or renamed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },

    /// The extension is not one of the known mesh formats.
    #[error(
        "{}: unknown mesh format {ext:?} (expected one of .obj, .ply, .gltf, .glb)",
        path.display()
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Its extension ("" when it has none).
        ext: String,
    },

    /// The file is malformed or uses a feature this reader does not support.
    #[error("{at}: {message}")]
    Format {
        /// File and line.
        at: Location,
        /// What was wrong, with expected versus found where it applies.
        message: String,
    },

    /// A vertex coordinate is NaN or infinite.
    #[error("{at}: vertex {vertex} has a non-finite {axis} coordinate ({value})")]
    NonFinite {
        /// File and line (line only for text formats).
        at: Location,
        /// 0-based vertex index.
        vertex: usize,
        /// `x`, `y` or `z`.
        axis: char,
        /// The offending value (NaN, inf or -inf).
        value: f32,
    },

    /// A triangle refers to a vertex that does not exist.
    #[error(
        "{at}: triangle {triangle} refers to vertex {index}, but there are only {vertex_count} \
         vertices"
    )]
    IndexOutOfRange {
        /// File and line.
        at: Location,
        /// 0-based triangle index (after triangulation).
        triangle: usize,
        /// The 0-based vertex index found.
        index: u64,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },

    /// An example has a different number of vertices than the rest pose.
    #[error("{}: {count} vertices, {reference} has {expected}", path.display())]
    VertexCountMismatch {
        /// The example file.
        path: PathBuf,
        /// Its vertex count.
        count: usize,
        /// The rest pose's name.
        reference: String,
        /// The rest pose's vertex count.
        expected: usize,
    },

    /// An example has a different number of triangles than the rest pose.
    #[error("{}: {count} triangles, {reference} has {expected}", path.display())]
    TriangleCountMismatch {
        /// The example file.
        path: PathBuf,
        /// Its triangle count.
        count: usize,
        /// The rest pose's name.
        reference: String,
        /// The rest pose's triangle count.
        expected: usize,
    },

    /// An example's triangles differ from the rest pose's: the first differing one.
    #[error("{}: triangle {triangle} is {got:?}, {reference} has {expected:?}", path.display())]
    TopologyMismatch {
        /// The example file.
        path: PathBuf,
        /// 0-based index of the first differing triangle.
        triangle: usize,
        /// The example's triangle.
        got: [u32; 3],
        /// The rest pose's name.
        reference: String,
        /// The rest pose's triangle.
        expected: [u32; 3],
    },

    /// A control point index is not a vertex of the rest pose.
    #[error(
        "{at}: control_points[{position}] = {vertex} is out of range ({reference} has \
         {vertex_count} vertices)"
    )]
    ControlPointOutOfRange {
        /// The manifest (or in-memory set).
        at: Location,
        /// Position in the `control_points` list.
        position: usize,
        /// The vertex index given.
        vertex: u32,
        /// The rest pose's name.
        reference: String,
        /// The rest pose's vertex count.
        vertex_count: usize,
    },

    /// An example-set manifest or folder is unusable (bad TOML, unknown key, a glob matching
    /// nothing, no meshes at all).
    #[error("{at}: {message}")]
    ExampleSet {
        /// The manifest or folder (with the TOML line when known).
        at: Location,
        /// What was wrong.
        message: String,
    },
}

impl MeshError {
    /// An I/O error on `path`.
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            source,
        }
    }

    /// A format error at `at`.
    pub(crate) fn format(at: Location, message: impl Into<String>) -> Self {
        Self::Format {
            at,
            message: message.into(),
        }
    }

    /// Fills in the file for errors found on an in-memory mesh (from [`Mesh::validate`]), so a
    /// reader can report them against the file it read.
    ///
    /// [`Mesh::validate`]: super::Mesh::validate
    pub(crate) fn in_file(mut self, path: &Path) -> Self {
        match &mut self {
            Self::Format { at, .. }
            | Self::NonFinite { at, .. }
            | Self::IndexOutOfRange { at, .. }
            | Self::ControlPointOutOfRange { at, .. }
            | Self::ExampleSet { at, .. }
                if at.path.is_none() =>
            {
                at.path = Some(path.to_path_buf());
            }
            _ => {}
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_name_file_line_and_values() {
        let e = MeshError::NonFinite {
            at: Location::line("horse/poses/3.obj", 812),
            vertex: 811,
            axis: 'y',
            value: f32::NAN,
        };
        assert_eq!(
            e.to_string(),
            "horse/poses/3.obj line 812: vertex 811 has a non-finite y coordinate (NaN)"
        );
        let e = MeshError::TopologyMismatch {
            path: "gallop/0007.obj".into(),
            triangle: 1234,
            got: [5, 6, 7],
            reference: "reference.obj".into(),
            expected: [5, 6, 8],
        };
        assert_eq!(
            e.to_string(),
            "gallop/0007.obj: triangle 1234 is [5, 6, 7], reference.obj has [5, 6, 8]"
        );
        let e = MeshError::VertexCountMismatch {
            path: "x.obj".into(),
            count: 8430,
            reference: "reference.obj".into(),
            expected: 8431,
        };
        assert_eq!(
            e.to_string(),
            "x.obj: 8430 vertices, reference.obj has 8431"
        );
    }

    #[test]
    fn in_file_fills_only_a_missing_path() {
        let e = MeshError::format(Location::default(), "bad").in_file(Path::new("a.obj"));
        assert_eq!(e.to_string(), "a.obj: bad");
        let e = MeshError::format(Location::file("b.obj"), "bad").in_file(Path::new("a.obj"));
        assert_eq!(e.to_string(), "b.obj: bad");
    }
}

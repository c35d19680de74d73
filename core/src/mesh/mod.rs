//! Triangle meshes: the [`Mesh`] type, file formats and topology helpers.

use glam::Vec3;

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
}

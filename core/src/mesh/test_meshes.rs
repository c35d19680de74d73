//! Small meshes the unit tests of `mesh` and `runtime` share.

use glam::Vec3;

use super::Mesh;

/// Regular tetrahedron, outward-facing counter-clockwise triangles.
pub(crate) fn tetrahedron() -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
        ],
        triangles: vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
    }
}

/// A grid of `nx x ny` vertices at `at(i, j)`, two triangles a quad.
pub(crate) fn grid(nx: u32, ny: u32, at: impl Fn(u32, u32) -> Vec3) -> Mesh {
    let mut m = Mesh::default();
    for j in 0..ny {
        for i in 0..nx {
            m.positions.push(at(i, j));
        }
    }
    let id = |a: u32, b: u32| b * nx + a;
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            m.triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            m.triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    m
}

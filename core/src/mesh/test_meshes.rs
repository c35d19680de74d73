//! Small meshes the tests share: the one definition of each fixture mesh of the workspace.
//!
//! Compiled for core's own unit tests, and for everyone else with the `test-meshes` feature
//! (never by a normal build). Crates above `crease-train` and `crease-server` take them from
//! `crease-testkit`, which re-exports them; core's integration tests and train's tests (crates
//! the kit depends on, so they cannot dev-depend on it) enable the feature themselves.

use glam::{Quat, Vec3};

use super::Mesh;

/// Regular tetrahedron, outward-facing counter-clockwise triangles.
pub fn tetrahedron() -> Mesh {
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

/// A grid of `nx x ny` vertices, vertex `(i, j)` at index `j nx + i` and at `at(i, j)` (called
/// in index order, so a seeded random `at` is reproducible), two triangles a quad: each quad split
/// along `(i, j)-(i+1, j+1)` into `[(i,j), (i+1,j), (i+1,j+1)]` and `[(i,j), (i+1,j+1), (i,j+1)]`
/// (counter-clockwise seen from +Z when `at` keeps `x` with `i` and `y` with `j`).
pub fn grid(nx: u32, ny: u32, mut at: impl FnMut(u32, u32) -> Vec3) -> Mesh {
    let mut m = Mesh::default();
    for j in 0..ny {
        for i in 0..nx {
            m.positions.push(at(i, j));
        }
    }
    let id = |a: u32, b: u32| b * nx + a;
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            m.triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            m.triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    m
}

/// A flat `w x w` [`grid`] at unit spacing in the z = 0 plane: vertex `(i, j)` at `(i, j, 0)`.
pub fn unit_grid(w: usize) -> Mesh {
    let w = w as u32;
    grid(w, w, |i, j| Vec3::new(i as f32, j as f32, 0.0))
}

/// A tube along z from 0 to `length`: `rings` rings of `around` unit-radius vertices, open at
/// both ends. Vertex `a` of ring `r` is at index `r around + a`, angle `2 pi a / around`, height
/// `length r / (rings - 1)`; each quad between two rings is split into two triangles facing out.
///
/// # Panics
/// If `rings < 2`.
pub fn tube(rings: usize, around: usize, length: f32) -> Mesh {
    let mut positions = Vec::with_capacity(rings * around);
    for r in 0..rings {
        let z = length * r as f32 / (rings - 1) as f32;
        for a in 0..around {
            let phi = std::f32::consts::TAU * a as f32 / around as f32;
            positions.push(Vec3::new(phi.cos(), phi.sin(), z));
        }
    }
    let mut triangles = Vec::with_capacity(2 * (rings - 1) * around);
    for r in 0..rings - 1 {
        for a in 0..around {
            let i0 = (r * around + a) as u32;
            let i1 = (r * around + (a + 1) % around) as u32;
            let (j0, j1) = (i0 + around as u32, i1 + around as u32);
            triangles.push([i0, i1, j1]);
            triangles.push([i0, j1, j0]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// `rest`'s positions with everything above the height `pivot` turned by `angle` about the
/// x axis through `(0, 0, pivot)`: a [`tube`] bent at one joint (rigid segments either side).
pub fn bend(rest: &Mesh, pivot: f32, angle: f32) -> Vec<Vec3> {
    let q = Quat::from_rotation_x(angle);
    let pivot = Vec3::new(0.0, 0.0, pivot);
    rest.positions
        .iter()
        .map(|&p| {
            if p.z > pivot.z {
                pivot + q * (p - pivot)
            } else {
                p
            }
        })
        .collect()
}

//! Meshes shared by the integration tests.

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;

/// A tube along z from 0 to `length`: `rings` rings of `around` unit-radius vertices,
/// triangulated.
pub fn tube(rings: usize, around: usize, length: f32) -> Mesh {
    let mut positions = Vec::new();
    for r in 0..rings {
        let z = length * r as f32 / (rings - 1) as f32;
        for a in 0..around {
            let phi = std::f32::consts::TAU * a as f32 / around as f32;
            positions.push(Vec3::new(phi.cos(), phi.sin(), z));
        }
    }
    let mut triangles = Vec::new();
    for r in 0..rings - 1 {
        for a in 0..around {
            let i0 = (r * around + a) as u32;
            let i1 = (r * around + (a + 1) % around) as u32;
            let j0 = i0 + around as u32;
            let j1 = i1 + around as u32;
            triangles.push([i0, i1, j1]);
            triangles.push([i0, j1, j0]);
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

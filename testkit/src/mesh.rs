//! The fixture meshes every test shares. Defined once, in `crease_core::mesh::test_meshes`
//! (core's `test-meshes` feature, which this crate turns on), because core's own unit tests use
//! them and cannot use this crate; here they are re-exported for everyone above.

pub use crease_core::mesh::test_meshes::{bend, grid, tetrahedron, tube, unit_grid};

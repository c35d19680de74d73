//! crease-core: what runs per frame. No async, no network, nothing from the rest of the
//! workspace (ARCHITECTURE.md's dependency rules, checked by `client/tests/house_rules.rs`).
//!
//! Layout:
//! - [`mesh`]: [`mesh::Mesh`], readers/writers (OBJ, PLY, glTF/GLB), normals, edges, adjacency,
//!   geodesic-ready topology, example sets (a folder or a TOML manifest of meshes sharing one
//!   topology), and Loop subdivision as a sparse matrix.
//! - [`runtime`]: the per-frame kernels, into reusable buffers: skinning, the kernel vector,
//!   the rotation regressors, the translation solve (FKY08 eq. 11), the detail layer (HZY11),
//!   and the One Euro filter that smooths a room's control points ([`runtime::filter`]).
//! - [`predictor`]: the per-frame pipeline over a trained model ([`predictor::Predictor`] and
//!   its reusable [`predictor::FrameContext`]): controls -> rotations -> translations ->
//!   skinned mesh, and the detail layer on request. It sits above [`model`] and [`runtime`]:
//!   the model's types are built from the runtime's, and the predictor runs both, so neither
//!   of the two points back.
//! - [`model`]: the on-disk container (versioned header, checksummed sections, atomic writes),
//!   the [`model::Rig`] and [`model::TrainedModel`] it stores, and the skinned-glTF export.
//! - [`codec`]: compact per-frame vertex buffers for streaming (quantisation, octahedral
//!   normals, keyframes and deltas, meshopt's vertex and index codecs, a self-describing header).
//! - [`atomic`]: atomic file writes shared by every writer of the workspace.
//!
//! The sweep hand and the rasteriser live in `crease-hand`, marker recordings in `crease-mocap`.

pub mod atomic;
pub mod codec;
pub mod mesh;
pub mod model;
pub mod predictor;
pub mod runtime;

pub use glam;

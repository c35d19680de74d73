//! crease-core: the runtime numerics of crease. No async, no network, nothing from the rest of
//! the workspace.
//!
//! Layout:
//! - [`mesh`]: [`mesh::Mesh`], readers/writers (OBJ, PLY, glTF/GLB), normals, edges, adjacency,
//!   and example sets (a folder or a TOML manifest of meshes sharing one topology).
//! - [`runtime`]: per-frame synthesis. Today: linear-blend and dual-quaternion skinning into
//!   caller-provided buffers.
//! - [`model`]: the on-disk container (versioned header, checksummed sections, atomic writes),
//!   the [`model::Rig`] it stores, and the skinned-glTF export of a rig.
//! - [`sweep`]: the LYK06 sweep hand; today its skeleton, poses and forward kinematics.
//! - [`codec`]: compact per-frame vertex buffers for streaming (16-bit quantisation, octahedral
//!   normals, keyframes and deltas, meshopt's vertex and index codecs, a self-describing header).
//! - [`mocap`]: marker recordings (Qualisys TSV, C3D) to control frames: marker maps,
//!   registration into the model's hand frame, gap filling, the One Euro filter.

mod atomic;
pub mod codec;
pub mod mesh;
pub mod mocap;
pub mod model;
pub mod render;
pub mod runtime;
pub mod sweep;

pub use glam;

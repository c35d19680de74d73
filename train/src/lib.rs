//! crease-train: learning from example meshes. Depends on `crease-core` only.
//!
//! Layout:
//! - [`bones`]: proxy bones and skinning weights from examples (FKY08 §3, HZY11 §5.1), fitted as
//!   a smooth skinning decomposition with rigid bones.

pub mod bones;
mod par;

//! crease-train: learning from example meshes. Depends on `crease-core` only.
//!
//! Layout:
//! - [`bones`]: proxy bones and skinning weights from examples (FKY08 §3, HZY11 §5.1), fitted as
//!   a smooth skinning decomposition with rigid bones.
//! - [`controls`]: automatic control points (PCA + varimax, FKY08 §3).
//! - [`geodesic`]: geodesic distances on the mesh edge graph (HZY11 §5.1.1).
//! - [`kcca`]: kernel CCA regression collapsed to one matrix (FKY08 §4), and the RBF baseline.
//! - [`edges`]: the edge skin of the translation solver: FKY08 eq. 10 weights and the vector
//!   edge skin fitted on top of them.
//! - [`regress`]: the rotation regressors of each method (global, local-geometry, local-pose,
//!   local, RBF baseline) as a runtime `RotationModel`.
//! - [`detail`]: the detail layer (HZY11 §4, §5.2): displacement extraction by ray casting,
//!   and the per-vertex detail regressor collapsed into one matrix.
//! - [`select`]: kernel, width, regularisation and beta chosen by leave-one-out inside the
//!   training set.
//! - [`eval`]: held-out and leave-one-out evaluation of every method against the oracles.
//! - [`pipeline`]: `crease train` as a function (bones, controls, regressors, edge weights).

pub mod bones;
pub mod controls;
pub mod detail;
pub mod edges;
pub mod eval;
pub mod geodesic;
pub mod kcca;
mod linalg;
mod par;
pub mod pipeline;
pub mod regress;
pub mod select;

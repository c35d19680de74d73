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
//! - [`group_rig`]: a coarse rig fitted beside a fine one, whose bones' control points group the
//!   fine bones for the geometry-local methods (issue 23).
//! - [`regress`]: the rotation regressors of each method (global, local-geometry, local-pose,
//!   local, RBF baseline) as a runtime `RotationModel`.
//! - [`detail`]: the detail layer (HZY11 §4, §5.2): displacement extraction by ray casting,
//!   and the per-vertex detail regressor collapsed into one matrix.
//! - [`metrics`]: RMS vertex errors normalised by the rest pose's size (HZY11 Table 2).
//! - [`selection`]: the data of model selection: the candidate grid, scored candidates, outcomes.
//! - [`base`]: the shared base of training: inputs, options, errors, report, and the fitted part
//!   every method shares ([`base::TrainedBase`]).
//! - [`select`]: kernel, width, regularisation and beta chosen by leave-one-out inside the
//!   training set; control points improved the same way.
//! - [`coverage`]: how many control points (the leave-one-out error per count of automatic
//!   points) and which bones the chosen ones leave undetermined (issue 42).
//! - [`pipeline`]: `crease train` as a function (bones, controls, regressors, edge weights).
//! - [`eval`]: held-out and leave-one-out evaluation of every method against the oracles.
//! - `linalg`: small dense kernels the per-vertex and per-edge fits share (no allocation).
//! - `par`: the two loop shapes training parallelises (rayon under `parallel`, else plain).
//!
//! The training modules point one way: [`eval`] -> [`pipeline`] -> [`select`] -> [`base`] ->
//! [`selection`], with [`metrics`] below [`select`] and [`eval`] (`client/tests/module_cycles.rs`
//! keeps every crate's modules free of cycles).

pub mod base;
pub mod bones;
pub mod controls;
pub mod coverage;
pub mod detail;
pub mod edges;
pub mod eval;
pub mod geodesic;
pub mod group_rig;
pub mod kcca;
mod linalg;
pub mod metrics;
mod par;
pub mod pipeline;
pub mod regress;
pub mod select;
pub mod selection;

//! Per-frame synthesis. Everything here writes into caller-provided buffers and allocates
//! nothing per frame.
//!
//! Layout:
//! - [`skin`]: linear-blend and dual-quaternion skinning.
//! - [`edge_skin`]: how the translation solver predicts mesh edges from bone rotations.
//! - [`kernel`]: the kernels of the regression (Gaussian, inhomogeneous polynomial) and the
//!   kernel vector `xi(c)` (FKY08 §4.2).
//! - [`predict`]: bone rotations from control points (global and pose-local models).
//! - [`predictor`]: the per-frame pipeline (controls -> transforms -> skinned mesh) and its
//!   reusable frame context.
//! - [`translations`]: the Poisson translation solver (FKY08 §5, eq. 11), factored once.
//! - [`detail`]: the detail layer's synthesis (HZY11 eq. 4): `S · base`, normals, `+ h n`.

pub mod detail;
pub mod edge_skin;
pub mod kernel;
pub mod predict;
pub mod predictor;
pub mod skin;
pub mod translations;

//! The detail layer's training side (HZY11 §4-§5.2, DESIGN.md data flow steps 2 and 9):
//!
//! - [`extract`]: the displacements `h_i` of each detailed example along the normals of its
//!   subdivided base mesh (ray casts, closest-point fallback);
//! - [`regress`]: the detail regressor `h(c) = D xi(c) + b`, one 1-D kernel CCA per detailed
//!   vertex collapsed into one matrix, and the static / cascaded baselines;
//! - [`split`]: the automatic base/detail split of a single-resolution example set: a
//!   simplified vertex subset of the rest mesh, smoothed per example into the base meshes.

pub mod extract;
pub mod layer;
pub mod regress;
pub mod split;

pub use extract::{
    DetailError, DetailExample, Displacement, DisplacementSource, DisplacementTarget,
    ExtractProgress, ExtractStats, Extracted, extract_all,
};
pub use split::{BaseSubset, SimplifyStats, Smoothing, SplitError};

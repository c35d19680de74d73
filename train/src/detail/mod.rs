//! The detail layer's training side (HZY11 §4-§5.2, DESIGN.md data flow steps 2 and 9):
//!
//! - [`extract`]: the displacements `h_i` of each detailed example along the normals of its
//!   subdivided base mesh (ray casts, closest-point fallback);
//! - [`regress`]: the detail regressor `h(c) = D xi(c) + b`, one 1-D kernel CCA per detailed
//!   vertex collapsed into one matrix, and the static / cascaded baselines.

pub mod extract;
pub mod regress;

pub use extract::{
    DetailError, DetailExample, Displacement, DisplacementSource, DisplacementTarget,
    ExtractProgress, ExtractStats, Extracted, extract_all,
};

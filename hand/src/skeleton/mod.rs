//! The simplified hand skeleton of LYK06 §2 ("Hand modeling: Skeleton"): only the major joints,
//! whose angles dominate the shape of the hand, i.e. the wrist, the carpometacarpal (CMC), the
//! metacarpophalangeal (MCP) and the interphalangeal joints (thumb IP; finger PIP and DIP).
//!
//! # Frame and conventions
//!
//! Units are metres and radians. One adult **right** hand in a right-handed frame:
//! - the wrist joint centre is the origin;
//! - `+Y` runs from the wrist towards the middle finger;
//! - `+Z` points out of the back (dorsum) of the hand, so the palm faces `-Z`;
//! - `+X = Y x Z` points from the thumb side towards the little finger (radial to ulnar):
//!   in the flat pose the thumb lies at negative X and the fingers are ordered
//!   index < middle < ring < little along X.
//!
//! Every joint frame ([`JointFrame`]) sits at the joint centre and is oriented like the bone
//! distal to it: local `+Y` along the bone (towards the next joint), local `+Z` out of its
//! dorsal (nail) side, local `-Z` towards its palmar (pulp) side. The tip frame has the
//! orientation of the distal phalanx.
//!
//! A joint's articulation, applied after its rest rotation, is `Rz(s * abduction) *
//! Rx(-flexion)`: **positive flexion curls the bone towards its palmar side** (`-Z`), and
//! positive abduction moves it away from the middle finger (`s` is `+1` for the thumb, index
//! and middle fingers, `-1` for ring and little). For the middle finger positive abduction is
//! radial (towards the index); for the wrist it is radial deviation. The thumb's rest frame is
//! pronated (its nail faces mostly radially), so its flexion moves it across the palm towards the
//! little finger and its abduction (palmar abduction) lifts it away from the palm (`-Z`). The
//! ring and little CMC joints have one degree of freedom, cupping, a flexion about an oblique
//! axis (see [`CUP_AXIS_TILT`]) that brings the metacarpal heads palmar and radial.
//!
//! # Forward kinematics
//!
//! [`HandSkeleton::pose_into`] writes, per digit, the ordered frames wrist, CMC, MCP, (PIP,
//! DIP | IP), tip into a fixed-size [`PosedSkeleton`] without allocating; these are the key
//! frames that the LYK06 §2 control sweeps interpolate.
//!
//! Layout:
//! - `joints`: [`Digit`], [`Joint`], the degrees of freedom ([`Dof`], [`DofKind`]) and their
//!   anatomical ranges ([`JointLimits`]).
//! - `pose`: [`HandPose`] (one angle per degree of freedom, JSON by name) and the
//!   [`NamedPose`]s.
//! - `sampler`: [`PoseSampler`], a seeded sampler of natural poses.
//! - `kinematics`: the rest geometry ([`HandSkeleton`], also built from given joint centres),
//!   forward kinematics into a [`PosedSkeleton`] of [`JointFrame`]s.

use std::f32::consts::PI;

mod joints;
mod kinematics;
mod pose;
mod sampler;

pub use joints::{DOF_COUNT, Digit, Dof, DofKind, Joint, JointLimits};
pub use kinematics::{
    CUP_AXIS_TILT, HandSkeleton, JointFrame, MAX_CHAIN, MIN_BONE_LENGTH, PosedSkeleton,
    RestChainError,
};
pub use pose::{HandPose, NamedPose};
pub use sampler::PoseSampler;

/// Degrees to radians, usable in constants.
const fn deg(d: f32) -> f32 {
    d * (PI / 180.0)
}

/// Errors of this module.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SkeletonError {
    /// A pose name that is not one of [`NamedPose::ALL`].
    #[error(
        "unknown pose name {0:?}; expected one of: flat, relaxed, fist, point, victory, pinch, grasp, spread, thumbs-up, ok"
    )]
    UnknownPose(String),
    /// A joint-angle name that is not one of [`Dof::all`] (e.g. in a pose JSON file).
    #[error("unknown joint angle {0:?}; expected names like \"index_mcp_flexion\"")]
    UnknownDof(String),
}

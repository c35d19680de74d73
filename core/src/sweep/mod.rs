//! The sweep-based hand of Lee, Yoon & Kim 2006 (LYK06): a simplified hand skeleton whose
//! digits each carry one sweep from the wrist to the tip (LYK06 §2, "Hand modeling").
//!
//! Layout:
//! - [`skeleton`]: the articulated skeleton (digits, joints, anatomical limits), hand poses
//!   (named poses and a seeded sampler of natural poses), and forward kinematics giving, per
//!   digit, the chain of joint frames from the wrist to the tip that the sweeps will follow.
//! - [`surface`]: the rest skin built by the project: a smooth signed distance function of the
//!   flat hand (round-cone phalanges, palm slab, wrist stub, smooth-minimum webs), polygonised
//!   by Surface Nets and smoothed, at two resolutions (base ~8K, detailed >= 150K vertices).
//! - [`sweeps`]: the control sweeps (one per digit: a C1 trajectory and a slerped orientation
//!   curve through the joint key frames), the binding of skin vertices by LYK06 eq. 1, and the
//!   blended, allocation-free deformation.

pub mod collide;
pub mod creases;
pub mod dataset;
pub mod palm;
pub mod rig;
pub mod skeleton;
pub mod surface;
pub mod sweeps;
pub mod webxr;

//! crease-hand: the sweep-based hand of Lee, Yoon & Kim 2006 (LYK06), a simplified hand
//! skeleton whose digits each carry one sweep from the wrist to the tip (LYK06 §2, "Hand
//! modeling"); the data-set generator behind `crease handgen`; the WebXR hand binding; and the
//! software rasteriser that draws its contact sheets and the CLI's picture strips. Depends on
//! `crease-core` only.
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
//!   blended, allocation-free deformation (sampled sweep frames).
//! - [`palm`]: the palm-control surface (LYK06 §3): a bicubic B-spline through 54 palmar
//!   vertices, 10 of them rising with MCP / thumb CMC flexion (bulge); palm vertices bound by
//!   `(u, v, d)` (LYK06 eq. 2).
//! - [`creases`]: palm lines, palmar flexion creases and dorsal knuckle wrinkles driven by
//!   named joints, and a static skin texture (the detailed resolution).
//! - [`collide`]: the self-intersection fix at IP/PIP/DIP (LYK06 §5, cross-sectional planes)
//!   and collisions (digit spheres, palm planes, an external ball) with push-out.
//! - [`rig`]: all of the above as one per-frame deformer ([`rig::HandRig`]).
//! - [`webxr`]: the WebXR generic hand (../shared/data/hand) bound to the sweeps from its
//!   joints; WebXR joint matrices <-> joint angles; the iwer poses.
//! - [`joint_map`]: a tracked hand's WebXR joints as mocap markers, and the marker maps that
//!   put a layout's landmarks on them (fitted on the sweep hand); [`vmc_map`]: the same for a
//!   VMC sender's humanoid hand bones (issue 39); [`mediapipe_map`]: for MediaPipe Hands'
//!   21 landmarks (a webcam, issue 46).
//! - [`dataset`]: the data-set generator of `crease handgen` (poses, control-point layouts,
//!   meshes at both resolutions, joint angles, manifests, contact sheet).
//! - [`render`]: a software rasteriser and PNG writer for contact sheets and picture strips
//!   (not numerics: its users are [`dataset`] and the CLI's `crease stream --strip`).

pub mod collide;
pub mod creases;
pub mod dataset;
pub mod joint_map;
pub mod mediapipe_map;
pub mod palm;
pub mod render;
pub mod rig;
pub mod skeleton;
pub mod surface;
pub mod sweeps;
pub mod vmc_map;
pub mod webxr;

/// The cubic smoothstep `3x² - 2x³` of `x` clamped to `[0, 1]`: the fall-offs and activations
/// of the sweep weights, the palm bulge, the palm-surface border and the creases.
pub(crate) fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

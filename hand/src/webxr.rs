//! External rest meshes bound to the LYK06 sweeps: the WebXR generic hand (issue 4 item 7).
//!
//! The WebXR Hand Input Module (W3C, "WebXR Hand Input Module - Level 1", §"Skeleton Joints")
//! names 25 joints: `wrist`, then per digit `*-metacarpal`, `*-phalanx-proximal`,
//! (`*-phalanx-intermediate`,) `*-phalanx-distal`, `*-tip` ([`JOINT_NAMES`], the spec's
//! order). `@webxr-input-profiles/assets` ships a skinned mesh of that skeleton
//! (`webxr-generic-hand-{left,right}.glb`), and `iwer` (Meta's Immersive Web Emulation Runtime)
//! ships three recorded poses as 25 joint matrices each (`iwer-pose-{relaxed,pinch,point}.js`).
//! This module binds the right GLB hand to the five digit sweeps of LYK06 §2 and converts
//! between joint matrices and the joint angles of [`HandPose`].
//!
//! # Conventions found in the data (checked by the tests)
//!
//! - **GLB**: a Blender export; the 25 joint nodes are flat children of an identity `Armature`
//!   node, so their node transforms are world transforms, and each equals the inverse of its
//!   inverse bind matrix to 3e-7: the bind pose is the node pose. Metres; the mesh node carries
//!   no transform, so the vertices are in the same (world) frame. In the right hand's bind pose
//!   the fingers point along world `-Y`, the back of the hand faces `+X`, the thumb lies towards
//!   `-Z`. Joint frames follow the WebXR convention: local `-Z` along the bone towards the tip
//!   (within 10° of the direction to the next joint), local `+Y` out of the back of the hand /
//!   nail ([`WEBXR_DORSAL`]), which with the fingers and thumb placement above makes the right
//!   hand right-handed. The skin has 4 influences per vertex, `JOINTS_0` indexing the skin's
//!   joint list (matched to [`JOINT_NAMES`] by node name, never by position).
//! - **iwer poses**: `offsetMatrix` is a column-major 4x4 (gl-matrix layout: elements 12..14
//!   are the translation), metres, rigid (determinant 1, unit scale to 1e-6), the pose of each
//!   joint in the input source's target-ray space. They are **left-hand** data: iwer's
//!   `XRHandInput` says "use left hand pose data and mirror for right hand" and mirrors with the
//!   element-wise sign pattern that equals `S * M * S`, `S = diag(-1, 1, 1, 1)`
//!   ([`mirror_left_right`]). In the data the thumb lies at the wrist's local `+X` (the GLB
//!   right hand: `-X`), and after the mirror the MCP (`*-phalanx-proximal`) centres match the
//!   GLB's in the wrist frame to within 8 mm. Their bone lengths are those of another hand
//!   (the tracked user's), not the GLB's, so converting a pose to angles and back through the
//!   GLB skeleton cannot reproduce its joint positions exactly (see the round-trip test).
//!
//! # The skeleton frame and the rest rotations
//!
//! [`WebXrHand::to_skeleton_frame`] is the rigid map (no scale: both are metres) from the GLB
//! world to the frame of [`super::skeleton`]: the wrist joint at the origin, `+Y` towards the
//! middle finger's MCP (`middle-finger-phalanx-proximal`), `+Z` the wrist joint's dorsal axis
//! made orthogonal to `+Y`. The skeleton ([`HandSkeleton::from_joint_positions`]) maps the
//! WebXR joints one to one onto its chains (metacarpal = CMC, proximal = MCP, intermediate =
//! PIP, distal = DIP or thumb IP, tip = tip) and gets its rest rotations from the bind pose:
//! each bone's `+Y` towards the next joint, `+Z` the WebXR joint's dorsal axis. So the
//! skeleton's flat pose **is** the GLB bind pose (every joint reproduced to float precision),
//! and the bind pose's slight curl and splay are absorbed by the rest rotations. We chose this
//! over converting the bind pose to angles from an idealised straight hand because the bind
//! pose is close to straight (measured by the tests: MCPs flexed 3-8°, PIPs ~1°, DIPs up to
//! 11° hyperextended, the index splayed 14° at its MCP), so the angles of the named poses mean
//! nearly what they say (a 90° MCP flexion is a right angle from the bind pose); the flat pose
//! binds without deformation (an idealised straight rest would put the binding itself off the
//! mesh's pose); and angles recovered from tracked joint matrices are measured from the mesh's
//! own rest, so they drive this mesh as tracked. What this does not give: the named poses were
//! tuned on [`HandSkeleton::adult_right`], whose thumb rest differs from the GLB's, so e.g.
//! the pinch's thumb and index tips need not meet on this hand.
//! Per joint a constant correction `C` relates the two conventions: a skeleton-frame joint
//! rotation is `to_skeleton * R_webxr * C` (`C` is close to a fixed axis swap: WebXR `-Z` ->
//! skeleton `+Y`, `+Y` -> `+Z`).
//!
//! # Angles from joint matrices
//!
//! [`WebXrHand::angles_from_joint_frames`] inverts the forward kinematics of
//! [`HandSkeleton::pose_into`] joint by joint, from the wrist outwards. The wrist angles come
//! from the wrist joint's orientation relative to the bind pose (WebXR has no forearm joint, so
//! they are measured in the GLB world). Every other joint is solved from the **direction of its
//! bone** (next joint centre minus this one), expressed in the joint's rest frame under the
//! forward-kinematics parent: that is the articulated bone axis `d = A * Y` of the articulation
//! `A = Rz(s * abduction) * Rx(-flexion)`. For two degrees of freedom
//! `d = (-cos f sin(s a), cos f cos(s a), -sin f)` gives both angles (the Z-X-Y Euler
//! decomposition of `A` without its last, twist, factor); a hinge (PIP, DIP, thumb MCP and IP,
//! the ring/little CMC cupping axis) takes the rotation about its axis that brings `+Y` closest
//! to `d`. Two choices, and why:
//! - bone directions rather than the joint orientations: the WebXR specification defines the
//!   joint centres exactly, but how well a runtime aligns the joint's `-Z` with the bone varies
//!   (the GLB's by up to 10°); with directions, each bone points where the data's does
//!   whenever the joint's degrees of freedom allow it;
//! - the forward-kinematics parent rather than the data's parent frame: each bone then corrects
//!   what its parent could not represent (e.g. a twist), so errors do not accumulate.
//!
//! Not representable, hence the expected residual of a round trip: twist about a bone,
//! abduction at a hinge, any motion of the index and middle CMC (rigid in LYK06's skeleton) and
//! cupping about another axis than [`CUP_AXIS_TILT`]'s at the ring/little CMC; positions also
//! differ by the difference in bone lengths when the data come from another hand
//! ([`WebXrHand::skeleton_fitted_to`] separates the two). Measured on the three iwer poses
//! (tests): through the GLB skeleton joints land within 17.5 mm (RMS 8 mm); with the iwer
//! hand's own bone lengths within 10.4 mm (RMS 5 mm), nearly all of it the index and ring MCPs,
//! whose metacarpals point differently in the iwer data than the rigid or cupping-only CMCs
//! allow; phalanx directions agree within 11°.

use std::path::Path;

use glam::{Affine3A, Mat3, Mat4, Quat, Vec3, Vec4};

use super::skeleton::{
    CUP_AXIS_TILT, Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, JointFrame, MAX_CHAIN,
    PosedSkeleton, RestChainError,
};
use super::sweeps::SweepHand;
use crease_core::mesh::Mesh;

/// Number of WebXR hand joints.
pub const JOINT_COUNT: usize = 25;

/// The WebXR hand joints in the specification's `XRHandJoint` order (also iwer's and the GLB
/// skin's order, though loading matches by name).
pub const JOINT_NAMES: [&str; JOINT_COUNT] = [
    "wrist",
    "thumb-metacarpal",
    "thumb-phalanx-proximal",
    "thumb-phalanx-distal",
    "thumb-tip",
    "index-finger-metacarpal",
    "index-finger-phalanx-proximal",
    "index-finger-phalanx-intermediate",
    "index-finger-phalanx-distal",
    "index-finger-tip",
    "middle-finger-metacarpal",
    "middle-finger-phalanx-proximal",
    "middle-finger-phalanx-intermediate",
    "middle-finger-phalanx-distal",
    "middle-finger-tip",
    "ring-finger-metacarpal",
    "ring-finger-phalanx-proximal",
    "ring-finger-phalanx-intermediate",
    "ring-finger-phalanx-distal",
    "ring-finger-tip",
    "pinky-finger-metacarpal",
    "pinky-finger-phalanx-proximal",
    "pinky-finger-phalanx-intermediate",
    "pinky-finger-phalanx-distal",
    "pinky-finger-tip",
];

/// The dorsal (back of hand, nail side) axis of a WebXR joint frame, local coordinates. The
/// bone runs along local `-Z`.
pub const WEBXR_DORSAL: Vec3 = Vec3::Y;

/// 25 joint poses (local to world, rigid) in [`JOINT_NAMES`] order.
pub type JointMatrices = [Mat4; JOINT_COUNT];

/// Where WebXR joint `i` sits in the skeleton: its digit (`None` for the wrist) and its index in
/// that digit's chain ([`PosedSkeleton::chain`]: 0 wrist, 1 CMC = metacarpal, ..., last tip).
///
/// # Panics
/// If `i >= JOINT_COUNT`.
pub fn joint_slot(i: usize) -> (Option<Digit>, usize) {
    assert!(i < JOINT_COUNT, "WebXR joint index {i}");
    match i {
        0 => (None, 0),
        1..=4 => (Some(Digit::Thumb), i),
        _ => (Some(Digit::FINGERS[(i - 5) / 5]), (i - 5) % 5 + 1),
    }
}

/// The WebXR joint index of chain slot `chain` of `digit` (the inverse of [`joint_slot`]).
///
/// # Panics
/// If `chain` is outside `1..digit.chain_len()`.
pub fn webxr_index(digit: Digit, chain: usize) -> usize {
    assert!(
        (1..digit.chain_len()).contains(&chain),
        "{digit:?} has no chain slot {chain}"
    );
    match digit {
        Digit::Thumb => chain,
        _ => 5 + 5 * (digit.index() - 1) + chain - 1,
    }
}

/// The frame of WebXR joint `i` in a posed skeleton (the tip frames carry the distal
/// phalanx's orientation).
pub fn skeleton_frame(posed: &PosedSkeleton, i: usize) -> JointFrame {
    match joint_slot(i) {
        (None, _) => posed.wrist(),
        (Some(d), c) => posed.chain(d)[c],
    }
}

/// iwer's left-to-right mirror (`mirrorMatrixToRight` in iwer's `XRHandInput.ts`): `S * m * S`
/// with `S = diag(-1, 1, 1, 1)`, a reflection of both the space's and the joint's local `X`.
/// It keeps the matrix rigid and its own inverse; the WebXR axes (`-Z` along the bone, `+Y`
/// dorsal) keep their meaning.
pub fn mirror_left_right(m: &Mat4) -> Mat4 {
    let s = Mat4::from_diagonal(Vec4::new(-1.0, 1.0, 1.0, 1.0));
    s * *m * s
}

/// Errors of this module. Each names the file (or the iwer line and joint) and what was
/// expected versus found.
#[derive(Debug, thiserror::Error)]
pub enum WebXrError {
    /// The file could not be read.
    #[error("{file}: {source}")]
    Io {
        /// The file.
        file: String,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The GLB is malformed or not the WebXR hand this module expects.
    #[error("{file}: {message}")]
    Glb {
        /// The file (or "in-memory GLB").
        file: String,
        /// What was wrong, expected versus found.
        message: String,
    },
    /// The bind-pose joints do not make a usable skeleton (e.g. two joints at one place).
    #[error("{file}: rest skeleton: {source}")]
    Skeleton {
        /// The file.
        file: String,
        /// The refused chain.
        #[source]
        source: RestChainError,
    },
    /// An iwer pose file entry could not be parsed.
    #[error("iwer pose line {line}, joint {joint:?}: {message}")]
    IwerSyntax {
        /// 1-based line of the problem.
        line: usize,
        /// The joint being read ("" before the first joint name).
        joint: String,
        /// What was wrong, expected versus found.
        message: String,
    },
    /// A parsed iwer pose does not hold the 25 WebXR joints exactly once.
    #[error("iwer pose: {0}")]
    IwerJoints(String),
}

/// Per-vertex skin influences of the GLB, remapped to [`JOINT_NAMES`] order.
#[derive(Clone, Debug, PartialEq)]
pub struct SkinWeights {
    /// Four WebXR joint indices per vertex.
    pub joints: Vec<[u8; 4]>,
    /// Their weights, normalised to sum to one (zero weights kept, as in the file).
    pub weights: Vec<[f32; 4]>,
}

/// The WebXR generic right hand bound to the LYK06 sweeps (module docs).
#[derive(Clone, Debug)]
pub struct WebXrHand {
    rest_mesh_webxr: Mesh,
    rest_mesh: Mesh,
    rest_joints: JointMatrices,
    skin: SkinWeights,
    to_skeleton: Affine3A,
    /// Per joint, `C` with skeleton rotation = `to_skeleton * R_webxr * C`.
    corrections: [Quat; JOINT_COUNT],
    skeleton: HandSkeleton,
    sweep_hand: SweepHand,
}

/// A pose recovered from iwer joint matrices: the joint angles and the rigid placement of the
/// GLB world in iwer's (right-hand, mirrored) target-ray space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IwerFit {
    /// The joint angles (wrist angles 0: the placement carries the wrist).
    pub pose: HandPose,
    /// Maps the GLB world into the mirrored (right-hand) target-ray space so that the wrists
    /// coincide.
    pub placement: Affine3A,
}

/// Rotation part of a (near-)rigid matrix, scale removed.
fn rotation_of(m: &Mat4) -> Quat {
    m.to_scale_rotation_translation().1.normalize()
}

/// Splits a rigid matrix into (rotation, translation).
fn rigid_parts(m: &Mat4) -> (Quat, Vec3) {
    (rotation_of(m), m.w_axis.truncate())
}

impl WebXrHand {
    /// Loads a WebXR generic hand GLB (the right one: the skeleton frame is a right hand's)
    /// and binds it (module docs).
    pub fn load(path: impl AsRef<Path>) -> Result<WebXrHand, WebXrError> {
        let path = path.as_ref();
        let file = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| WebXrError::Io {
            file: file.clone(),
            source,
        })?;
        WebXrHand::from_glb(&bytes, &file)
    }

    /// [`WebXrHand::load`] from the bytes of a GLB; `file` names it in errors.
    pub fn from_glb(bytes: &[u8], file: &str) -> Result<WebXrHand, WebXrError> {
        let glb = read_glb(bytes, file)?;
        let fail = |message: String| WebXrError::Glb {
            file: file.to_owned(),
            message,
        };
        let rest_joints = glb.joints;
        let (wrist_rot, wrist_pos) = rigid_parts(&rest_joints[0]);
        let middle_mcp = rest_joints[webxr_index(Digit::Middle, 2)].w_axis.truncate();
        let y = (middle_mcp - wrist_pos).normalize_or_zero();
        let z = wrist_rot * WEBXR_DORSAL;
        let z = (z - z.dot(y) * y).normalize_or_zero();
        if y == Vec3::ZERO || z == Vec3::ZERO {
            return Err(fail(format!(
                "wrist at {wrist_pos} and middle MCP at {middle_mcp} give no hand frame"
            )));
        }
        // Columns: the skeleton axes in the GLB world; its inverse maps the world to them.
        let axes = Mat3::from_cols(y.cross(z), y, z);
        let from_skeleton =
            Affine3A::from_rotation_translation(Quat::from_mat3(&axes).normalize(), wrist_pos);
        let to_skeleton = from_skeleton.inverse();
        let to_rot = Quat::from_mat3a(&to_skeleton.matrix3).normalize();

        let mut positions = [[Vec3::ZERO; MAX_CHAIN - 1]; 5];
        let mut dorsal = [[Vec3::ZERO; MAX_CHAIN - 2]; 5];
        for (i, m) in rest_joints.iter().enumerate().skip(1) {
            let (Some(d), c) = joint_slot(i) else {
                continue;
            };
            positions[d.index()][c - 1] = to_skeleton.transform_point3(m.w_axis.truncate());
            if c - 1 < d.joints().len() {
                dorsal[d.index()][c - 1] = to_rot * (rotation_of(m) * WEBXR_DORSAL);
            }
        }
        let skeleton =
            HandSkeleton::from_joint_positions(&positions, &dorsal).map_err(|source| {
                WebXrError::Skeleton {
                    file: file.to_owned(),
                    source,
                }
            })?;
        let flat = skeleton.pose(&HandPose::FLAT);
        let corrections = std::array::from_fn(|i| {
            let xr = to_rot * rotation_of(&rest_joints[i]);
            (xr.inverse() * skeleton_frame(&flat, i).rotation).normalize()
        });

        let rest_mesh = Mesh {
            positions: glb
                .mesh
                .positions
                .iter()
                .map(|&p| to_skeleton.transform_point3(p))
                .collect(),
            triangles: glb.mesh.triangles.clone(),
        };
        let sweep_hand = SweepHand::bind(&skeleton, &rest_mesh);
        Ok(WebXrHand {
            rest_mesh_webxr: glb.mesh,
            rest_mesh,
            rest_joints,
            skin: glb.skin,
            to_skeleton,
            corrections,
            skeleton,
            sweep_hand,
        })
    }

    /// The rest mesh in the skeleton frame (what [`WebXrHand::sweep_hand`] is bound to).
    pub fn rest_mesh(&self) -> &Mesh {
        &self.rest_mesh
    }

    /// The rest mesh as stored in the GLB (WebXR world, metres).
    pub fn rest_mesh_webxr(&self) -> &Mesh {
        &self.rest_mesh_webxr
    }

    /// The bind-pose joint matrices (WebXR world), [`JOINT_NAMES`] order.
    pub fn rest_joints(&self) -> &JointMatrices {
        &self.rest_joints
    }

    /// The bind-pose joint centres in the skeleton frame, [`JOINT_NAMES`] order.
    pub fn rest_joint_positions(&self) -> [Vec3; JOINT_COUNT] {
        std::array::from_fn(|i| {
            self.to_skeleton
                .transform_point3(self.rest_joints[i].w_axis.truncate())
        })
    }

    /// The GLB's own skin weights (for comparisons with linear blend skinning).
    pub fn skin_weights(&self) -> &SkinWeights {
        &self.skin
    }

    /// The skeleton built from the bind pose (its flat pose is the bind pose).
    pub fn skeleton(&self) -> &HandSkeleton {
        &self.skeleton
    }

    /// The rest mesh bound to the sweeps of [`WebXrHand::skeleton`]; deform it with
    /// [`SweepHand::deform_into`] (output in the skeleton frame).
    pub fn sweep_hand(&self) -> &SweepHand {
        &self.sweep_hand
    }

    /// The rigid map from the GLB world to the skeleton frame (module docs).
    pub fn to_skeleton_frame(&self) -> Affine3A {
        self.to_skeleton
    }

    /// The rigid map from the skeleton frame to the GLB world.
    pub fn from_skeleton_frame(&self) -> Affine3A {
        self.to_skeleton.inverse()
    }

    /// A posed skeleton's joints as WebXR joint matrices in the GLB world.
    pub fn joint_frames_from_posed(&self, posed: &PosedSkeleton) -> JointMatrices {
        let back = self.from_skeleton_frame();
        std::array::from_fn(|i| {
            let f = skeleton_frame(posed, i);
            let local = Affine3A::from_rotation_translation(
                f.rotation * self.corrections[i].inverse(),
                f.position,
            );
            Mat4::from(back * local)
        })
    }

    /// Forward kinematics of `pose` as WebXR joint matrices in the GLB world: the bind pose
    /// for [`HandPose::FLAT`], the wrist angles turning the hand about the wrist joint.
    pub fn joint_frames_from_angles(&self, pose: &HandPose) -> JointMatrices {
        self.joint_frames_from_posed(&self.skeleton.pose(pose))
    }

    /// The joint angles whose forward kinematics best follow `frames` (WebXR joint matrices in
    /// the GLB world; module docs for the method and its residual). Angles are not clamped.
    pub fn angles_from_joint_frames(&self, frames: &JointMatrices) -> HandPose {
        let to_rot = Quat::from_mat3a(&self.to_skeleton.matrix3).normalize();
        // The data's wrist orientation in the skeleton's convention.
        let wrist = (to_rot * rotation_of(&frames[0]) * self.corrections[0]).normalize();
        let mut pose = HandPose::FLAT;
        let (f, a) = swing_angles(wrist * Vec3::Y);
        set(&mut pose, Joint::Wrist, DofKind::Flexion, f);
        set(&mut pose, Joint::Wrist, DofKind::Abduction, a);
        let wrist = self.skeleton.pose(&pose).wrist().rotation;
        for digit in Digit::ALL {
            let rest = self.skeleton.rest_rotations(digit);
            let mut parent = wrist;
            for (k, &joint) in digit.joints().iter().enumerate() {
                // The bone's direction from the joint centres, in the joint's rest frame under
                // the FK parent: the articulated bone axis `A * Y`.
                let i = webxr_index(digit, k + 1);
                let bone = to_rot * (frames[i + 1].w_axis - frames[i].w_axis).truncate();
                let d = rest[k].inverse() * parent.inverse() * bone.normalize_or_zero();
                let sign = abduction_sign(digit);
                let articulation = match joint {
                    Joint::IndexCmc | Joint::MiddleCmc => Quat::IDENTITY,
                    Joint::RingCmc | Joint::LittleCmc => {
                        let axis = cup_axis();
                        let f = hinge_angle(axis, d);
                        set(&mut pose, joint, DofKind::Flexion, f);
                        Quat::from_axis_angle(axis, f)
                    }
                    Joint::ThumbCmc
                    | Joint::IndexMcp
                    | Joint::MiddleMcp
                    | Joint::RingMcp
                    | Joint::LittleMcp => {
                        let (f, a) = swing_angles(d);
                        set(&mut pose, joint, DofKind::Flexion, f);
                        set(&mut pose, joint, DofKind::Abduction, sign * a);
                        Quat::from_rotation_z(a) * Quat::from_rotation_x(-f)
                    }
                    _ => {
                        let f = hinge_angle(-Vec3::X, d);
                        set(&mut pose, joint, DofKind::Flexion, f);
                        Quat::from_rotation_x(-f)
                    }
                };
                parent = (parent * rest[k] * articulation).normalize();
            }
        }
        pose
    }

    /// [`WebXrHand::skeleton`] with the bone geometry of the hand in `frames` (WebXR joint
    /// matrices, any world): CMC centres in its wrist frame and the distances between
    /// consecutive joints, the rest rotations kept ([`HandSkeleton::with_bones`]). Posing it
    /// with the angles recovered from `frames` isolates what the angles cannot represent from
    /// the difference in hand size and proportions.
    pub fn skeleton_fitted_to(&self, frames: &JointMatrices) -> HandSkeleton {
        let to_rot = Quat::from_mat3a(&self.to_skeleton.matrix3).normalize();
        let wrist = (to_rot * rotation_of(&frames[0]) * self.corrections[0]).normalize();
        let at = |i: usize| frames[i].w_axis.truncate();
        let mut bases = [Vec3::ZERO; 5];
        let mut lengths = [[0.0; MAX_CHAIN - 2]; 5];
        for digit in Digit::ALL {
            let cmc = webxr_index(digit, 1);
            bases[digit.index()] = wrist.inverse() * (to_rot * (at(cmc) - at(0)));
            for (k, l) in lengths[digit.index()]
                .iter_mut()
                .take(digit.joints().len())
                .enumerate()
            {
                *l = (at(cmc + k + 1) - at(cmc + k)).length();
            }
        }
        self.skeleton.with_bones(bases, lengths)
    }

    /// The angles of an iwer pose ([`parse_iwer_pose`]): its left-hand matrices mirrored to the
    /// right hand ([`mirror_left_right`]), placed so that the wrist joint coincides with the
    /// GLB's bind-pose wrist, then [`WebXrHand::angles_from_joint_frames`].
    pub fn pose_from_iwer(&self, joints: &[(String, Mat4)]) -> Result<IwerFit, WebXrError> {
        let left = iwer_joint_matrices(joints)?;
        let right = left.map(|m| mirror_left_right(&m));
        let placement = rigid_affine(&right[0]) * rigid_affine(&self.rest_joints[0]).inverse();
        let back = Mat4::from(placement.inverse());
        let frames = right.map(|m| back * m);
        Ok(IwerFit {
            pose: self.angles_from_joint_frames(&frames),
            placement,
        })
    }

    /// iwer joint matrices (left hand, target-ray space, [`JOINT_NAMES`] order) of `pose`
    /// placed by `placement`: the inverse of [`WebXrHand::pose_from_iwer`] up to its residual.
    pub fn iwer_from_pose(&self, pose: &HandPose, placement: &Affine3A) -> Vec<(String, Mat4)> {
        let place = Mat4::from(*placement);
        self.joint_frames_from_angles(pose)
            .iter()
            .zip(JOINT_NAMES)
            .map(|(m, name)| (name.to_owned(), mirror_left_right(&(place * *m))))
            .collect()
    }
}

/// A rigid affine from a (near-)rigid matrix, scale removed.
fn rigid_affine(m: &Mat4) -> Affine3A {
    let (r, t) = rigid_parts(m);
    Affine3A::from_rotation_translation(r, t)
}

/// Sets one angle of `pose`; joints without that degree of freedom are skipped (the callers
/// only name existing ones).
fn set(pose: &mut HandPose, joint: Joint, kind: DofKind, radians: f32) {
    if let Some(dof) = Dof::new(joint, kind) {
        pose.set(dof, radians);
    }
}

/// `s` of the skeleton's `Rz(s * abduction)` (skeleton module docs: `+1` for thumb, index and
/// middle, `-1` for ring and little).
fn abduction_sign(digit: Digit) -> f32 {
    match digit {
        Digit::Thumb | Digit::Index | Digit::Middle => 1.0,
        Digit::Ring | Digit::Little => -1.0,
    }
}

/// The ring/little CMC cupping axis of the skeleton (a flexion by `+f` rotates about it).
fn cup_axis() -> Vec3 {
    Vec3::new(-CUP_AXIS_TILT.cos(), 0.0, CUP_AXIS_TILT.sin())
}

/// `(f, φ)` with `Rz(φ) * Rx(-f) * Y = d` (for unit `d`): `d = (-cos f sin φ, cos f cos φ,
/// -sin f)`, the Z-X-Y Euler angles of any rotation taking `+Y` to `d`, twist dropped.
fn swing_angles(d: Vec3) -> (f32, f32) {
    let f = (-d.z).atan2(d.x.hypot(d.y));
    let phi = (-d.x).atan2(d.y);
    (f, phi)
}

/// The angle of the rotation about unit `axis` (perpendicular to `+Y`) that brings `+Y`
/// closest to `d`: `atan2(axis · (Y × d), Y · d)`.
fn hinge_angle(axis: Vec3, d: Vec3) -> f32 {
    axis.dot(Vec3::Y.cross(d)).atan2(d.y)
}

/// The parts of the GLB this module uses.
struct Glb {
    mesh: Mesh,
    joints: JointMatrices,
    skin: SkinWeights,
}

/// Reads the first skinned mesh primitive, its skin's 25 joints (by name) and their bind
/// matrices (inverse of the inverse bind matrices; glTF 2.0 §3.7.3 "Skins").
fn read_glb(bytes: &[u8], file: &str) -> Result<Glb, WebXrError> {
    let fail = |message: String| WebXrError::Glb {
        file: file.to_owned(),
        message,
    };
    let gltf = ::gltf::Gltf::from_slice(bytes)
        .map_err(|e| fail(format!("not a valid glTF/GLB file: {e}")))?;
    let blob = gltf.blob.as_deref();
    let buffer = |b: ::gltf::Buffer<'_>| match b.source() {
        ::gltf::buffer::Source::Bin => blob,
        ::gltf::buffer::Source::Uri(_) => None,
    };
    let skin = gltf
        .document
        .skins()
        .next()
        .ok_or_else(|| fail("no skin, expected the 25-joint WebXR hand skin".to_owned()))?;
    let skin_joints: Vec<_> = skin.joints().collect();
    // Skin joint position -> WebXR index.
    let mut to_webxr = vec![u8::MAX; skin_joints.len()];
    let mut found: [Option<usize>; JOINT_COUNT] = [None; JOINT_COUNT];
    for (k, node) in skin_joints.iter().enumerate() {
        if let Some(i) = JOINT_NAMES.iter().position(|&n| Some(n) == node.name()) {
            to_webxr[k] = i as u8;
            found[i] = Some(k);
        }
    }
    if let Some(i) = found.iter().position(Option::is_none) {
        return Err(fail(format!(
            "skin joint {:?} missing; the skin has {} joints named {:?}",
            JOINT_NAMES[i],
            skin_joints.len(),
            skin_joints.iter().map(|n| n.name()).collect::<Vec<_>>()
        )));
    }
    let inverse_bind: Vec<Mat4> = skin
        .reader(buffer)
        .read_inverse_bind_matrices()
        .ok_or_else(|| fail("skin has no readable inverseBindMatrices (GLB chunk only)".into()))?
        .map(|m| Mat4::from_cols_array_2d(&m))
        .collect();
    if inverse_bind.len() != skin_joints.len() {
        return Err(fail(format!(
            "{} inverse bind matrices for {} skin joints",
            inverse_bind.len(),
            skin_joints.len()
        )));
    }
    let mut joints = [Mat4::IDENTITY; JOINT_COUNT];
    for (i, k) in found.iter().enumerate() {
        let k = k.unwrap_or_default();
        let bind = inverse_bind[k].inverse();
        if !bind.is_finite() || (bind.determinant() - 1.0).abs() > 1e-3 {
            return Err(fail(format!(
                "joint {:?}: bind matrix is not rigid (determinant {}, expected 1)",
                JOINT_NAMES[i],
                bind.determinant()
            )));
        }
        joints[i] = bind;
    }

    let skinned = gltf
        .document
        .nodes()
        .find(|n| n.skin().is_some() && n.mesh().is_some())
        .and_then(|n| n.mesh())
        .ok_or_else(|| fail("no node with both a mesh and a skin".to_owned()))?;
    let primitive = skinned
        .primitives()
        .next()
        .ok_or_else(|| fail(format!("mesh {} has no primitives", skinned.index())))?;
    if primitive.mode() != ::gltf::mesh::Mode::Triangles {
        return Err(fail(format!(
            "primitive mode {:?}, expected Triangles",
            primitive.mode()
        )));
    }
    let reader = primitive.reader(buffer);
    let positions: Vec<Vec3> = reader
        .read_positions()
        .ok_or_else(|| fail("no readable POSITION attribute".to_owned()))?
        .map(Vec3::from_array)
        .collect();
    let n = positions.len();
    let indices: Vec<u32> = match reader.read_indices() {
        Some(ix) => ix.into_u32().collect(),
        None => (0..n as u32).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(fail(format!(
            "{} indices, expected a multiple of 3",
            indices.len()
        )));
    }
    let mesh = Mesh {
        positions,
        triangles: indices
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect(),
    };
    mesh.validate()
        .map_err(|e| fail(format!("mesh is invalid: {e}")))?;
    let skin_joint_ids: Vec<[u16; 4]> = reader
        .read_joints(0)
        .ok_or_else(|| fail("no readable JOINTS_0 attribute".to_owned()))?
        .into_u16()
        .collect();
    let raw_weights: Vec<[f32; 4]> = reader
        .read_weights(0)
        .ok_or_else(|| fail("no readable WEIGHTS_0 attribute".to_owned()))?
        .into_f32()
        .collect();
    if skin_joint_ids.len() != n || raw_weights.len() != n {
        return Err(fail(format!(
            "{} JOINTS_0 and {} WEIGHTS_0 entries, expected one per vertex ({n})",
            skin_joint_ids.len(),
            raw_weights.len()
        )));
    }
    let mut skin = SkinWeights {
        joints: Vec::with_capacity(n),
        weights: Vec::with_capacity(n),
    };
    for (v, (ids, w)) in skin_joint_ids.iter().zip(&raw_weights).enumerate() {
        let total: f32 = w.iter().sum();
        if !(total.is_finite() && total > 0.0 && w.iter().all(|&x| x >= 0.0)) {
            return Err(fail(format!(
                "vertex {v}: weights {w:?}, expected non-negative with a positive sum"
            )));
        }
        let mut j = [0u8; 4];
        for (out, &id) in j.iter_mut().zip(ids) {
            *out = *to_webxr.get(id as usize).unwrap_or(&u8::MAX);
            if *out == u8::MAX {
                return Err(fail(format!(
                    "vertex {v}: JOINTS_0 entry {id} is not one of the 25 WebXR joints"
                )));
            }
        }
        skin.joints.push(j);
        skin.weights.push(w.map(|x| x / total));
    }
    Ok(Glb { mesh, joints, skin })
}

/// Parses an iwer hand pose file (`export const ... = { jointTransforms: { wrist: {
/// offsetMatrix: [16 numbers], radius: r }, 'thumb-metacarpal': { ... }, ... } }`): every
/// `offsetMatrix` with the key of the object holding it (bare or quoted), in file order. A
/// tolerant scan, not a JavaScript parser: comments and other fields are skipped. The matrices
/// are column-major (gl-matrix), so element 12..14 is the translation.
pub fn parse_iwer_pose(text: &str) -> Result<Vec<(String, Mat4)>, WebXrError> {
    const KEY: &str = "offsetMatrix";
    let line_of = |pos: usize| text[..pos].matches('\n').count() + 1;
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(found) = text[from..].find(KEY) {
        let at = from + found;
        from = at + KEY.len();
        let joint = owner_key(&text[..at]).ok_or_else(|| WebXrError::IwerSyntax {
            line: line_of(at),
            joint: String::new(),
            message: "offsetMatrix outside an object with a name key ('name': { ... })".into(),
        })?;
        let err = |pos: usize, message: String| WebXrError::IwerSyntax {
            line: line_of(pos),
            joint: joint.clone(),
            message,
        };
        let rest = &text[from..];
        let open = rest
            .find('[')
            .filter(|&o| rest[..o].trim().trim_start_matches(':').trim().is_empty())
            .ok_or_else(|| err(from, "expected ': [' after offsetMatrix".into()))?;
        let close = rest[open..]
            .find(']')
            .ok_or_else(|| err(from + open, "unclosed '[' of offsetMatrix".into()))?;
        let body_at = from + open + 1;
        let body = &rest[open + 1..open + close];
        let mut values = Vec::with_capacity(16);
        let mut offset = 0;
        for token in body.split(',') {
            let t = token.trim();
            if !t.is_empty() {
                let v: f32 = t.parse().map_err(|_| {
                    err(
                        body_at + offset,
                        format!("expected a number, got {t:?} (element {})", values.len()),
                    )
                })?;
                if !v.is_finite() {
                    return Err(err(body_at + offset, format!("non-finite value {t}")));
                }
                values.push(v);
            }
            offset += token.len() + 1;
        }
        if values.len() != 16 {
            return Err(err(
                body_at,
                format!("expected 16 numbers in offsetMatrix, got {}", values.len()),
            ));
        }
        out.push((joint, Mat4::from_cols_slice(&values)));
        from += open + close + 1;
    }
    if out.is_empty() {
        return Err(WebXrError::IwerSyntax {
            line: 1,
            joint: String::new(),
            message: "no offsetMatrix found".into(),
        });
    }
    Ok(out)
}

/// The key of the innermost `{` still open at the end of `before`, e.g. `thumb-tip` for
/// `'thumb-tip': { ...`.
fn owner_key(before: &str) -> Option<String> {
    let mut depth = 0i32;
    let mut open = None;
    for (i, c) in before.char_indices().rev() {
        match c {
            '}' => depth += 1,
            '{' if depth == 0 => {
                open = Some(i);
                break;
            }
            '{' => depth -= 1,
            _ => {}
        }
    }
    let head = before[..open?].trim_end().strip_suffix(':')?.trim_end();
    let key = match head.chars().last()? {
        q @ ('\'' | '"') => {
            let inner = &head[..head.len() - 1];
            &inner[inner.rfind(q)? + 1..]
        }
        _ => {
            let start = head
                .rfind(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '$'))
                .map_or(0, |i| i + 1);
            &head[start..]
        }
    };
    (!key.is_empty()).then(|| key.to_owned())
}

/// The 25 matrices of a parsed iwer pose in [`JOINT_NAMES`] order; every joint exactly once,
/// no others.
pub fn iwer_joint_matrices(joints: &[(String, Mat4)]) -> Result<JointMatrices, WebXrError> {
    let mut out = [None; JOINT_COUNT];
    for (name, m) in joints {
        let i = JOINT_NAMES.iter().position(|n| n == name).ok_or_else(|| {
            WebXrError::IwerJoints(format!(
                "unknown joint {name:?}; expected the 25 WebXR joint names"
            ))
        })?;
        if out[i].replace(*m).is_some() {
            return Err(WebXrError::IwerJoints(format!(
                "joint {name:?} given twice"
            )));
        }
    }
    let missing: Vec<_> = (0..JOINT_COUNT)
        .filter(|&i| out[i].is_none())
        .map(|i| JOINT_NAMES[i])
        .collect();
    if !missing.is_empty() {
        return Err(WebXrError::IwerJoints(format!(
            "{} of 25 joints given; missing {missing:?}",
            JOINT_COUNT - missing.len()
        )));
    }
    Ok(out.map(|m| m.unwrap_or(Mat4::IDENTITY)))
}

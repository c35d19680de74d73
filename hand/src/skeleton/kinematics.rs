//! The rest geometry of a hand ([`HandSkeleton`]: the average adult right hand, scaled, or
//! fitted to given joint centres) and forward kinematics into a fixed-size [`PosedSkeleton`] of
//! [`JointFrame`]s, allocation-free.

use glam::{Affine3A, Quat, Vec3};
use serde::{Deserialize, Serialize};

use super::{Digit, HandPose, Joint, deg};

/// A rigid frame: a joint centre and the orientation of the bone distal to it (see the module
/// docs for the axes).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JointFrame {
    /// Joint centre, metres, in the hand frame.
    pub position: Vec3,
    /// Orientation (unit quaternion): local `+Y` along the bone, `+Z` dorsal.
    pub rotation: Quat,
}

impl JointFrame {
    /// The hand frame itself.
    pub const IDENTITY: JointFrame = JointFrame {
        position: Vec3::ZERO,
        rotation: Quat::IDENTITY,
    };

    /// As an affine transform (local to hand frame).
    pub fn to_affine(&self) -> Affine3A {
        Affine3A::from_rotation_translation(self.rotation, self.position)
    }

    /// Maps a point from this frame to the hand frame.
    pub fn transform_point(&self, local: Vec3) -> Vec3 {
        self.position + self.rotation * local
    }

    /// The bone direction, local `+Y` in the hand frame.
    pub fn axis(&self) -> Vec3 {
        self.rotation * Vec3::Y
    }

    /// The dorsal direction, local `+Z` in the hand frame.
    pub fn dorsal(&self) -> Vec3 {
        self.rotation * Vec3::Z
    }
}

/// Longest digit chain: wrist, CMC, MCP, PIP, DIP, tip.
pub const MAX_CHAIN: usize = 6;
/// Most joints in one digit (CMC, MCP, PIP, DIP).
const MAX_DIGIT_JOINTS: usize = MAX_CHAIN - 2;

/// Tilt of the ring/little CMC cupping axis from the metacarpal's local `-X` towards `+Z`
/// (radians). The 4th and 5th CMC joints flex about axes oblique to the metacarpal (their
/// saddle surfaces face radially), so cupping carries the metacarpal heads palmar and
/// radially, towards the thumb, which is what hollows the palm; 20° is a middle value of the
/// obliquity usually described for the 5th CMC (a chosen value, not a measurement).
pub const CUP_AXIS_TILT: f32 = deg(20.0);

/// Rest geometry of one digit.
#[derive(Clone, Copy, Debug, PartialEq)]
struct DigitRest {
    /// CMC joint centre in the wrist frame.
    base: Vec3,
    /// Rest rotation of each joint relative to its parent frame (applied before the
    /// articulation); unused entries are identity.
    rest: [Quat; MAX_DIGIT_JOINTS],
    /// Length of the bone distal to each joint (metacarpal, proximal, middle, distal phalanx
    /// including the soft tip); unused entries are 0.
    lengths: [f32; MAX_DIGIT_JOINTS],
}

impl DigitRest {
    /// A finger from its CMC and MCP centres (in the flat palm plane `z = 0`), the direction
    /// of its straight phalanges as an angle about `+Z` from `+Y` (positive towards the thumb),
    /// and its three phalanx lengths.
    fn finger(cmc: Vec3, mcp: Vec3, splay: f32, phalanges: [f32; 3]) -> Self {
        let d = mcp - cmc;
        // Rz(a) maps +Y to (-sin a, cos a, 0).
        let metacarpal_angle = (-d.x).atan2(d.y);
        DigitRest {
            base: cmc,
            rest: [
                Quat::from_rotation_z(metacarpal_angle),
                Quat::from_rotation_z(splay - metacarpal_angle),
                Quat::IDENTITY,
                Quat::IDENTITY,
            ],
            lengths: [d.length(), phalanges[0], phalanges[1], phalanges[2]],
        }
    }
}

/// The rest geometry of a hand skeleton: for each digit, where its CMC sits relative to the
/// wrist, the rest orientation of its joints, and its bone lengths.
#[derive(Clone, Debug, PartialEq)]
pub struct HandSkeleton {
    digits: [DigitRest; 5],
}

impl HandSkeleton {
    /// An average adult right hand, hand length (wrist crease to middle fingertip) 19 cm.
    ///
    /// Proportions: phalanx lengths of the order of published adult means (e.g. Buryanov &
    /// Kotiuk 2010, "Proportions of hand segments"; values here are rounded, not copied),
    /// distal phalanges lengthened by the ~3 mm pulp; metacarpals and the carpal offset (~3 cm from the wrist centre to the CMC row) set so
    /// that the middle finger chain sums to 0.032 + 0.065 + 0.045 + 0.027 + 0.021 = 0.190 m;
    /// knuckles (MCP heads) ~2 cm apart along an arc, the middle finger on the `Y` axis.
    pub fn adult_right() -> Self {
        let thumb = DigitRest {
            base: Vec3::new(-0.019, 0.014, -0.008),
            // Pronated ~70° about its own axis (nail facing radially and a little dorsally),
            // pointing 38° radially from +Y in the flat hand.
            rest: [
                Quat::from_rotation_z(deg(38.0)) * Quat::from_rotation_y(deg(-70.0)),
                Quat::IDENTITY,
                Quat::IDENTITY,
                Quat::IDENTITY,
            ],
            lengths: [0.044, 0.032, 0.027, 0.0],
        };
        HandSkeleton {
            digits: [
                thumb,
                DigitRest::finger(
                    Vec3::new(-0.012, 0.031, 0.0),
                    Vec3::new(-0.023, 0.094, 0.0),
                    deg(4.0),
                    [0.040, 0.023, 0.020],
                ),
                DigitRest::finger(
                    Vec3::new(0.0, 0.032, 0.0),
                    Vec3::new(0.0, 0.097, 0.0),
                    0.0,
                    [0.045, 0.027, 0.021],
                ),
                DigitRest::finger(
                    Vec3::new(0.011, 0.030, 0.0),
                    Vec3::new(0.021, 0.091, 0.0),
                    deg(-3.0),
                    [0.042, 0.026, 0.021],
                ),
                DigitRest::finger(
                    Vec3::new(0.019, 0.027, 0.0),
                    Vec3::new(0.039, 0.081, 0.0),
                    deg(-7.0),
                    [0.033, 0.018, 0.019],
                ),
            ],
        }
    }

    /// This skeleton uniformly scaled by `factor` (e.g. `hand_length / 0.19`).
    pub fn scaled(&self, factor: f32) -> Self {
        let mut out = self.clone();
        for d in &mut out.digits {
            d.base *= factor;
            for l in &mut d.lengths {
                *l *= factor;
            }
        }
        out
    }

    /// The CMC joint centre of `digit` in the wrist frame (the wrist-to-CMC "bone").
    pub fn base(&self, digit: Digit) -> Vec3 {
        self.digits[digit.index()].base
    }

    /// Rest lengths of the bones distal to each of the digit's joints, in
    /// [`Digit::joints`] order (metacarpal, then phalanges; the last ends at the tip).
    pub fn bone_lengths(&self, digit: Digit) -> &[f32] {
        &self.digits[digit.index()].lengths[..digit.joints().len()]
    }

    /// Forward kinematics into a new [`PosedSkeleton`].
    pub fn pose(&self, pose: &HandPose) -> PosedSkeleton {
        let mut out = PosedSkeleton::default();
        self.pose_into(pose, &mut out);
        out
    }

    /// Forward kinematics into `out`, allocation-free: each digit's chain is the wrist frame
    /// (at the origin, rotated by the wrist angles), then per joint `parent * T(offset) * rest *
    /// articulation` with `offset` the CMC base or the parent bone along its `+Y`, then the tip.
    /// The angles are used as given; clamp the pose first to respect limits.
    pub fn pose_into(&self, pose: &HandPose, out: &mut PosedSkeleton) {
        let wrist = JointFrame {
            position: Vec3::ZERO,
            rotation: articulation(Joint::Wrist, 1.0, pose),
        };
        for digit in Digit::ALL {
            let rest = &self.digits[digit.index()];
            let chain = &mut out.frames[digit.index()];
            chain[0] = wrist;
            let mut parent = wrist;
            let mut offset = rest.base;
            let joints = digit.joints();
            for (k, &joint) in joints.iter().enumerate() {
                let local = rest.rest[k] * articulation(joint, digit.abduction_sign(), pose);
                let frame = JointFrame {
                    position: parent.transform_point(offset),
                    rotation: (parent.rotation * local).normalize(),
                };
                chain[k + 1] = frame;
                parent = frame;
                offset = Vec3::Y * rest.lengths[k];
            }
            chain[joints.len() + 1] = JointFrame {
                position: parent.transform_point(offset),
                rotation: parent.rotation,
            };
        }
    }
}

impl Default for HandSkeleton {
    fn default() -> Self {
        HandSkeleton::adult_right()
    }
}

/// The articulation rotation of one joint (module docs): `Rz(s * abduction) * Rx(-flexion)`,
/// or for the ring/little CMC a flexion about the oblique cupping axis.
fn articulation(joint: Joint, abduction_sign: f32, pose: &HandPose) -> Quat {
    let flexion = pose.flexion(joint);
    match joint {
        Joint::RingCmc | Joint::LittleCmc => {
            // Rotation by +f about an axis with a -X part carries +Y to -Z (palmar); the +Z
            // part carries it to -X (radial).
            let axis = Vec3::new(-CUP_AXIS_TILT.cos(), 0.0, CUP_AXIS_TILT.sin());
            Quat::from_axis_angle(axis, flexion)
        }
        _ => {
            Quat::from_rotation_z(abduction_sign * pose.abduction(joint))
                * Quat::from_rotation_x(-flexion)
        }
    }
}

/// A posed skeleton: per digit, the frames from the wrist to the tip (fixed size, `Copy`, so
/// a caller can keep one and refill it every frame with [`HandSkeleton::pose_into`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PosedSkeleton {
    frames: [[JointFrame; MAX_CHAIN]; 5],
}

impl Default for PosedSkeleton {
    fn default() -> Self {
        PosedSkeleton {
            frames: [[JointFrame::IDENTITY; MAX_CHAIN]; 5],
        }
    }
}

impl PosedSkeleton {
    /// The frames of one digit, wrist first, then [`Digit::joints`], then the tip
    /// ([`Digit::chain_len`] of them).
    pub fn chain(&self, digit: Digit) -> &[JointFrame] {
        &self.frames[digit.index()][..digit.chain_len()]
    }

    /// The wrist frame (shared by every chain).
    pub fn wrist(&self) -> JointFrame {
        self.frames[0][0]
    }

    /// The frame of one joint.
    pub fn joint(&self, joint: Joint) -> JointFrame {
        match joint.digit() {
            None => self.wrist(),
            Some(d) => self.frames[d.index()][joint.chain_index()],
        }
    }

    /// The tip frame of one digit.
    pub fn tip(&self, digit: Digit) -> JointFrame {
        self.frames[digit.index()][digit.chain_len() - 1]
    }
}

/// Why [`HandSkeleton::from_joint_positions`] refused a rest chain.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{digit:?} chain, bone from chain frame {bone}: {what}")]
pub struct RestChainError {
    /// The digit whose chain is unusable.
    pub digit: Digit,
    /// Chain index (1 = CMC, ..., last = tip) of the joint at the start of the bad bone.
    pub bone: usize,
    /// What was wrong, with the value found.
    pub what: String,
}

/// Shortest bone [`HandSkeleton::from_joint_positions`] accepts (metres): a shorter one has no
/// usable direction in `f32` at hand scale.
pub const MIN_BONE_LENGTH: f32 = 1e-4;

impl HandSkeleton {
    /// A skeleton whose flat pose ([`HandPose::FLAT`]) passes exactly through given joint
    /// centres, for binding external rest meshes (e.g. the WebXR hand, issue 4 item 7).
    ///
    /// `positions[d]` holds digit `d`'s chain in the wrist frame (module docs), wrist excluded:
    /// CMC, MCP, (PIP, DIP | IP), tip, i.e. [`Digit::chain_len`]` - 1` entries (the thumb's
    /// last slot is ignored). `dorsal[d][k]` is the dorsal (nail-side) direction of joint `k`
    /// of the digit ([`Digit::joints`] order; need not be unit or orthogonal to the bone).
    ///
    /// Every joint's rest frame gets local `+Y` towards the next chain position and `+Z` the
    /// dorsal hint made orthogonal to it; the CMC base is the first position, the bone lengths
    /// the distances along the chain, and the rest rotations the frames' relative rotations
    /// (the wrist frame is the identity). So any curl or splay of the given chain becomes part of
    /// the rest rotations: joint angles are measured from it.
    pub fn from_joint_positions(
        positions: &[[Vec3; MAX_CHAIN - 1]; 5],
        dorsal: &[[Vec3; MAX_CHAIN - 2]; 5],
    ) -> Result<HandSkeleton, RestChainError> {
        let mut digits = [DigitRest {
            base: Vec3::ZERO,
            rest: [Quat::IDENTITY; MAX_DIGIT_JOINTS],
            lengths: [0.0; MAX_DIGIT_JOINTS],
        }; 5];
        for digit in Digit::ALL {
            let p = &positions[digit.index()];
            let fail = |bone: usize, what: String| RestChainError { digit, bone, what };
            let out = &mut digits[digit.index()];
            out.base = p[0];
            if !p[0].is_finite() {
                return Err(fail(1, format!("CMC position {} is not finite", p[0])));
            }
            let mut parent = Quat::IDENTITY;
            for k in 0..digit.joints().len() {
                let bone = p[k + 1] - p[k];
                let length = bone.length();
                if !(length.is_finite() && length >= MIN_BONE_LENGTH) {
                    return Err(fail(
                        k + 1,
                        format!("bone length {length} m, expected finite and >= {MIN_BONE_LENGTH}"),
                    ));
                }
                let y = bone / length;
                let hint = dorsal[digit.index()][k];
                let z = hint - hint.dot(y) * y;
                if !(z.is_finite() && z.length() > 1e-3 * hint.length()) {
                    return Err(fail(
                        k + 1,
                        format!("dorsal direction {hint} is zero, not finite or along the bone"),
                    ));
                }
                let z = z.normalize();
                let frame = Quat::from_mat3(&glam::Mat3::from_cols(y.cross(z), y, z)).normalize();
                out.rest[k] = (parent.inverse() * frame).normalize();
                out.lengths[k] = length;
                parent = frame;
            }
        }
        Ok(HandSkeleton { digits })
    }

    /// This skeleton with another hand's bone geometry: the CMC bases (wrist frame) and bone
    /// lengths ([`HandSkeleton::bone_lengths`] order; unused entries ignored) replaced, the rest
    /// rotations kept, so the same angles pose it the same way (e.g. to measure how well angles
    /// recovered from a tracked hand reproduce that hand's own joints).
    pub fn with_bones(&self, bases: [Vec3; 5], lengths: [[f32; MAX_CHAIN - 2]; 5]) -> HandSkeleton {
        let mut out = self.clone();
        for digit in Digit::ALL {
            let d = &mut out.digits[digit.index()];
            d.base = bases[digit.index()];
            let n = digit.joints().len();
            d.lengths[..n].copy_from_slice(&lengths[digit.index()][..n]);
        }
        out
    }

    /// Rest rotations of `digit`'s joints relative to their parent frames (the first relative
    /// to the wrist frame), applied before each joint's articulation; [`Digit::joints`] order.
    pub fn rest_rotations(&self, digit: Digit) -> &[Quat] {
        &self.digits[digit.index()].rest[..digit.joints().len()]
    }
}

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

use std::collections::BTreeMap;
use std::f32::consts::PI;
use std::fmt;
use std::str::FromStr;

use glam::{Affine3A, Quat, Vec3};
use serde::{Deserialize, Serialize};

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

/// One of the five digits. Each carries one sweep from the wrist to its tip (LYK06 §2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Digit {
    /// The thumb: CMC (2 DOF), MCP, IP.
    Thumb,
    /// Index finger: fixed CMC, MCP (2 DOF), PIP, DIP.
    Index,
    /// Middle finger: fixed CMC, MCP (2 DOF), PIP, DIP.
    Middle,
    /// Ring finger: CMC cupping, MCP (2 DOF), PIP, DIP.
    Ring,
    /// Little finger: CMC cupping, MCP (2 DOF), PIP, DIP.
    Little,
}

impl Digit {
    /// All digits, thumb first, in radial-to-ulnar order.
    pub const ALL: [Digit; 5] = [
        Digit::Thumb,
        Digit::Index,
        Digit::Middle,
        Digit::Ring,
        Digit::Little,
    ];
    /// The four fingers (every digit but the thumb).
    pub const FINGERS: [Digit; 4] = [Digit::Index, Digit::Middle, Digit::Ring, Digit::Little];

    /// Position in [`Digit::ALL`].
    pub const fn index(self) -> usize {
        self as usize
    }

    /// Lower-case name ("thumb", "index", ...).
    pub const fn name(self) -> &'static str {
        match self {
            Digit::Thumb => "thumb",
            Digit::Index => "index",
            Digit::Middle => "middle",
            Digit::Ring => "ring",
            Digit::Little => "little",
        }
    }

    /// The joints of this digit from the wrist outwards (the wrist itself excluded).
    pub const fn joints(self) -> &'static [Joint] {
        match self {
            Digit::Thumb => &[Joint::ThumbCmc, Joint::ThumbMcp, Joint::ThumbIp],
            Digit::Index => &[
                Joint::IndexCmc,
                Joint::IndexMcp,
                Joint::IndexPip,
                Joint::IndexDip,
            ],
            Digit::Middle => &[
                Joint::MiddleCmc,
                Joint::MiddleMcp,
                Joint::MiddlePip,
                Joint::MiddleDip,
            ],
            Digit::Ring => &[
                Joint::RingCmc,
                Joint::RingMcp,
                Joint::RingPip,
                Joint::RingDip,
            ],
            Digit::Little => &[
                Joint::LittleCmc,
                Joint::LittleMcp,
                Joint::LittlePip,
                Joint::LittleDip,
            ],
        }
    }

    /// Number of frames in this digit's chain: wrist, its joints, tip (5 for the thumb, 6 for
    /// a finger).
    pub const fn chain_len(self) -> usize {
        self.joints().len() + 2
    }

    /// Sign `s` of the abduction rotation `Rz(s * a)`: positive abduction moves the digit away
    /// from the middle finger (radially for thumb, index and middle; ulnarly for ring, little).
    const fn abduction_sign(self) -> f32 {
        match self {
            Digit::Thumb | Digit::Index | Digit::Middle => 1.0,
            Digit::Ring | Digit::Little => -1.0,
        }
    }
}

/// A joint of the skeleton. The fingertips are end points, not joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Joint {
    /// The wrist: the root of every digit chain (flexion and radial/ulnar deviation).
    Wrist,
    /// Thumb carpometacarpal (trapeziometacarpal) joint.
    ThumbCmc,
    /// Thumb metacarpophalangeal joint.
    ThumbMcp,
    /// Thumb interphalangeal joint.
    ThumbIp,
    /// Index CMC (rigid: no degree of freedom, a frame for the sweep).
    IndexCmc,
    /// Index MCP.
    IndexMcp,
    /// Index PIP.
    IndexPip,
    /// Index DIP.
    IndexDip,
    /// Middle CMC (rigid).
    MiddleCmc,
    /// Middle MCP.
    MiddleMcp,
    /// Middle PIP.
    MiddlePip,
    /// Middle DIP.
    MiddleDip,
    /// Ring CMC (cupping).
    RingCmc,
    /// Ring MCP.
    RingMcp,
    /// Ring PIP.
    RingPip,
    /// Ring DIP.
    RingDip,
    /// Little CMC (cupping).
    LittleCmc,
    /// Little MCP.
    LittleMcp,
    /// Little PIP.
    LittlePip,
    /// Little DIP.
    LittleDip,
}

impl Joint {
    /// Number of joints.
    pub const COUNT: usize = 20;
    /// Every joint, wrist first, then digit by digit from the wrist outwards.
    pub const ALL: [Joint; Joint::COUNT] = [
        Joint::Wrist,
        Joint::ThumbCmc,
        Joint::ThumbMcp,
        Joint::ThumbIp,
        Joint::IndexCmc,
        Joint::IndexMcp,
        Joint::IndexPip,
        Joint::IndexDip,
        Joint::MiddleCmc,
        Joint::MiddleMcp,
        Joint::MiddlePip,
        Joint::MiddleDip,
        Joint::RingCmc,
        Joint::RingMcp,
        Joint::RingPip,
        Joint::RingDip,
        Joint::LittleCmc,
        Joint::LittleMcp,
        Joint::LittlePip,
        Joint::LittleDip,
    ];

    /// Snake-case name ("wrist", "index_mcp", ...).
    pub const fn name(self) -> &'static str {
        match self {
            Joint::Wrist => "wrist",
            Joint::ThumbCmc => "thumb_cmc",
            Joint::ThumbMcp => "thumb_mcp",
            Joint::ThumbIp => "thumb_ip",
            Joint::IndexCmc => "index_cmc",
            Joint::IndexMcp => "index_mcp",
            Joint::IndexPip => "index_pip",
            Joint::IndexDip => "index_dip",
            Joint::MiddleCmc => "middle_cmc",
            Joint::MiddleMcp => "middle_mcp",
            Joint::MiddlePip => "middle_pip",
            Joint::MiddleDip => "middle_dip",
            Joint::RingCmc => "ring_cmc",
            Joint::RingMcp => "ring_mcp",
            Joint::RingPip => "ring_pip",
            Joint::RingDip => "ring_dip",
            Joint::LittleCmc => "little_cmc",
            Joint::LittleMcp => "little_mcp",
            Joint::LittlePip => "little_pip",
            Joint::LittleDip => "little_dip",
        }
    }

    /// The joint with this [`Joint::name`].
    pub fn from_name(name: &str) -> Option<Joint> {
        Joint::ALL.into_iter().find(|j| j.name() == name)
    }

    /// The digit this joint belongs to; `None` for the wrist, which is shared by all.
    pub const fn digit(self) -> Option<Digit> {
        match self {
            Joint::Wrist => None,
            Joint::ThumbCmc | Joint::ThumbMcp | Joint::ThumbIp => Some(Digit::Thumb),
            Joint::IndexCmc | Joint::IndexMcp | Joint::IndexPip | Joint::IndexDip => {
                Some(Digit::Index)
            }
            Joint::MiddleCmc | Joint::MiddleMcp | Joint::MiddlePip | Joint::MiddleDip => {
                Some(Digit::Middle)
            }
            Joint::RingCmc | Joint::RingMcp | Joint::RingPip | Joint::RingDip => Some(Digit::Ring),
            Joint::LittleCmc | Joint::LittleMcp | Joint::LittlePip | Joint::LittleDip => {
                Some(Digit::Little)
            }
        }
    }

    /// Index of this joint's frame in its digit's chain ([`PosedSkeleton::chain`]): 0 for the
    /// wrist, 1 for a CMC, and so on.
    pub fn chain_index(self) -> usize {
        match self.digit() {
            None => 0,
            Some(d) => 1 + d.joints().iter().position(|&j| j == self).unwrap_or(0),
        }
    }
}

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Which rotation of a joint a degree of freedom is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DofKind {
    /// Rotation about the joint's local `-X`: positive curls towards the palmar side. For the
    /// ring and little CMC this is cupping, about an oblique axis.
    Flexion,
    /// Rotation about the joint's local `Z`: positive moves away from the middle finger.
    Abduction,
}

/// Number of degrees of freedom of a [`HandPose`].
pub const DOF_COUNT: usize = 24;

/// The degrees of freedom: (joint, kind, name). The one source of truth for their order.
const DOF_TABLE: [(Joint, DofKind, &str); DOF_COUNT] = [
    (Joint::Wrist, DofKind::Flexion, "wrist_flexion"),
    (Joint::Wrist, DofKind::Abduction, "wrist_abduction"),
    (Joint::ThumbCmc, DofKind::Flexion, "thumb_cmc_flexion"),
    (Joint::ThumbCmc, DofKind::Abduction, "thumb_cmc_abduction"),
    (Joint::ThumbMcp, DofKind::Flexion, "thumb_mcp_flexion"),
    (Joint::ThumbIp, DofKind::Flexion, "thumb_ip_flexion"),
    (Joint::IndexMcp, DofKind::Flexion, "index_mcp_flexion"),
    (Joint::IndexMcp, DofKind::Abduction, "index_mcp_abduction"),
    (Joint::IndexPip, DofKind::Flexion, "index_pip_flexion"),
    (Joint::IndexDip, DofKind::Flexion, "index_dip_flexion"),
    (Joint::MiddleMcp, DofKind::Flexion, "middle_mcp_flexion"),
    (Joint::MiddleMcp, DofKind::Abduction, "middle_mcp_abduction"),
    (Joint::MiddlePip, DofKind::Flexion, "middle_pip_flexion"),
    (Joint::MiddleDip, DofKind::Flexion, "middle_dip_flexion"),
    (Joint::RingCmc, DofKind::Flexion, "ring_cmc_flexion"),
    (Joint::RingMcp, DofKind::Flexion, "ring_mcp_flexion"),
    (Joint::RingMcp, DofKind::Abduction, "ring_mcp_abduction"),
    (Joint::RingPip, DofKind::Flexion, "ring_pip_flexion"),
    (Joint::RingDip, DofKind::Flexion, "ring_dip_flexion"),
    (Joint::LittleCmc, DofKind::Flexion, "little_cmc_flexion"),
    (Joint::LittleMcp, DofKind::Flexion, "little_mcp_flexion"),
    (Joint::LittleMcp, DofKind::Abduction, "little_mcp_abduction"),
    (Joint::LittlePip, DofKind::Flexion, "little_pip_flexion"),
    (Joint::LittleDip, DofKind::Flexion, "little_dip_flexion"),
];

/// One degree of freedom (one joint angle) of a [`HandPose`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Dof(u8);

impl Dof {
    /// Every degree of freedom, in storage order.
    pub fn all() -> impl Iterator<Item = Dof> {
        (0..DOF_COUNT as u8).map(Dof)
    }

    /// The degree of freedom `kind` of `joint`, if the joint has it.
    pub fn new(joint: Joint, kind: DofKind) -> Option<Dof> {
        DOF_TABLE
            .iter()
            .position(|&(j, k, _)| j == joint && k == kind)
            .map(|i| Dof(i as u8))
    }

    /// The degree of freedom with this [`Dof::name`].
    pub fn from_name(name: &str) -> Option<Dof> {
        DOF_TABLE
            .iter()
            .position(|&(_, _, n)| n == name)
            .map(|i| Dof(i as u8))
    }

    /// Position in storage order (`< DOF_COUNT`).
    pub const fn index(self) -> usize {
        self.0 as usize
    }

    /// The joint it rotates.
    pub const fn joint(self) -> Joint {
        DOF_TABLE[self.0 as usize].0
    }

    /// Flexion or abduction.
    pub const fn kind(self) -> DofKind {
        DOF_TABLE[self.0 as usize].1
    }

    /// Snake-case name, `"<joint>_<kind>"` (e.g. `"index_mcp_flexion"`); the key in pose JSON.
    pub const fn name(self) -> &'static str {
        DOF_TABLE[self.0 as usize].2
    }
}

/// Anatomical range of every degree of freedom, radians, `min <= max`.
#[derive(Clone, Debug, PartialEq)]
pub struct JointLimits {
    min: [f32; DOF_COUNT],
    max: [f32; DOF_COUNT],
}

impl JointLimits {
    /// Active ranges of motion of an adult hand, round values of the order of the usual clinical
    /// (AAOS-style) tables, not taken from one source: wrist flexion -70..80°,
    /// deviation -30 (ulnar)..20° (radial); thumb CMC flexion -20..50° and palmar abduction
    /// -10..60° (measured from this skeleton's rest thumb, which is already half abducted),
    /// thumb MCP -10..60°, IP -15..80°; finger MCP flexion -20..90°, abduction ±20° (middle
    /// ±15°), PIP 0..110°, DIP 0..80°; CMC cupping ring 0..10°, little 0..15°.
    pub fn adult() -> Self {
        let mut limits = JointLimits {
            min: [0.0; DOF_COUNT],
            max: [0.0; DOF_COUNT],
        };
        for dof in Dof::all() {
            let (lo, hi) = match (dof.joint(), dof.kind()) {
                (Joint::Wrist, DofKind::Flexion) => (-70.0, 80.0),
                (Joint::Wrist, DofKind::Abduction) => (-30.0, 20.0),
                (Joint::ThumbCmc, DofKind::Flexion) => (-20.0, 50.0),
                (Joint::ThumbCmc, DofKind::Abduction) => (-10.0, 60.0),
                (Joint::ThumbMcp, _) => (-10.0, 60.0),
                (Joint::ThumbIp, _) => (-15.0, 80.0),
                (Joint::RingCmc, _) => (0.0, 10.0),
                (Joint::LittleCmc, _) => (0.0, 15.0),
                (Joint::MiddleMcp, DofKind::Abduction) => (-15.0, 15.0),
                (Joint::IndexMcp | Joint::RingMcp | Joint::LittleMcp, DofKind::Abduction) => {
                    (-20.0, 20.0)
                }
                (Joint::IndexMcp | Joint::MiddleMcp | Joint::RingMcp | Joint::LittleMcp, _) => {
                    (-20.0, 90.0)
                }
                (Joint::IndexPip | Joint::MiddlePip | Joint::RingPip | Joint::LittlePip, _) => {
                    (0.0, 110.0)
                }
                (Joint::IndexDip | Joint::MiddleDip | Joint::RingDip | Joint::LittleDip, _) => {
                    (0.0, 80.0)
                }
                // The index and middle CMC have no degree of freedom in DOF_TABLE.
                (Joint::IndexCmc | Joint::MiddleCmc, _) => (0.0, 0.0),
            };
            limits.min[dof.index()] = deg(lo);
            limits.max[dof.index()] = deg(hi);
        }
        limits
    }

    /// `(min, max)` of one degree of freedom, radians.
    pub fn range(&self, dof: Dof) -> (f32, f32) {
        (self.min[dof.index()], self.max[dof.index()])
    }

    /// Replaces one range; `None` (and no change) unless both ends are finite and `min <= max`.
    pub fn with_range(mut self, dof: Dof, min: f32, max: f32) -> Option<Self> {
        if !(min.is_finite() && max.is_finite() && min <= max) {
            return None;
        }
        self.min[dof.index()] = min;
        self.max[dof.index()] = max;
        Some(self)
    }
}

impl Default for JointLimits {
    fn default() -> Self {
        JointLimits::adult()
    }
}

/// Joint angles of a hand, radians, one per [`Dof`]. All zero is the flat pose.
///
/// Serialises as a JSON object from [`Dof::name`] to angle; missing names read as 0, unknown
/// names are an error.
#[derive(Clone, Copy, Debug, PartialEq, Default, Serialize, Deserialize)]
#[serde(into = "BTreeMap<String, f32>", try_from = "BTreeMap<String, f32>")]
pub struct HandPose {
    angles: [f32; DOF_COUNT],
}

impl HandPose {
    /// The flat pose: every angle zero.
    pub const FLAT: HandPose = HandPose {
        angles: [0.0; DOF_COUNT],
    };

    /// A pose from angles in [`Dof::all`] order.
    pub const fn from_angles(angles: [f32; DOF_COUNT]) -> Self {
        HandPose { angles }
    }

    /// The angles in [`Dof::all`] order.
    pub const fn angles(&self) -> &[f32; DOF_COUNT] {
        &self.angles
    }

    /// One angle.
    pub fn get(&self, dof: Dof) -> f32 {
        self.angles[dof.index()]
    }

    /// Sets one angle.
    pub fn set(&mut self, dof: Dof, radians: f32) {
        self.angles[dof.index()] = radians;
    }

    /// Flexion of `joint`; 0 for a joint without a flexion degree of freedom.
    pub fn flexion(&self, joint: Joint) -> f32 {
        Dof::new(joint, DofKind::Flexion).map_or(0.0, |d| self.get(d))
    }

    /// Abduction of `joint`; 0 for a joint without an abduction degree of freedom.
    pub fn abduction(&self, joint: Joint) -> f32 {
        Dof::new(joint, DofKind::Abduction).map_or(0.0, |d| self.get(d))
    }

    /// Every angle finite.
    pub fn is_finite(&self) -> bool {
        self.angles.iter().all(|a| a.is_finite())
    }

    /// Every angle finite and inside its range.
    pub fn is_within(&self, limits: &JointLimits) -> bool {
        Dof::all().all(|d| {
            let (lo, hi) = limits.range(d);
            let a = self.get(d);
            a.is_finite() && lo <= a && a <= hi
        })
    }

    /// This pose with every angle clamped into its range; a non-finite angle becomes the value
    /// of the range closest to 0 (the flat pose's angle), so the result is always within limits.
    pub fn clamp(&self, limits: &JointLimits) -> HandPose {
        let mut out = *self;
        for d in Dof::all() {
            let (lo, hi) = limits.range(d);
            let a = self.get(d);
            let a = if a.is_finite() { a } else { 0.0 };
            out.set(d, a.clamp(lo, hi));
        }
        out
    }

    /// Angle-wise linear interpolation, `t = 0` gives `self`, `t = 1` gives `other`. Between two
    /// poses within limits the result is within limits too (the ranges are intervals).
    pub fn lerp(&self, other: &HandPose, t: f32) -> HandPose {
        let mut out = *self;
        for (o, (a, b)) in out
            .angles
            .iter_mut()
            .zip(self.angles.iter().zip(other.angles.iter()))
        {
            *o = a + (b - a) * t;
        }
        out
    }

    /// One of the named poses.
    pub fn named(pose: NamedPose) -> HandPose {
        named_pose(pose)
    }

    /// Sets a joint's angle in degrees; for building poses from anatomical tables.
    fn set_deg(&mut self, joint: Joint, kind: DofKind, degrees: f32) {
        let dof = Dof::new(joint, kind);
        debug_assert!(dof.is_some(), "{joint} has no {kind:?}");
        if let Some(d) = dof {
            self.set(d, deg(degrees));
        }
    }

    /// Sets a finger's MCP flexion and abduction, PIP and DIP flexion, in degrees.
    fn set_finger(&mut self, digit: Digit, mcp: f32, abduction: f32, pip: f32, dip: f32) {
        let j = digit.joints();
        self.set_deg(j[1], DofKind::Flexion, mcp);
        self.set_deg(j[1], DofKind::Abduction, abduction);
        self.set_deg(j[2], DofKind::Flexion, pip);
        self.set_deg(j[3], DofKind::Flexion, dip);
    }

    /// Sets the thumb's CMC flexion and abduction, MCP and IP flexion, in degrees.
    fn set_thumb(&mut self, cmc_flexion: f32, cmc_abduction: f32, mcp: f32, ip: f32) {
        self.set_deg(Joint::ThumbCmc, DofKind::Flexion, cmc_flexion);
        self.set_deg(Joint::ThumbCmc, DofKind::Abduction, cmc_abduction);
        self.set_deg(Joint::ThumbMcp, DofKind::Flexion, mcp);
        self.set_deg(Joint::ThumbIp, DofKind::Flexion, ip);
    }

    /// Sets the ring and little CMC cupping, in degrees.
    fn set_cupping(&mut self, ring: f32, little: f32) {
        self.set_deg(Joint::RingCmc, DofKind::Flexion, ring);
        self.set_deg(Joint::LittleCmc, DofKind::Flexion, little);
    }
}

impl From<HandPose> for BTreeMap<String, f32> {
    fn from(pose: HandPose) -> Self {
        Dof::all()
            .map(|d| (d.name().to_owned(), pose.get(d)))
            .collect()
    }
}

impl TryFrom<BTreeMap<String, f32>> for HandPose {
    type Error = SkeletonError;

    fn try_from(map: BTreeMap<String, f32>) -> Result<Self, Self::Error> {
        let mut pose = HandPose::FLAT;
        for (name, angle) in map {
            let dof = Dof::from_name(&name).ok_or(SkeletonError::UnknownDof(name))?;
            pose.set(dof, angle);
        }
        Ok(pose)
    }
}

/// The named poses of issue 4, for tests, demos and the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NamedPose {
    /// Every angle zero: fingers straight and together, thumb at rest beside the palm.
    Flat,
    /// The resting posture: a light flexion cascade increasing from index to little.
    Relaxed,
    /// A closed fist, thumb wrapped over the middle phalanges.
    Fist,
    /// Index straight, the other fingers curled, thumb over the middle finger.
    Point,
    /// Index and middle straight and spread (V sign), the others curled.
    Victory,
    /// Thumb and index tips meet (tip pinch); the other fingers relaxed.
    Pinch,
    /// Cylindrical power grasp around a ~5 cm handle.
    Grasp,
    /// Fingers straight and fully spread, thumb extended.
    Spread,
    /// Fist with the thumb straight.
    ThumbsUp,
    /// The OK sign: thumb and index form a ring, the other fingers straight and spread.
    Ok,
}

impl NamedPose {
    /// Every named pose.
    pub const ALL: [NamedPose; 10] = [
        NamedPose::Flat,
        NamedPose::Relaxed,
        NamedPose::Fist,
        NamedPose::Point,
        NamedPose::Victory,
        NamedPose::Pinch,
        NamedPose::Grasp,
        NamedPose::Spread,
        NamedPose::ThumbsUp,
        NamedPose::Ok,
    ];

    /// Lower-case, hyphenated name ("fist", "thumbs-up", "ok"); [`FromStr`] accepts it.
    pub const fn name(self) -> &'static str {
        match self {
            NamedPose::Flat => "flat",
            NamedPose::Relaxed => "relaxed",
            NamedPose::Fist => "fist",
            NamedPose::Point => "point",
            NamedPose::Victory => "victory",
            NamedPose::Pinch => "pinch",
            NamedPose::Grasp => "grasp",
            NamedPose::Spread => "spread",
            NamedPose::ThumbsUp => "thumbs-up",
            NamedPose::Ok => "ok",
        }
    }

    /// The joint angles of this pose.
    pub fn pose(self) -> HandPose {
        named_pose(self)
    }
}

impl fmt::Display for NamedPose {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for NamedPose {
    type Err = SkeletonError;

    /// Case-insensitive; `_` is accepted for `-` ("thumbs_up").
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let wanted = s.trim().to_ascii_lowercase().replace('_', "-");
        NamedPose::ALL
            .into_iter()
            .find(|p| p.name() == wanted)
            .ok_or_else(|| SkeletonError::UnknownPose(s.to_owned()))
    }
}

/// The angles of each named pose, in degrees: set by hand to look like the pose, inside
/// [`JointLimits::adult`] (a test checks), the pinch and OK thumbs fitted so that the thumb and
/// index tips meet (a test checks).
fn named_pose(which: NamedPose) -> HandPose {
    use Digit::{Index, Little, Middle, Ring};
    let mut p = HandPose::FLAT;
    // A fist's fingers, shared by several poses: MCP near its limit, PIP ~100°, DIP ~2/3 PIP.
    let fist = |p: &mut HandPose, digit: Digit| match digit {
        Index => p.set_finger(Index, 85.0, 0.0, 100.0, 60.0),
        Middle => p.set_finger(Middle, 88.0, 0.0, 105.0, 65.0),
        Ring => p.set_finger(Ring, 88.0, 0.0, 105.0, 65.0),
        _ => p.set_finger(Little, 85.0, 0.0, 100.0, 60.0),
    };
    match which {
        NamedPose::Flat => {}
        NamedPose::Relaxed => {
            p.set_deg(Joint::Wrist, DofKind::Flexion, -10.0);
            p.set_thumb(10.0, 25.0, 10.0, 10.0);
            p.set_finger(Index, 20.0, 2.0, 25.0, 12.0);
            p.set_finger(Middle, 25.0, 0.0, 30.0, 15.0);
            p.set_finger(Ring, 30.0, 2.0, 35.0, 18.0);
            p.set_finger(Little, 35.0, 4.0, 40.0, 20.0);
            p.set_cupping(3.0, 5.0);
        }
        NamedPose::Fist => {
            for d in Digit::FINGERS {
                fist(&mut p, d);
            }
            p.set_cupping(8.0, 12.0);
            p.set_thumb(35.0, 15.0, 45.0, 30.0);
        }
        NamedPose::Point => {
            for d in [Middle, Ring, Little] {
                fist(&mut p, d);
            }
            p.set_cupping(6.0, 10.0);
            p.set_thumb(30.0, 15.0, 40.0, 25.0);
        }
        NamedPose::Victory => {
            p.set_finger(Index, 0.0, 12.0, 0.0, 0.0);
            p.set_finger(Middle, 0.0, -10.0, 0.0, 0.0);
            fist(&mut p, Ring);
            fist(&mut p, Little);
            p.set_cupping(6.0, 10.0);
            p.set_thumb(40.0, 10.0, 45.0, 35.0);
        }
        NamedPose::Pinch => {
            p.set_finger(Index, 45.0, 0.0, 55.0, 30.0);
            p.set_finger(Middle, 20.0, 0.0, 25.0, 12.0);
            p.set_finger(Ring, 25.0, 2.0, 30.0, 15.0);
            p.set_finger(Little, 30.0, 4.0, 35.0, 18.0);
            p.set_thumb(40.0, 25.0, 0.0, 0.0);
        }
        NamedPose::Grasp => {
            for d in Digit::FINGERS {
                p.set_finger(d, 45.0, 0.0, 65.0, 40.0);
            }
            p.set_cupping(5.0, 8.0);
            p.set_thumb(25.0, 50.0, 20.0, 15.0);
        }
        NamedPose::Spread => {
            p.set_finger(Index, 0.0, 20.0, 0.0, 0.0);
            p.set_finger(Middle, 0.0, 0.0, 0.0, 0.0);
            p.set_finger(Ring, 0.0, 15.0, 0.0, 0.0);
            p.set_finger(Little, 0.0, 20.0, 0.0, 0.0);
            p.set_thumb(-15.0, 10.0, 0.0, 0.0);
        }
        NamedPose::ThumbsUp => {
            for d in Digit::FINGERS {
                fist(&mut p, d);
            }
            p.set_cupping(8.0, 12.0);
            p.set_thumb(-10.0, 10.0, 0.0, 0.0);
        }
        NamedPose::Ok => {
            p.set_finger(Index, 50.0, 0.0, 60.0, 35.0);
            p.set_finger(Middle, 5.0, -5.0, 5.0, 2.0);
            p.set_finger(Ring, 5.0, 8.0, 5.0, 2.0);
            p.set_finger(Little, 5.0, 15.0, 5.0, 2.0);
            p.set_thumb(25.0, 30.0, 15.0, 25.0);
        }
    }
    p
}

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

/// SplitMix64 (Steele, Lea & Flood 2014): a tiny, well-mixed, seedable generator; enough for
/// sampling poses, and it keeps `rand` out of core.
#[derive(Clone, Debug)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 24 random bits (all an `f32` mantissa holds).
    fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Triangular in `(-1, 1)`, peaked at 0: a cheap bounded stand-in for Gaussian jitter.
    fn jitter(&mut self) -> f32 {
        self.uniform() - self.uniform()
    }
}

/// Seeded sampler of natural hand poses.
///
/// A latent grip amount in `[0, 1]` drives every finger's flexion together; each finger
/// follows it with its own jitter (and a small chance, highest for the index, of staying
/// straight on its own, as in pointing); PIP follows MCP and DIP is about 2/3 of PIP, the
/// coupling of the flexor tendons (Rijpkema & Girard 1991); abduction shrinks as the fingers
/// flex (a flexed MCP's collateral ligaments are taut); ring and little cup with the grip;
/// the thumb mixes the grip with its own random amount. The result is always clamped to the
/// limits, so every sample is within them.
#[derive(Clone, Debug)]
pub struct PoseSampler {
    rng: SplitMix64,
    limits: JointLimits,
}

impl PoseSampler {
    /// A sampler over [`JointLimits::adult`]; the same seed gives the same sequence.
    pub fn new(seed: u64) -> Self {
        PoseSampler::with_limits(seed, JointLimits::adult())
    }

    /// A sampler whose samples are clamped to `limits`.
    pub fn with_limits(seed: u64, limits: JointLimits) -> Self {
        PoseSampler {
            rng: SplitMix64(seed),
            limits,
        }
    }

    /// The next pose.
    pub fn sample(&mut self) -> HandPose {
        let r = &mut self.rng;
        let mut p = HandPose::FLAT;
        let grip = r.uniform();
        let spread = r.uniform();
        p.set_deg(Joint::Wrist, DofKind::Flexion, 25.0 * r.jitter());
        p.set_deg(Joint::Wrist, DofKind::Abduction, 10.0 * r.jitter());
        // Per finger: chance of staying straight independently of the grip, the ulnar cascade
        // (ulnar fingers curl a little more at the same grip), and the largest spread, degrees.
        let fingers = [
            (Digit::Index, 0.20, 0.00, 20.0),
            (Digit::Middle, 0.08, 0.03, 5.0),
            (Digit::Ring, 0.04, 0.06, 15.0),
            (Digit::Little, 0.08, 0.09, 20.0),
        ];
        let mut cupping = [0.0f32; 2];
        for (digit, straight, cascade, max_spread) in fingers {
            let g = if r.uniform() < straight {
                0.1 * r.uniform()
            } else {
                (grip + cascade + 0.15 * r.jitter()).clamp(0.0, 1.0)
            };
            let mcp = -10.0 + 98.0 * g + 6.0 * r.jitter();
            let pip = (105.0 * g + 8.0 * r.jitter()).max(0.0);
            let dip = (2.0 / 3.0) * pip + 5.0 * r.jitter();
            let abduction = (1.0 - g) * spread * max_spread + 3.0 * r.jitter();
            p.set_finger(digit, mcp, abduction, pip, dip);
            match digit {
                Digit::Ring => cupping[0] = 10.0 * g * r.uniform(),
                Digit::Little => cupping[1] = 15.0 * g * r.uniform(),
                _ => {}
            }
        }
        p.set_cupping(cupping[0], cupping[1]);
        let t = 0.5 * grip + 0.5 * r.uniform();
        let thumb_mcp = 55.0 * t + 8.0 * r.jitter();
        p.set_thumb(
            -15.0 + 60.0 * t + 5.0 * r.jitter(),
            -5.0 + 60.0 * r.uniform(),
            thumb_mcp,
            0.8 * thumb_mcp + 8.0 * r.jitter(),
        );
        p.clamp(&self.limits)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dof_table_is_consistent() {
        for d in Dof::all() {
            assert_eq!(Dof::new(d.joint(), d.kind()), Some(d));
            assert_eq!(Dof::from_name(d.name()), Some(d));
            let suffix = match d.kind() {
                DofKind::Flexion => "flexion",
                DofKind::Abduction => "abduction",
            };
            assert_eq!(d.name(), format!("{}_{suffix}", d.joint().name()));
        }
        let (lo, hi) = JointLimits::adult().range(Dof(0));
        assert!(lo < hi);
    }

    #[test]
    fn joint_names_and_chain_indices_round_trip() {
        for j in Joint::ALL {
            assert_eq!(Joint::from_name(j.name()), Some(j));
            if let Some(d) = j.digit() {
                assert_eq!(d.joints()[j.chain_index() - 1], j);
            }
        }
    }

    #[test]
    fn splitmix_matches_reference_values() {
        // The first outputs for this seed in rand_xoshiro's `reference` test (rust-random/rngs,
        // rand_xoshiro/src/splitmix64.rs), produced with Vigna's splitmix64.c.
        let mut r = SplitMix64(1477776061723855037);
        for expected in [
            1985237415132408290,
            2979275885539914483,
            13511426838097143398,
        ] {
            assert_eq!(r.next_u64(), expected);
        }
    }
}

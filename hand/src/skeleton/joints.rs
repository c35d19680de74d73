//! The skeleton's vocabulary: the five [`Digit`]s, their [`Joint`]s, the degrees of freedom
//! ([`Dof`], one row of a single table giving joint, kind and name) and the adult ranges of
//! motion ([`JointLimits`]).

use std::fmt;

use serde::{Deserialize, Serialize};

use super::deg;

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
    pub(super) const fn abduction_sign(self) -> f32 {
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
    ///
    /// [`PosedSkeleton::chain`]: super::PosedSkeleton::chain
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
///
/// [`HandPose`]: super::HandPose
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
///
/// [`HandPose`]: super::HandPose
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
}

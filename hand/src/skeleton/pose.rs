//! [`HandPose`]: one angle per degree of freedom (JSON by name, missing names 0), and the
//! [`NamedPose`]s with their hand-set angles.

use std::collections::BTreeMap;
use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{DOF_COUNT, Digit, Dof, DofKind, Joint, JointLimits, SkeletonError, deg};

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
    pub(super) fn set_deg(&mut self, joint: Joint, kind: DofKind, degrees: f32) {
        let dof = Dof::new(joint, kind);
        debug_assert!(dof.is_some(), "{joint} has no {kind:?}");
        if let Some(d) = dof {
            self.set(d, deg(degrees));
        }
    }

    /// Sets a finger's MCP flexion and abduction, PIP and DIP flexion, in degrees.
    pub(super) fn set_finger(
        &mut self,
        digit: Digit,
        mcp: f32,
        abduction: f32,
        pip: f32,
        dip: f32,
    ) {
        let j = digit.joints();
        self.set_deg(j[1], DofKind::Flexion, mcp);
        self.set_deg(j[1], DofKind::Abduction, abduction);
        self.set_deg(j[2], DofKind::Flexion, pip);
        self.set_deg(j[3], DofKind::Flexion, dip);
    }

    /// Sets the thumb's CMC flexion and abduction, MCP and IP flexion, in degrees.
    pub(super) fn set_thumb(&mut self, cmc_flexion: f32, cmc_abduction: f32, mcp: f32, ip: f32) {
        self.set_deg(Joint::ThumbCmc, DofKind::Flexion, cmc_flexion);
        self.set_deg(Joint::ThumbCmc, DofKind::Abduction, cmc_abduction);
        self.set_deg(Joint::ThumbMcp, DofKind::Flexion, mcp);
        self.set_deg(Joint::ThumbIp, DofKind::Flexion, ip);
    }

    /// Sets the ring and little CMC cupping, in degrees.
    pub(super) fn set_cupping(&mut self, ring: f32, little: f32) {
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

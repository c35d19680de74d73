//! The hand's skeleton as VMC sends it: Unity HumanBodyBones names, each bone's pose local to
//! its parent, composed into one frame (forward kinematics), and the fingertips, which are not
//! VMC bones, placed past each distal bone.
//!
//! **Frames.** VMC poses are Unity's: left-handed, Y up, Z forward, metres. Every pose is
//! mirrored into a right-handed frame as it arrives by negating Z: a position `(x, y, z)`
//! becomes `(x, y, -z)` and a rotation `(qx, qy, qz, qw)` becomes `(-qx, -qy, qz, qw)` (the
//! mirror `M = diag(1, 1, -1)` conjugates a rotation `R` into `M R M`: its axis, a
//! pseudovector, becomes `det(M) M axis = (-ax, -ay, az)`, its angle is kept). Mirroring is a
//! homomorphism, so composing mirrored local poses gives the mirror of Unity's global poses:
//! the markers are Unity's world positions with Z negated, in metres, Y up.
//!
//! **Chain.** A bone's parent is the nearest ancestor in Unity's humanoid chain
//! (`Hips > Spine > Chest > UpperChest > Shoulder > UpperArm > LowerArm > Hand > fingers`)
//! that the sender has sent: optional bones (UpperChest, Shoulder) may be missing. The chain
//! starts at `/VMC/Ext/Root/Pos` when one was received (identity otherwise). A sender that
//! sends only the hand's subtree makes the hand the root: the joints are then in the hand's
//! parent's frame (the hand's local pose applied to an identity parent).
//!
//! **Tips.** A tip is at `distal + R_distal · (k · t_distal)`: `t_distal` is the distal bone's
//! local offset (the segment from the intermediate joint to the distal joint, in the
//! intermediate's frame) and `R_distal` the distal's global rotation, so the tip continues the
//! finger's last segment, bent by the distal joint, `k` times as long (0.8 by default). This
//! assumes bones whose rest rotations are identity (VRM's normalised humanoid, what VSeeFace,
//! VirtualMotionCapture and Warudo send); `--bones FILE` sets `k` or an absolute length.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, bail};
use crease_core::glam::{Quat, Vec3};

/// Which hand is bridged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Hand {
    /// Unity's `Right*` bones.
    Right,
    /// Unity's `Left*` bones.
    Left,
}

impl Hand {
    /// The bone-name prefix: `Right` or `Left`.
    pub fn prefix(self) -> &'static str {
        match self {
            Hand::Right => "Right",
            Hand::Left => "Left",
        }
    }
}

/// The five digits, in Unity's naming.
pub const FINGERS: [&str; 5] = ["Thumb", "Index", "Middle", "Ring", "Little"];
/// The three bones of a digit, base first.
pub const SEGMENTS: [&str; 3] = ["Proximal", "Intermediate", "Distal"];
/// The chain from the hips to the hand's parent, root first (`Shoulder`, `UpperArm`,
/// `LowerArm` carry the hand's prefix).
const TRUNK: [&str; 4] = ["Hips", "Spine", "Chest", "UpperChest"];
const ARM: [&str; 3] = ["Shoulder", "UpperArm", "LowerArm"];

/// Every Unity HumanBodyBones name that is not a finger (fingers: `{Left,Right}{digit}{segment}`).
const BODY_BONES: [&str; 25] = [
    "Hips",
    "LeftUpperLeg",
    "RightUpperLeg",
    "LeftLowerLeg",
    "RightLowerLeg",
    "LeftFoot",
    "RightFoot",
    "Spine",
    "Chest",
    "UpperChest",
    "Neck",
    "Head",
    "LeftShoulder",
    "RightShoulder",
    "LeftUpperArm",
    "RightUpperArm",
    "LeftLowerArm",
    "RightLowerArm",
    "LeftHand",
    "RightHand",
    "LeftToes",
    "RightToes",
    "LeftEye",
    "RightEye",
    "Jaw",
];

/// Whether `name` is a Unity humanoid bone or a fingertip name of either hand (a marker name
/// that is not one is taken for a tracker's serial).
pub fn is_humanoid_name(name: &str) -> bool {
    if BODY_BONES.contains(&name) {
        return true;
    }
    let Some(rest) = name
        .strip_prefix("Right")
        .or_else(|| name.strip_prefix("Left"))
    else {
        return false;
    };
    FINGERS.iter().any(|f| {
        rest.strip_prefix(f)
            .is_some_and(|s| SEGMENTS.contains(&s) || s == "Tip")
    })
}

/// A rigid pose: rotation then translation (`p -> rotation * p + position`), right-handed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// Where the bone's origin is.
    pub position: Vec3,
    /// The bone's orientation (unit).
    pub rotation: Quat,
}

impl Pose {
    /// The identity.
    pub const IDENTITY: Pose = Pose {
        position: Vec3::ZERO,
        rotation: Quat::IDENTITY,
    };

    /// A Unity (left-handed) pose mirrored into the right-handed frame (module docs). The
    /// quaternion is normalised; `None` when it has no direction or a value is not finite.
    pub fn from_unity(p: [f32; 3], q: [f32; 4]) -> Option<Pose> {
        if !p.iter().chain(q.iter()).all(|v| v.is_finite()) {
            return None;
        }
        let rotation = Quat::from_xyzw(-q[0], -q[1], q[2], q[3]);
        let len = rotation.length();
        if !(len > 1e-6 && len.is_finite()) {
            return None;
        }
        Some(Pose {
            position: Vec3::new(p[0], p[1], -p[2]),
            rotation: rotation / len,
        })
    }

    /// `self` then `local`: the pose of a child whose pose relative to `self` is `local`.
    pub fn then(&self, local: &Pose) -> Pose {
        Pose {
            position: self.position + self.rotation * local.position,
            rotation: (self.rotation * local.rotation).normalize(),
        }
    }
}

/// How long each fingertip is: `ratio` times the distal bone's local offset (the intermediate
/// segment), or `length` in metres when set.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipLength {
    /// Factor of the segment before the distal joint.
    pub ratio: f32,
    /// Absolute length (metres), overriding `ratio`.
    pub length: Option<f32>,
}

/// Tip lengths per digit, in [`FINGERS`] order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TipLengths(pub [TipLength; 5]);

impl Default for TipLengths {
    fn default() -> Self {
        TipLengths(
            [TipLength {
                ratio: DEFAULT_TIP_RATIO,
                length: None,
            }; 5],
        )
    }
}

/// The default tip: 0.8 of the segment before it (a distal phalanx is about 0.7-0.8 of the
/// middle one; the thumb's distal about 0.8 of its proximal).
pub const DEFAULT_TIP_RATIO: f32 = 0.8;

impl TipLengths {
    /// Reads `--bones FILE`: a small TOML file of tip lengths,
    ///
    /// ```toml
    /// [tip_ratio]        # factor of the segment before the distal joint (default 0.8)
    /// Thumb = 0.75
    /// Index = 0.8
    /// [tip_length]       # or an absolute length in metres, which wins over the ratio
    /// Little = 0.018
    /// ```
    ///
    /// with digits named as Unity names them (`Thumb`, `Index`, `Middle`, `Ring`, `Little`).
    /// Only this much TOML is read: tables, `Digit = number` lines and `#` comments.
    ///
    /// # Errors
    /// An unreadable file, or a line, table, digit or value that is not one of the above,
    /// naming the line.
    pub fn read(path: &Path) -> anyhow::Result<TipLengths> {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        Self::parse(&text).with_context(|| format!("--bones {}", path.display()))
    }

    /// Parses the text of a `--bones` file ([`TipLengths::read`]).
    ///
    /// # Errors
    /// As [`TipLengths::read`].
    pub fn parse(text: &str) -> anyhow::Result<TipLengths> {
        let mut tips = TipLengths::default();
        let mut table: Option<&str> = None;
        let mut seen = BTreeMap::new();
        for (n, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or("").trim();
            let at = n + 1;
            if line.is_empty() {
                continue;
            }
            if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
                let name = name.trim();
                if name != "tip_ratio" && name != "tip_length" {
                    bail!("line {at}: table [{name}]: expected [tip_ratio] or [tip_length]");
                }
                table = Some(if name == "tip_ratio" {
                    "tip_ratio"
                } else {
                    "tip_length"
                });
                continue;
            }
            let Some((key, value)) = line.split_once('=') else {
                bail!("line {at}: {raw:?}: expected `Digit = number` or a [table]");
            };
            let (key, value) = (key.trim().trim_matches('"'), value.trim());
            let Some(t) = table else {
                bail!("line {at}: {key} is outside [tip_ratio] or [tip_length]");
            };
            let Some(digit) = FINGERS.iter().position(|f| *f == key) else {
                bail!(
                    "line {at}: [{t}] {key}: not a digit (expected one of {})",
                    FINGERS.join(", ")
                );
            };
            let v: f32 = value
                .parse()
                .ok()
                .filter(|v: &f32| v.is_finite() && *v > 0.0)
                .with_context(|| {
                    format!("line {at}: [{t}] {key} = {value}: expected a positive number")
                })?;
            if seen.insert((t, digit), at).is_some() {
                bail!("line {at}: [{t}] {key} is given twice");
            }
            if t == "tip_ratio" {
                tips.0[digit].ratio = v;
            } else {
                tips.0[digit].length = Some(v);
            }
        }
        Ok(tips)
    }
}

/// What the stream's markers are, by index: the trunk and arm chain, the hand, its fifteen
/// finger bones and five tips (the names of [`Skeleton::names`]).
#[derive(Clone, Debug)]
pub struct Skeleton {
    /// Marker names in index order.
    names: Vec<String>,
    /// The chain's bones (trunk, arm, hand) by marker index, root first.
    chain: Vec<usize>,
    /// Index of the hand bone.
    hand: usize,
    /// Per digit, the indices of its three bones and its tip.
    digits: [[usize; 4]; 5],
    tips: TipLengths,
}

/// The joints of one frame: a position per [`Skeleton::names`], and whether it is valid.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Joints {
    /// Right-handed positions (module docs), metres.
    pub positions: Vec<Vec3>,
    /// Whether the joint was received this frame (tips: their distal bone) and its chain to
    /// the hand is known.
    pub valid: Vec<bool>,
}

impl Skeleton {
    /// The skeleton of `hand`'s side.
    pub fn new(hand: Hand, tips: TipLengths) -> Skeleton {
        let side = hand.prefix();
        let mut names: Vec<String> = TRUNK.iter().map(|s| (*s).to_owned()).collect();
        names.extend(ARM.iter().map(|s| format!("{side}{s}")));
        names.push(format!("{side}Hand"));
        let hand_index = names.len() - 1;
        let chain = (0..names.len()).collect();
        let mut digits = [[0; 4]; 5];
        for (d, finger) in FINGERS.iter().enumerate() {
            for (s, segment) in SEGMENTS.iter().enumerate() {
                digits[d][s] = names.len();
                names.push(format!("{side}{finger}{segment}"));
            }
        }
        for (d, finger) in FINGERS.iter().enumerate() {
            digits[d][3] = names.len();
            names.push(format!("{side}{finger}Tip"));
        }
        Skeleton {
            names,
            chain,
            hand: hand_index,
            digits,
            tips,
        }
    }

    /// The marker names the skeleton gives, in index order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// The index of a bone name (not a tip), if it is one of this skeleton's.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        let i = self.names.iter().position(|n| n == name)?;
        (!self.digits.iter().any(|d| d[3] == i)).then_some(i)
    }

    /// Whether `index` is the hand or one of its finger bones.
    pub fn is_hand_bone(&self, index: usize) -> bool {
        index == self.hand || self.digits.iter().any(|d| d[..3].contains(&index))
    }

    /// Forward kinematics of one frame. `locals[i]` is bone `i`'s latest local pose (or
    /// `None` if never received), `fresh[i]` whether it came in this frame, `root` the
    /// `/VMC/Ext/Root/Pos` pose. A bone's global pose composes the known chain above it (module
    /// docs); a joint is valid when it is fresh and the hand and every finger bone between
    /// it and the hand are known.
    pub fn solve(&self, locals: &[Option<Pose>], fresh: &[bool], root: Option<Pose>) -> Joints {
        let n = self.names.len();
        assert_eq!(locals.len(), n, "one local pose slot per marker");
        let mut out = Joints {
            positions: vec![Vec3::NAN; n],
            valid: vec![false; n],
        };
        // The trunk and arm: each known bone composes onto the last known one above it.
        let mut parent = root.unwrap_or(Pose::IDENTITY);
        let mut hand_global = None;
        for &i in &self.chain {
            if let Some(local) = &locals[i] {
                parent = parent.then(local);
                out.positions[i] = parent.position;
                out.valid[i] = fresh[i];
                if i == self.hand {
                    hand_global = Some(parent);
                }
            }
        }
        let Some(hand) = hand_global else {
            return out;
        };
        for (d, digit) in self.digits.iter().enumerate() {
            let mut pose = hand;
            let mut last = None;
            for &b in &digit[..3] {
                let Some(local) = &locals[b] else {
                    last = None;
                    break;
                };
                pose = pose.then(local);
                out.positions[b] = pose.position;
                out.valid[b] = fresh[b];
                last = Some((pose, local.position));
            }
            if let Some((distal, offset)) = last {
                let tip = self.tips.0[d];
                let step = match tip.length {
                    Some(len) => offset.normalize_or_zero() * len,
                    None => offset * tip.ratio,
                };
                let t = digit[3];
                out.positions[t] = distal.position + distal.rotation * step;
                out.valid[t] = fresh[digit[2]] && step.length() > 0.0;
            }
        }
        for (p, v) in out.positions.iter().zip(out.valid.iter_mut()) {
            *v &= p.is_finite();
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_humanoid_check() {
        let s = Skeleton::new(Hand::Right, TipLengths::default());
        assert_eq!(s.names().len(), 8 + 15 + 5);
        assert_eq!(s.names()[7], "RightHand");
        assert!(s.names().iter().any(|n| n == "RightIndexTip"));
        assert!(s.bone_index("RightIndexTip").is_none());
        assert!(s.bone_index("RightIndexDistal").is_some());
        assert!(is_humanoid_name("LeftLittleTip"));
        assert!(is_humanoid_name("UpperChest"));
        assert!(!is_humanoid_name("LHR-0A1B2C3D"));
        assert!(!is_humanoid_name("RightIndexMiddle"));
    }

    #[test]
    fn tip_file_parses_and_names_its_errors() {
        let t = TipLengths::parse(
            "# tips\n[tip_ratio]\nThumb = 0.75\n\n[tip_length]\nLittle = 0.018 # metres\n",
        )
        .unwrap();
        assert_eq!(t.0[0].ratio, 0.75);
        assert_eq!(t.0[1].ratio, DEFAULT_TIP_RATIO);
        assert_eq!(t.0[4].length, Some(0.018));
        let e = TipLengths::parse("[tip_ratio]\nPinky = 1\n").unwrap_err();
        assert!(format!("{e:#}").contains("line 2") && format!("{e:#}").contains("Pinky"));
        assert!(TipLengths::parse("Index = 1\n").is_err());
        assert!(TipLengths::parse("[tips]\n").is_err());
        assert!(TipLengths::parse("[tip_ratio]\nIndex = -1\n").is_err());
        assert!(TipLengths::parse("[tip_ratio]\nIndex = 1\nIndex = 2\n").is_err());
    }

    #[test]
    fn mirror_keeps_rotations_consistent() {
        // 90 degrees about Unity's Y: Unity's +X goes to -Z; mirrored, +X goes to +Z.
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let p = Pose::from_unity([0.0, 0.0, 0.0], [0.0, h, 0.0, h]).unwrap();
        let v = p.rotation * Vec3::X;
        assert!((v - Vec3::Z).length() < 1e-6, "{v}");
        assert!(Pose::from_unity([0.0; 3], [0.0; 4]).is_none());
        assert!(Pose::from_unity([f32::NAN, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]).is_none());
    }
}

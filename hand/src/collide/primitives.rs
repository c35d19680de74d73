//! The primitives that approximate the hand (digit spheres, palm patches, joint fold planes),
//! the external [`Ball`], and the geometry the detection and the push-out share: penetration
//! depths, patch heights, bounding spheres and the cull's overlap tests.

use glam::Vec3;

use super::{Owner, PALM_DEPTH, PALM_PATCH_RADIUS};
use crate::skeleton::Digit;

/// Why a [`CollisionSphere`] exists.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SphereKind {
    /// Sampled along the sweep every [`SPHERE_SPACING`].
    ///
    /// [`SPHERE_SPACING`]: super::SPHERE_SPACING
    Sampled,
    /// At an IP / PIP / DIP joint (LYK06's extra joint spheres).
    Joint,
}

/// A collision sphere on a digit's sweep (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CollisionSphere {
    /// The digit whose sweep carries it.
    pub digit: Digit,
    /// Arc length on the digit's sweep (metres; the same in every pose).
    pub arc: f32,
    /// Radius (metres).
    pub radius: f32,
    /// Centre `T(arc)`: in the last pose given to [`HandCollider::apply`] (the rest pose before).
    ///
    /// [`HandCollider::apply`]: super::HandCollider::apply
    pub center: Vec3,
    /// Sampled or at a joint.
    pub kind: SphereKind,
    /// Whether it is tested against the palm ([`PALM_REACH_FRACTION`]).
    ///
    /// [`PALM_REACH_FRACTION`]: super::PALM_REACH_FRACTION
    pub palm_reach: bool,
}

/// A tangent plane of the palm, acting within [`PALM_PATCH_RADIUS`] of its point (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PalmPlane {
    /// The skin vertex the plane passes through.
    pub vertex: u32,
    /// Point on the plane: the deformed sample vertex (last pose; rest before).
    pub point: Vec3,
    /// Unit normal out of the palmar skin.
    pub normal: Vec3,
}

/// The cross-sectional plane of a sweep at an IP / PIP / DIP joint (LYK06 "Folding at joints").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FoldPlane {
    /// The digit.
    pub digit: Digit,
    /// Index of the joint in the digit's chain (3: PIP or thumb IP, 4: DIP).
    pub chain_index: usize,
    /// Arc length `s_J` of the joint on the sweep.
    pub arc: f32,
    /// `T(s_J)` in the last pose (rest before).
    pub point: Vec3,
    /// The sweep direction `R(s_J) +Y` (towards the tip) in the last pose.
    pub normal: Vec3,
}

/// An external rigid ball (LYK06 "Collision detection with other objects").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ball {
    /// Centre, metres, in the hand frame.
    pub center: Vec3,
    /// Radius, metres.
    pub radius: f32,
}

/// A primitive as the push-out sees it this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Shape {
    /// Centre and (effective) radius.
    Sphere(Vec3, f32),
    /// Point, outward normal, sink (the plane's surface is at `-sink` along the normal).
    Plane(Vec3, Vec3, f32),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Obstacle {
    pub(super) shape: Shape,
    pub(super) owner: Owner,
    /// Spheres: whether they reach the palm (and their digit passes the curl early-out).
    pub(super) palm_reach: bool,
}

/// Outward palm normal from a sample's `-X, +X, -Y, +Y` neighbours: `Y × X` is `-Z` in the
/// rest palm, i.e. palmar.
pub(super) fn plane_normal(positions: &[Vec3], ring: &[u32; 4]) -> Vec3 {
    let [mx, px, my, py] = ring.map(|i| positions[i as usize]);
    (py - my).cross(px - mx).normalize_or_zero()
}

/// Bounding sphere of some spheres: centred on the mean centre.
pub(super) fn bound_of(spheres: impl Iterator<Item = (Vec3, f32)> + Clone) -> (Vec3, f32) {
    let (sum, count) = spheres
        .clone()
        .fold((Vec3::ZERO, 0usize), |(s, c), (p, _)| (s + p, c + 1));
    if count == 0 {
        return (Vec3::ZERO, -1.0);
    }
    let c = sum / count as f32;
    let r = spheres.fold(0.0f32, |r, (p, pr)| r.max((p - c).length() + pr));
    (c, r)
}

pub(super) fn overlaps(a: (Vec3, f32), b: (Vec3, f32)) -> bool {
    a.1 >= 0.0 && b.1 >= 0.0 && (a.0 - b.0).length() < a.1 + b.1
}

/// Height of `x` above a palm patch, `None` outside the patch's radius along the plane.
pub(super) fn patch_height(point: Vec3, normal: Vec3, x: Vec3) -> Option<f32> {
    let r = x - point;
    let h = normal.dot(r);
    (r.length_squared() - h * h < PALM_PATCH_RADIUS * PALM_PATCH_RADIUS).then_some(h)
}

/// Whether a primitive can touch any point of the bound `(centre, radius)`.
pub(super) fn shape_near(shape: Shape, (c, r): (Vec3, f32)) -> bool {
    match shape {
        Shape::Sphere(p, pr) => (p - c).length_squared() < (pr + r) * (pr + r),
        Shape::Plane(p, n, sink) => {
            let d = c - p;
            let h = n.dot(d);
            let t2 = d.length_squared() - h * h;
            let reach = PALM_PATCH_RADIUS + r;
            h < r - sink && h > -PALM_DEPTH - r && t2 < reach * reach
        }
    }
}

/// Penetration depth of `v` into a primitive and the unit direction that pushes it out.
pub(super) fn penetration(shape: Shape, v: Vec3) -> Option<(f32, Vec3)> {
    match shape {
        Shape::Sphere(c, r) => {
            let d = v - c;
            let l2 = d.length_squared();
            if l2 >= r * r {
                return None;
            }
            let l = l2.sqrt();
            let dir = if l > 0.0 { d / l } else { Vec3::Z };
            Some((r - l, dir))
        }
        Shape::Plane(p, n, sink) => {
            let h = patch_height(p, n, v)?;
            (h < -sink && h > -PALM_DEPTH).then_some((-sink - h, n))
        }
    }
}

//! A bone's rigid transform ([`RigidTransform`]) and its unit dual quaternion ([`DualQuat`]),
//! the two forms [`super::BonePalette`] converts every bone into once per frame.

use glam::{Affine3A, Mat4, Quat, Vec3, Vec3A, Vec4};

use super::blend::apply_blended;

/// A rigid bone transform: `x' = rotation * x + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    /// Unit quaternion.
    pub rotation: Quat,
    /// Translation applied after the rotation.
    pub translation: Vec3,
}

impl Default for RigidTransform {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl RigidTransform {
    /// The identity transform.
    pub const IDENTITY: Self = Self {
        rotation: Quat::IDENTITY,
        translation: Vec3::ZERO,
    };

    /// A transform from its parts.
    pub fn new(rotation: Quat, translation: Vec3) -> Self {
        Self {
            rotation,
            translation,
        }
    }

    /// Applies the transform to a point.
    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// Applies only the rotation (for directions and normals).
    #[inline]
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        self.rotation * v
    }

    /// `self ∘ other`: the transform that applies `other` first, then `self`.
    pub fn compose(&self, other: &RigidTransform) -> RigidTransform {
        RigidTransform {
            rotation: self.rotation * other.rotation,
            translation: self.rotation * other.translation + self.translation,
        }
    }

    /// The inverse transform (`x = q⁻¹ (x' - t)`), assuming a unit rotation.
    pub fn inverse(&self) -> RigidTransform {
        let inv = self.rotation.conjugate();
        RigidTransform {
            rotation: inv,
            translation: -(inv * self.translation),
        }
    }

    /// As a SIMD 3x4 affine matrix.
    pub fn to_affine(&self) -> Affine3A {
        Affine3A::from_rotation_translation(self.rotation, self.translation)
    }

    /// As a 4x4 homogeneous matrix.
    pub fn to_mat4(&self) -> Mat4 {
        Mat4::from_rotation_translation(self.rotation, self.translation)
    }

    /// As a unit dual quaternion.
    pub fn to_dual_quat(&self) -> DualQuat {
        DualQuat::from_rigid(self)
    }

    /// Whether every component is finite.
    pub fn is_finite(&self) -> bool {
        self.rotation.is_finite() && self.translation.is_finite()
    }
}

/// A dual quaternion `real + ε dual`. For a rigid transform `(q, t)` the unit dual quaternion
/// is `real = q`, `dual = ½ (t, 0) q` (Kavan et al. 2007, "Skinning with dual quaternions").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DualQuat {
    /// Rotation part.
    pub real: Quat,
    /// Translation part, `½ t q`.
    pub dual: Quat,
}

impl DualQuat {
    /// The unit dual quaternion of a rigid transform with unit rotation.
    pub fn from_rigid(t: &RigidTransform) -> Self {
        let q = t.rotation;
        let qv = Vec3::new(q.x, q.y, q.z);
        let tr = t.translation;
        // (t, 0) ⊗ (qv, qw) = (qw t + t × qv, -t·qv), halved.
        let dv = 0.5 * (q.w * tr + tr.cross(qv));
        let dw = -0.5 * tr.dot(qv);
        DualQuat {
            real: q,
            dual: Quat::from_xyzw(dv.x, dv.y, dv.z, dw),
        }
    }

    /// Applies the transform this dual quaternion represents after normalising it (so a blended,
    /// non-unit dual quaternion may be passed); see `apply_blended`.
    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        Vec3::from(apply_blended(
            Vec4::from(self.real),
            Vec4::from(self.dual),
            Vec3A::from(p),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compose_and_inverse_agree_with_matrices() {
        let a = RigidTransform::new(Quat::from_rotation_y(0.7), Vec3::new(1.0, -2.0, 0.5));
        let b = RigidTransform::new(
            Quat::from_axis_angle(Vec3::new(1.0, 1.0, 0.0).normalize(), -1.1),
            Vec3::new(0.3, 0.2, 4.0),
        );
        let p = Vec3::new(0.4, -0.9, 2.2);
        let ab = a.compose(&b);
        assert!(
            (ab.transform_point(p) - (a.to_mat4() * b.to_mat4()).transform_point3(p)).length()
                < 1e-5
        );
        assert!((a.inverse().transform_point(a.transform_point(p)) - p).length() < 1e-5);
        assert!((a.to_dual_quat().transform_point(p) - a.transform_point(p)).length() < 1e-5);
    }
}

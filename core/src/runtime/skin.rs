//! Linear-blend and dual-quaternion skinning.

use glam::{Quat, Vec3};

/// A rigid bone transform: `x' = rotation * x + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    /// Unit quaternion.
    pub rotation: Quat,
    /// Translation applied after the rotation.
    pub translation: Vec3,
}

impl RigidTransform {
    /// The identity transform.
    pub const IDENTITY: Self = Self { rotation: Quat::IDENTITY, translation: Vec3::ZERO };

    /// Applies the transform to a point.
    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }
}

/// Per-vertex bone influences with a fixed stride `k` (1..=8): vertex `v` owns entries
/// `v*k .. (v+1)*k` of `indices` and `weights`. Unused slots have weight 0 (index 0).
#[derive(Clone, Debug, PartialEq)]
pub struct SkinWeights {
    k: usize,
    indices: Vec<u32>,
    weights: Vec<f32>,
}

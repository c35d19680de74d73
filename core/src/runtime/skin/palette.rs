//! [`BonePalette`]: one frame's bones converted once into what the skinning loops read (SIMD
//! 3x4 matrices for LBS, dual quaternions for DQS, and a zero-padded row table for the packed
//! LBS), in buffers reused from frame to frame.

use glam::{Affine3A, Vec4};

use super::RigidTransform;

/// Per-frame bone data in the form the skinning loops read: one SIMD 3x4 matrix (for LBS), one
/// dual quaternion (for DQS) and the same matrix as three rows (for [`skin_lbs_packed`]) per
/// bone. Keep one per stream and call [`BonePalette::update`] every frame; after the first frame
/// it reuses its buffers.
///
/// [`skin_lbs_packed`]: super::skin_lbs_packed
#[derive(Clone, Debug)]
pub struct BonePalette {
    pub(super) matrices: Vec<Affine3A>,
    pub(super) dual_quats: Vec<[Vec4; 2]>,
    /// Row table of [`skin_lbs_packed`]: entry 0 is all zeros (the bone that padding slots of a
    /// [`PackedSkin`] name), entry `1 + b` holds bone `b`'s rows, and zero entries follow up to
    /// at least [`U8_TABLE_LEN`] entries, so a `u8` index can never leave the table. Invariant,
    /// kept by every constructor and [`BonePalette::update`]: `rows.len() ==
    /// max(U8_TABLE_LEN, matrices.len() + 1)`, every entry past `matrices.len()` zero.
    ///
    /// [`skin_lbs_packed`]: super::skin_lbs_packed
    /// [`PackedSkin`]: super::PackedSkin
    pub(super) rows: Vec<BoneRows>,
}

impl Default for BonePalette {
    fn default() -> Self {
        Self {
            matrices: Vec::new(),
            dual_quats: Vec::new(),
            rows: vec![[Vec4::ZERO; 4]; U8_TABLE_LEN],
        }
    }
}

impl BonePalette {
    /// An empty palette.
    pub fn new() -> Self {
        Self::default()
    }

    /// A palette filled from `bones`.
    pub fn from_transforms(bones: &[RigidTransform]) -> Self {
        let mut p = Self::new();
        p.update(bones);
        p
    }

    /// Refills the palette from `bones`, whose rotations must be unit quaternions. Allocates only
    /// when `bones` is longer than any earlier call's.
    pub fn update(&mut self, bones: &[RigidTransform]) {
        let previous = self.matrices.len();
        self.matrices.clear();
        self.matrices
            .extend(bones.iter().map(RigidTransform::to_affine));
        self.dual_quats.clear();
        self.dual_quats.extend(bones.iter().map(|b| {
            let d = b.to_dual_quat();
            [Vec4::from(d.real), Vec4::from(d.dual)]
        }));
        let n = bones.len();
        if n != previous {
            // Re-zero only when the bone count changes: otherwise entries past n are still zero.
            self.rows.clear();
            self.rows.resize(U8_TABLE_LEN.max(n + 1), [Vec4::ZERO; 4]);
        }
        for (r, m) in self.rows[1..=n].iter_mut().zip(&self.matrices) {
            *r = affine_rows(m);
        }
    }

    /// Number of bones.
    pub fn len(&self) -> usize {
        self.matrices.len()
    }

    /// Whether the palette holds no bones.
    pub fn is_empty(&self) -> bool {
        self.matrices.is_empty()
    }

    /// The LBS matrices, one per bone.
    pub fn matrices(&self) -> &[Affine3A] {
        &self.matrices
    }
}

/// One bone's 3x4 matrix as rows `[m00 m01 m02 t0]`, `[m10 m11 m12 t1]`, `[m20 m21 m22 t2]`,
/// plus an unused zero row that pads the entry to 64 bytes: a `u8` index then becomes a byte
/// offset with one shift (`<< 6`), where a 48-byte stride needs a multiply (`lea` + shift) per
/// influence.
pub(super) type BoneRows = [Vec4; 4];

/// Entries in a [`BonePalette`]'s row table at the least: every `u8` index is in range, so the
/// packed kernel indexes a `&[BoneRows; 256]` with no bounds check.
pub(super) const U8_TABLE_LEN: usize = 256;

/// `m` as rows (see [`BoneRows`]). The entries are moved, not recomputed, so blending rows gives
/// bit for bit the same sums as blending `m`'s columns.
#[inline]
fn affine_rows(m: &Affine3A) -> BoneRows {
    let (x, y, z, t) = (
        m.matrix3.x_axis,
        m.matrix3.y_axis,
        m.matrix3.z_axis,
        m.translation,
    );
    [
        Vec4::new(x.x, y.x, z.x, t.x),
        Vec4::new(x.y, y.y, z.y, t.y),
        Vec4::new(x.z, y.z, z.z, t.z),
        Vec4::ZERO,
    ]
}

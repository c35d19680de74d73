//! Linear-blend and dual-quaternion skinning.
//!
//! A skinned vertex is a blend of its bones' rigid transforms applied to its rest position:
//! - [`skin_lbs`]: linear blend skinning, `p' = (sum_j w_j M_j) p` (Magnenat-Thalmann et al.
//!   1988; the "matrix palette" formulation every GPU skinner uses).
//! - [`skin_dqs`]: dual-quaternion skinning (Kavan, Collins, Zara, O'Sullivan, "Skinning with
//!   dual quaternions", I3D 2007; extended as "Geometric skinning with approximate dual
//!   quaternion blending", TOG 2008), which does not collapse volume at twisting joints the way
//!   LBS does. FKY08 §6.3 skins with it on the GPU.
//!
//! Per frame the caller converts the bones once into a [`BonePalette`] (3x4 matrices and dual
//! quaternions, one per bone, in a buffer it keeps between frames), then skins into its own
//! output buffer. Nothing here allocates per frame. Sizes are checked once per call, never per
//! vertex: [`SkinWeights`] guarantees its own shape at construction.
//!
//! The per-vertex loops are monomorphised over the influence count `k` (1..=8), so the inner
//! loop over influences has a compile-time trip count. With the `parallel` feature the vertices
//! are split into chunks of [`PARALLEL_CHUNK`] processed by rayon; without it the very same kernel
//! runs over all vertices on the calling thread.

use glam::{Affine3A, Mat4, Quat, Vec3, Vec3A, Vec4};

/// Most bone influences per vertex a [`SkinWeights`] may hold (two glTF `JOINTS_n` sets).
pub const MAX_INFLUENCES: usize = 8;

/// How far a vertex's weights may sum from 1. Weights are stored as f32; a set of 8 weights
/// normalised in f32 sums to 1 within a few ulps (~1e-6), so 1e-4 only rejects weights that were
/// never normalised, while tolerating weights written with 5 significant digits.
pub const WEIGHT_SUM_TOLERANCE: f32 = 1e-4;

/// Vertices per rayon task. One vertex costs ~10 ns, so 1024 vertices (~10 µs) outweigh the
/// task overhead (~1 µs) while an 8k-vertex mesh still splits into enough tasks for 8 cores.
pub const PARALLEL_CHUNK: usize = 1024;

/// Errors from building skin weights or from skinning calls with inconsistent sizes.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SkinError {
    /// `k` outside `1..=MAX_INFLUENCES`.
    #[error("influences per vertex k = {k}, must be in 1..={MAX_INFLUENCES}")]
    BadK {
        /// The rejected stride.
        k: usize,
    },
    /// `indices` and `weights` differ in length or are not a multiple of `k` long.
    #[error(
        "skin arrays: {indices} indices and {weights} weights, expected equal lengths that are a \
         multiple of k = {k}"
    )]
    BadLength {
        /// Stride.
        k: usize,
        /// Length of the index array.
        indices: usize,
        /// Length of the weight array.
        weights: usize,
    },
    /// A weight is NaN or infinite.
    #[error("vertex {vertex}: weight slot {slot} is {value}, not finite")]
    NonFiniteWeight {
        /// Vertex index.
        vertex: usize,
        /// Slot within the vertex, `0..k`.
        slot: usize,
        /// The offending weight.
        value: f32,
    },
    /// A weight is negative.
    #[error("vertex {vertex}: weight slot {slot} is {value}, weights must be >= 0")]
    NegativeWeight {
        /// Vertex index.
        vertex: usize,
        /// Slot within the vertex, `0..k`.
        slot: usize,
        /// The offending weight.
        value: f32,
    },
    /// A vertex's weights do not sum to 1.
    #[error("vertex {vertex}: weights sum to {sum}, expected 1 (within {WEIGHT_SUM_TOLERANCE})")]
    WeightSum {
        /// Vertex index.
        vertex: usize,
        /// The sum found.
        sum: f32,
    },
    /// A bone index is not below the bone count.
    #[error("vertex {vertex}: slot {slot} names bone {bone}, but there are {bone_count} bones")]
    BoneOutOfRange {
        /// Vertex index.
        vertex: usize,
        /// Slot within the vertex, `0..k`.
        slot: usize,
        /// The bone index found.
        bone: u32,
        /// Number of bones available.
        bone_count: usize,
    },
    /// A buffer passed to a skinning call has the wrong number of vertices.
    #[error("{what}: {got} vertices, the skin weights have {expected}")]
    VertexCount {
        /// Which buffer ("rest positions", "output").
        what: &'static str,
        /// Vertex count of the skin weights.
        expected: usize,
        /// Length of the buffer.
        got: usize,
    },
}

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

/// Per-vertex bone influences with a fixed stride `k` (1..=8): vertex `v` owns entries
/// `v*k .. (v+1)*k` of `indices` and `weights`, heaviest first. Unused slots have weight 0.
///
/// Invariants, checked by [`SkinWeights::new`] and kept because the fields are private: `k` in
/// `1..=8`, equal array lengths that are a multiple of `k`, weights finite, `>= 0`, summing to 1
/// per vertex within [`WEIGHT_SUM_TOLERANCE`], each vertex's slots in non-increasing weight
/// order.
#[derive(Clone, Debug, PartialEq)]
pub struct SkinWeights {
    k: usize,
    indices: Vec<u32>,
    weights: Vec<f32>,
    /// Largest bone index in `indices` (cached so skinning calls check it in O(1)).
    max_bone: Option<u32>,
}

impl SkinWeights {
    /// Validating constructor; the error names the first offending vertex (and slot, as given).
    ///
    /// Each vertex's slots are then reordered by weight, heaviest first (stable on ties), so
    /// zero-weight padding ends up last and slot 0 is the dual-quaternion pivot.
    pub fn new(k: usize, mut indices: Vec<u32>, mut weights: Vec<f32>) -> Result<Self, SkinError> {
        if !(1..=MAX_INFLUENCES).contains(&k) {
            return Err(SkinError::BadK { k });
        }
        if indices.len() != weights.len() || indices.len() % k != 0 {
            return Err(SkinError::BadLength {
                k,
                indices: indices.len(),
                weights: weights.len(),
            });
        }
        for (vertex, ws) in weights.chunks_exact(k).enumerate() {
            let mut sum = 0.0f32;
            for (slot, &value) in ws.iter().enumerate() {
                if !value.is_finite() {
                    return Err(SkinError::NonFiniteWeight {
                        vertex,
                        slot,
                        value,
                    });
                }
                if value < 0.0 {
                    return Err(SkinError::NegativeWeight {
                        vertex,
                        slot,
                        value,
                    });
                }
                sum += value;
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                return Err(SkinError::WeightSum { vertex, sum });
            }
        }
        for (ii, ww) in indices.chunks_exact_mut(k).zip(weights.chunks_exact_mut(k)) {
            // Insertion sort: k <= 8, and usually already in order.
            for j in 1..k {
                let mut i = j;
                while i > 0 && ww[i] > ww[i - 1] {
                    ww.swap(i, i - 1);
                    ii.swap(i, i - 1);
                    i -= 1;
                }
            }
        }
        let max_bone = indices.iter().copied().max();
        Ok(Self {
            k,
            indices,
            weights,
            max_bone,
        })
    }

    /// Influences per vertex.
    pub fn k(&self) -> usize {
        self.k
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.indices.len() / self.k
    }

    /// The bone indices and weights of vertex `v` (each `k` long). Panics if `v` is out of range.
    pub fn vertex(&self, v: usize) -> (&[u32], &[f32]) {
        let r = v * self.k..(v + 1) * self.k;
        (&self.indices[r.clone()], &self.weights[r])
    }

    /// All bone indices, vertex-major.
    pub fn indices(&self) -> &[u32] {
        &self.indices
    }

    /// All weights, vertex-major.
    pub fn weights(&self) -> &[f32] {
        &self.weights
    }

    /// Iterates over vertices as `(indices, weights)` pairs.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = (&[u32], &[f32])> + '_ {
        self.indices
            .chunks_exact(self.k)
            .zip(self.weights.chunks_exact(self.k))
    }

    /// Largest bone index referenced by any slot (including zero-weight slots); `None` when
    /// there are no vertices.
    pub fn max_bone_index(&self) -> Option<u32> {
        self.max_bone
    }

    /// Checks that every slot (zero-weight ones too: a GPU shader reads them) names a bone below
    /// `bone_count`; the error names the first offending vertex and slot (as stored, heaviest
    /// first).
    pub fn validate_bones(&self, bone_count: usize) -> Result<(), SkinError> {
        if self.max_bone.is_none_or(|m| (m as usize) < bone_count) {
            return Ok(());
        }
        for (i, &bone) in self.indices.iter().enumerate() {
            if bone as usize >= bone_count {
                return Err(SkinError::BoneOutOfRange {
                    vertex: i / self.k,
                    slot: i % self.k,
                    bone,
                    bone_count,
                });
            }
        }
        Ok(())
    }

    /// Checks that `rest` and `out` match the vertex count and the bones fit in the palette.
    fn check_call(&self, rest: usize, out: usize, bones: usize) -> Result<(), SkinError> {
        let expected = self.vertex_count();
        if rest != expected {
            return Err(SkinError::VertexCount {
                what: "rest positions",
                expected,
                got: rest,
            });
        }
        if out != expected {
            return Err(SkinError::VertexCount {
                what: "output",
                expected,
                got: out,
            });
        }
        self.validate_bones(bones)
    }
}

/// Per-frame bone data in the form the skinning loops read: one SIMD 3x4 matrix (for LBS) and
/// one dual quaternion (for DQS) per bone. Keep one per stream and call [`BonePalette::update`]
/// every frame; after the first frame it reuses its buffers.
#[derive(Clone, Debug, Default)]
pub struct BonePalette {
    matrices: Vec<Affine3A>,
    dual_quats: Vec<[Vec4; 2]>,
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
        self.matrices.clear();
        self.matrices
            .extend(bones.iter().map(RigidTransform::to_affine));
        self.dual_quats.clear();
        self.dual_quats.extend(bones.iter().map(|b| {
            let d = b.to_dual_quat();
            [Vec4::from(d.real), Vec4::from(d.dual)]
        }));
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

/// Calls `$run!(K)` with the literal matching a runtime `k` in 1..=8.
macro_rules! dispatch_k {
    ($k:expr, $run:ident) => {
        match $k {
            1 => $run!(1),
            2 => $run!(2),
            3 => $run!(3),
            4 => $run!(4),
            5 => $run!(5),
            6 => $run!(6),
            7 => $run!(7),
            8 => $run!(8),
            other => unreachable!("SkinWeights::new guarantees k in 1..=8, got {other}"),
        }
    };
}

/// Linear blend skinning: `out[v] = sum_j w_vj M_{b_vj} rest[v]`, blending the k 3x4 matrices
/// first and transforming once.
///
/// Errors (checked once, before any vertex is written) when `rest` or `out` do not have
/// `skin.vertex_count()` entries or a bone index is not below `palette.len()`.
pub fn skin_lbs(
    rest: &[Vec3],
    skin: &SkinWeights,
    palette: &BonePalette,
    out: &mut [Vec3],
) -> Result<(), SkinError> {
    skin.check_call(rest.len(), out.len(), palette.len())?;
    let m = palette.matrices.as_slice();
    macro_rules! run {
        ($k:literal) => {
            for_chunks::<$k, _>(rest, skin, out, |r, i, w, o| {
                lbs_kernel::<$k>(m, r, i, w, o)
            })
        };
    }
    dispatch_k!(skin.k(), run);
    Ok(())
}

/// Dual quaternion skinning (Kavan et al. 2007/2008): per vertex, blend the k bones' unit dual
/// quaternions with the vertex's weights, flipping the sign of any whose rotation lies in the
/// opposite hemisphere from the vertex's most-weighted bone (q and -q are the same rotation;
/// blending them unflipped would cancel), normalise, and apply.
///
/// Same size checks as [`skin_lbs`].
pub fn skin_dqs(
    rest: &[Vec3],
    skin: &SkinWeights,
    palette: &BonePalette,
    out: &mut [Vec3],
) -> Result<(), SkinError> {
    skin.check_call(rest.len(), out.len(), palette.len())?;
    let d = palette.dual_quats.as_slice();
    macro_rules! run {
        ($k:literal) => {
            for_chunks::<$k, _>(rest, skin, out, |r, i, w, o| {
                dqs_kernel::<$k>(d, r, i, w, o)
            })
        };
    }
    dispatch_k!(skin.k(), run);
    Ok(())
}

/// Runs `kernel(rest, indices, weights, out)` over all vertices: with the `parallel` feature and
/// more than [`PARALLEL_CHUNK`] vertices, in chunks of that size on the rayon pool; else in one
/// call on this thread.
fn for_chunks<const K: usize, F>(rest: &[Vec3], skin: &SkinWeights, out: &mut [Vec3], kernel: F)
where
    F: Fn(&[Vec3], &[u32], &[f32], &mut [Vec3]) + Sync,
{
    let (idx, w) = (skin.indices(), skin.weights());
    #[cfg(feature = "parallel")]
    if out.len() > PARALLEL_CHUNK {
        use rayon::prelude::*;
        out.par_chunks_mut(PARALLEL_CHUNK)
            .zip(rest.par_chunks(PARALLEL_CHUNK))
            .zip(idx.par_chunks(PARALLEL_CHUNK * K))
            .zip(w.par_chunks(PARALLEL_CHUNK * K))
            .for_each(|(((o, r), i), w)| kernel(r, i, w, o));
        return;
    }
    kernel(rest, idx, w, out);
}

/// LBS over one run of vertices with exactly `K` influences each.
#[inline(always)]
fn lbs_kernel<const K: usize>(
    mats: &[Affine3A],
    rest: &[Vec3],
    idx: &[u32],
    w: &[f32],
    out: &mut [Vec3],
) {
    let influences = idx.chunks_exact(K).zip(w.chunks_exact(K));
    for ((o, &p), (ii, ww)) in out.iter_mut().zip(rest).zip(influences) {
        let (mut cx, mut cy, mut cz, mut ct) = (Vec3A::ZERO, Vec3A::ZERO, Vec3A::ZERO, Vec3A::ZERO);
        for j in 0..K {
            let wj = ww[j];
            // Slots are sorted heaviest first (SkinWeights::new), so the first zero ends the
            // vertex's influences: fitted rigs use far fewer than K on most vertices.
            if wj == 0.0 {
                break;
            }
            let m = &mats[ii[j] as usize];
            cx += m.matrix3.x_axis * wj;
            cy += m.matrix3.y_axis * wj;
            cz += m.matrix3.z_axis * wj;
            ct += m.translation * wj;
        }
        *o = Vec3::from(cx * p.x + cy * p.y + cz * p.z + ct);
    }
}

/// DQS over one run of vertices with exactly `K` influences each.
#[inline(always)]
fn dqs_kernel<const K: usize>(
    dqs: &[[Vec4; 2]],
    rest: &[Vec3],
    idx: &[u32],
    w: &[f32],
    out: &mut [Vec3],
) {
    let influences = idx.chunks_exact(K).zip(w.chunks_exact(K));
    for ((o, &p), (ii, ww)) in out.iter_mut().zip(rest).zip(influences) {
        // Hemisphere reference: the most-weighted bone, slot 0 (SkinWeights keeps slots sorted
        // by weight). Every flipped term then has a non-negative dot product with it, so
        // |blend| >= its weight >= 1/k.
        let qp = dqs[ii[0] as usize][0];
        let (mut br, mut bd) = (Vec4::ZERO, Vec4::ZERO);
        for j in 0..K {
            let [r, d] = dqs[ii[j] as usize];
            // q and -q are one rotation: take the sign that agrees with the pivot.
            let s = ww[j].copysign(r.dot(qp));
            br += r * s;
            bd += d * s;
        }
        *o = Vec3::from(apply_blended(br, bd, Vec3A::from(p)));
    }
}

/// Normalises the blended dual quaternion `(br, bd)` by `|br|` and applies it to `p`:
/// `p' = p + 2 r × (r × p + w p) + 2 (w dv − dw r + r × dv)` with `(r, w)` the unit real part
/// and `(dv, dw)` the scaled dual part (Kavan et al. 2008, TOG: the vertex transform by a
/// normalised dual-quaternion blend). This form does not need the dual part to be orthogonal to
/// the real part, which a blend generally breaks.
///
/// With valid weights and the hemisphere fix, `|br| >= max weight >= 1/k`, so the division is
/// safe.
#[inline(always)]
fn apply_blended(br: Vec4, bd: Vec4, p: Vec3A) -> Vec3A {
    let inv = br.length_recip();
    let (br, bd) = (br * inv, bd * inv);
    let r = Vec3A::from_vec4(br);
    let w = br.w;
    let dv = Vec3A::from_vec4(bd);
    let dw = bd.w;
    let rot = p + 2.0 * r.cross(r.cross(p) + w * p);
    rot + 2.0 * (w * dv - dw * r + r.cross(dv))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn new_rejects_bad_shapes() {
        assert_eq!(
            SkinWeights::new(0, vec![], vec![]),
            Err(SkinError::BadK { k: 0 })
        );
        assert_eq!(
            SkinWeights::new(9, vec![], vec![]),
            Err(SkinError::BadK { k: 9 })
        );
        assert!(matches!(
            SkinWeights::new(2, vec![0, 1, 2], vec![0.5, 0.5, 1.0]),
            Err(SkinError::BadLength { .. })
        ));
        assert!(matches!(
            SkinWeights::new(2, vec![0, 1], vec![0.5, 0.25, 0.25, 0.0]),
            Err(SkinError::BadLength { .. })
        ));
    }

    #[test]
    fn zero_weight_slots_and_empty_are_fine() {
        let s = SkinWeights::new(4, vec![3, 0, 0, 0], vec![1.0, 0.0, 0.0, 0.0]).unwrap();
        assert_eq!(s.vertex_count(), 1);
        assert_eq!(s.max_bone_index(), Some(3));
        assert!(s.validate_bones(4).is_ok());
        let e = SkinWeights::new(4, vec![], vec![]).unwrap();
        assert_eq!(e.vertex_count(), 0);
        assert_eq!(e.max_bone_index(), None);
        assert!(e.validate_bones(0).is_ok());
    }

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

    #[test]
    fn skinning_checks_sizes_before_writing() {
        let s = SkinWeights::new(1, vec![0, 1], vec![1.0, 1.0]).unwrap();
        let rest = [Vec3::ONE; 2];
        let mut out = [Vec3::ZERO; 2];
        let one = BonePalette::from_transforms(&[RigidTransform::IDENTITY]);
        assert!(matches!(
            skin_lbs(&rest, &s, &one, &mut out),
            Err(SkinError::BoneOutOfRange {
                vertex: 1,
                slot: 0,
                bone: 1,
                bone_count: 1
            })
        ));
        assert_eq!(out, [Vec3::ZERO; 2]);
        let two = BonePalette::from_transforms(&[RigidTransform::IDENTITY; 2]);
        assert!(matches!(
            skin_dqs(&rest[..1], &s, &two, &mut out),
            Err(SkinError::VertexCount {
                what: "rest positions",
                expected: 2,
                got: 1
            })
        ));
        assert!(matches!(
            skin_lbs(&rest, &s, &two, &mut out[..1]),
            Err(SkinError::VertexCount { what: "output", .. })
        ));
    }
}

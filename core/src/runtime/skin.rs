//! Linear-blend and dual-quaternion skinning.
//!
//! A skinned vertex is a blend of its bones' rigid transforms applied to its rest position:
//! - [`skin_lbs`]: linear blend skinning, `p' = (sum_j w_j M_j) p` (Magnenat-Thalmann et al.
//!   1988; the "matrix palette" formulation every GPU skinner uses).
//! - [`skin_lbs_packed`]: the same LBS, bit for bit, on a [`PackedSkin`] (the weights rearranged
//!   once: non-zero influences only, narrow indices, four vertices blended side by side); ~1.35x
//!   faster than [`skin_lbs`] on the horse. The per-frame path ([`super::predictor`]) uses it;
//!   [`skin_lbs`] stays for one-off calls and as its reference.
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
//! are split into chunks of [`PARALLEL_CHUNK`] processed by rayon (when the pool has more than
//! one thread); without it the very same kernel runs over all vertices on the calling thread.

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
    /// A bone index too large for [`PackedSkin`]'s 16-bit indices.
    #[error(
        "vertex {vertex}: slot {slot} names bone {bone}; packed skins hold bones below {PACKED_MAX_BONES}"
    )]
    TooManyBones {
        /// Vertex index.
        vertex: usize,
        /// Slot within the vertex, `0..k`.
        slot: usize,
        /// The bone index found.
        bone: u32,
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
        if indices.len() != weights.len() || !indices.len().is_multiple_of(k) {
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

/// Per-frame bone data in the form the skinning loops read: one SIMD 3x4 matrix (for LBS), one
/// dual quaternion (for DQS) and the same matrix as three rows (for [`skin_lbs_packed`]) per
/// bone. Keep one per stream and call [`BonePalette::update`] every frame; after the first frame
/// it reuses its buffers.
#[derive(Clone, Debug)]
pub struct BonePalette {
    matrices: Vec<Affine3A>,
    dual_quats: Vec<[Vec4; 2]>,
    /// Row table of [`skin_lbs_packed`]: entry 0 is all zeros (the bone that padding slots of a
    /// [`PackedSkin`] name), entry `1 + b` holds bone `b`'s rows, and zero entries follow up to
    /// at least [`U8_TABLE_LEN`] entries, so a `u8` index can never leave the table. Invariant,
    /// kept by every constructor and [`BonePalette::update`]: `rows.len() ==
    /// max(U8_TABLE_LEN, matrices.len() + 1)`, every entry past `matrices.len()` zero.
    rows: Vec<BoneRows>,
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
type BoneRows = [Vec4; 4];

/// Entries in a [`BonePalette`]'s row table at the least: every `u8` index is in range, so the
/// packed kernel indexes a `&[BoneRows; 256]` with no bounds check.
const U8_TABLE_LEN: usize = 256;

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

/// Vertices a [`PackedSkin`] blends side by side. Each vertex's blend is a chain of dependent
/// adds (3 cycles each on current x86 cores); interleaving four independent vertices keeps the
/// FP units busy. Four lanes x three row accumulators is 12 of the 16 SSE registers; with more
/// lanes the accumulators spill.
const LANES: usize = 4;

/// Most bones a [`PackedSkin`] can name: its indices are `u16` holding `bone + 1`.
pub const PACKED_MAX_BONES: usize = u16::MAX as usize;

/// Bones up to which a [`PackedSkin`] stores `u8` indices (`bone + 1 <= 255`), the form whose
/// palette lookups need no bounds check (see [`U8_TABLE_LEN`]).
const U8_MAX_BONES: usize = u8::MAX as usize;

// Parallel chunks must start on a block boundary.
const _: () = assert!(PARALLEL_CHUNK.is_multiple_of(LANES));

/// One influence slot of a block of [`LANES`] consecutive vertices: the weight and the bone-row
/// index (`bone + 1`; 0 names the zero row) of each vertex. 20 bytes with `u8` indices.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Slot<I> {
    weights: [f32; LANES],
    rows: [I; LANES],
}

/// The bone-row indices of a [`PackedSkin`], in the narrowest type that holds them.
#[derive(Clone, Debug, PartialEq)]
enum PackedSlots {
    /// At most [`U8_MAX_BONES`] bones: lookups in a `[BoneRows; 256]`, unchecked by construction.
    U8(Vec<Slot<u8>>),
    /// Up to [`PACKED_MAX_BONES`] bones: checked lookups.
    U16(Vec<Slot<u16>>),
}

/// [`SkinWeights`] rearranged once for fast per-frame LBS with [`skin_lbs_packed`]; the result
/// is bit for bit that of [`skin_lbs`].
///
/// Why this layout. On the horse (8,431 vertices, k = 8, 150 bones, one core) LBS is bound by
/// the core's instruction throughput, not by memory: `skin_lbs` spends ~17 instructions per
/// influence (4 column loads, 4 multiplies, 4 adds, a broadcast, a bounds check, the zero-weight
/// test) and runs at ~5x the time of a memcpy of the bytes it touches; the same loop over 1,000
/// vertices that sit in L1 costs the same per vertex. So the packed form cuts instructions per
/// influence (to ~12.75) rather than bytes:
/// - **Rows, not columns.** The palette keeps each bone as three `[m_r0 m_r1 m_r2 t_r]` rows;
///   blending them is 3 multiplies + 3 adds per influence instead of 4 + 4 (all four SIMD lanes
///   carry data). The point is applied once per vertex: each row times `(x, y, z, 1)`, four
///   vertices' products transposed and summed in `skin_lbs`'s order `((x + y) + z) + t`.
/// - **Only the non-zero influences**, so no per-slot weight test. Vertices are grouped in blocks
///   of four consecutive vertices blended side by side, which overlaps their dependent add
///   chains; a block has as many slots as its most-influenced vertex, shorter vertices padded
///   with weight 0 on an all-zero row (`acc + 0 * 0 == acc` exactly: the accumulators start at
///   +0 and never become -0, so padding changes no bit). The fitted horse rig pads 3% of slots.
/// - **Narrow indices, no bounds checks.** Row indices are `u8` when the bones fit (bone + 1,
///   0 being the zero row): the palette's row table has 256 entries of 64 bytes, so no `u8` can
///   leave it and the address is one shift. More bones fall back to `u16` with checked lookups.
///   Indices are checked against the palette once per call ([`skin_lbs_packed`]).
///
/// Bytes per influence: 5 (`u8` index + `f32` weight) instead of 8.
///
/// Measured per frame, palette update included, one thread (`cargo bench --bench lbs`): 104 µs
/// for `skin_lbs`, 78 µs packed. Steps on the way (a standalone harness, synthetic k = 8, time
/// relative to `skin_lbs`): non-zero influences only, rows, `u8` indices, one vertex at a time
/// 0.88; blocks of four vertices 0.81 (of two or three: 0.83); 64-byte rows 0.79; the
/// transposed finish 0.75.
///
/// Tried and dropped: weights stored pre-broadcast (`[Vec4; 4]` per slot: 4% faster for 3.4x the
/// bytes); weights pre-multiplied into the rest point (saves the broadcast and the finish
/// multiplies but rounds differently from `skin_lbs`).
#[derive(Clone, Debug, PartialEq)]
pub struct PackedSkin {
    vertex_count: usize,
    /// Largest bone named by a non-zero weight; `None` when no vertices.
    max_bone: Option<u32>,
    /// Block `b` (vertices `LANES*b ..`) owns slots `offsets[b]..offsets[b + 1]`; one entry per
    /// block plus one.
    offsets: Vec<u32>,
    slots: PackedSlots,
}

impl PackedSkin {
    /// Packs `skin`, keeping only its non-zero weights (slots after a vertex's first zero weight
    /// never contribute: [`SkinWeights`] sorts them heaviest first).
    ///
    /// Fails with [`SkinError::TooManyBones`] when a non-zero weight names a bone
    /// `>= PACKED_MAX_BONES`. Zero-weight slots are dropped, so their bone indices are not checked
    /// here nor by [`skin_lbs_packed`] (unlike [`skin_lbs`], which checks every slot).
    pub fn new(skin: &SkinWeights) -> Result<Self, SkinError> {
        let mut max_bone = None;
        for (vertex, (ii, ww)) in skin.iter().enumerate() {
            for (slot, (&bone, &w)) in ii.iter().zip(ww).enumerate() {
                if w == 0.0 {
                    break;
                }
                if bone as usize >= PACKED_MAX_BONES {
                    return Err(SkinError::TooManyBones { vertex, slot, bone });
                }
                max_bone = max_bone.max(Some(bone));
            }
        }
        let narrow = max_bone.is_none_or(|m| (m as usize) < U8_MAX_BONES);
        let (offsets, slots) = if narrow {
            let (o, s) = pack_slots(skin, |b| b as u8);
            (o, PackedSlots::U8(s))
        } else {
            let (o, s) = pack_slots(skin, |b| b as u16);
            (o, PackedSlots::U16(s))
        };
        Ok(Self {
            vertex_count: skin.vertex_count(),
            max_bone,
            offsets,
            slots,
        })
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    /// Largest bone index named by a non-zero weight; `None` when there are no vertices.
    pub fn max_bone_index(&self) -> Option<u32> {
        self.max_bone
    }

    /// Whether row indices are stored as `u8` (at most 255 bones), the unchecked fast form.
    pub fn has_narrow_indices(&self) -> bool {
        matches!(self.slots, PackedSlots::U8(_))
    }

    /// Influence slots stored, padding included (`LANES` influences each): for diagnostics.
    pub fn slot_count(&self) -> usize {
        match &self.slots {
            PackedSlots::U8(s) => s.len() * LANES,
            PackedSlots::U16(s) => s.len() * LANES,
        }
    }

    /// The first `(vertex, slot, bone)` whose non-zero weight names a bone `>= bone_count`
    /// (error path only: walks the whole skin).
    fn first_bone_at_least(&self, bone_count: usize) -> Option<(usize, usize, u32)> {
        fn find<I: Copy + Into<u32>>(
            offsets: &[u32],
            slots: &[Slot<I>],
            bone_count: usize,
        ) -> Option<(usize, usize, u32)> {
            for (b, off) in offsets.windows(2).enumerate() {
                // Within a block, vertex order first (the error names the first vertex).
                let block = &slots[off[0] as usize..off[1] as usize];
                for lane in 0..LANES {
                    for (slot, s) in block.iter().enumerate() {
                        let row: u32 = s.rows[lane].into();
                        if row > 0 && (row - 1) as usize >= bone_count {
                            return Some((b * LANES + lane, slot, row - 1));
                        }
                    }
                }
            }
            None
        }
        match &self.slots {
            PackedSlots::U8(s) => find(&self.offsets, s, bone_count),
            PackedSlots::U16(s) => find(&self.offsets, s, bone_count),
        }
    }
}

/// Lays out `skin`'s non-zero influences in blocks of [`LANES`] vertices (see [`PackedSkin`]),
/// storing `bone + 1` through `narrow`, which the caller has checked cannot truncate.
fn pack_slots<I: Copy + Default>(
    skin: &SkinWeights,
    narrow: impl Fn(u32) -> I,
) -> (Vec<u32>, Vec<Slot<I>>) {
    let n = skin.vertex_count();
    let blocks = n.div_ceil(LANES);
    let mut offsets = Vec::with_capacity(blocks + 1);
    let mut slots = Vec::new();
    offsets.push(0);
    for b in 0..blocks {
        // Each vertex's non-zero prefix; missing lanes of a partial last block have none.
        let used: [(&[u32], &[f32]); LANES] = std::array::from_fn(|lane| {
            let v = b * LANES + lane;
            if v >= n {
                return (&[][..], &[][..]);
            }
            let (ii, ww) = skin.vertex(v);
            let len = ww.iter().take_while(|&&w| w != 0.0).count();
            (&ii[..len], &ww[..len])
        });
        let depth = used.iter().map(|(ii, _)| ii.len()).max().unwrap_or(0);
        for j in 0..depth {
            let mut slot = Slot {
                weights: [0.0; LANES],
                rows: [I::default(); LANES],
            };
            for (lane, (ii, ww)) in used.iter().enumerate() {
                if let (Some(&bone), Some(&w)) = (ii.get(j), ww.get(j)) {
                    slot.weights[lane] = w;
                    slot.rows[lane] = narrow(bone + 1);
                }
            }
            slots.push(slot);
        }
        offsets.push(u32::try_from(slots.len()).expect("fewer than 2^32 slots"));
    }
    (offsets, slots)
}

/// A table of bone rows indexed by a packed row index.
trait RowTable<I> {
    fn row(&self, i: I) -> &BoneRows;
}

impl RowTable<u8> for [BoneRows; U8_TABLE_LEN] {
    #[inline(always)]
    fn row(&self, i: u8) -> &BoneRows {
        // In range for every u8: no bounds check is emitted.
        &self[usize::from(i)]
    }
}

impl RowTable<u16> for [BoneRows] {
    #[inline(always)]
    fn row(&self, i: u16) -> &BoneRows {
        &self[usize::from(i)]
    }
}

/// Linear blend skinning with a [`PackedSkin`]: the same `out[v] = (sum_j w_vj M_{b_vj})
/// rest[v]` as [`skin_lbs`], bit for bit, in a fraction of the time (see [`PackedSkin`]).
///
/// Errors (checked once, before any vertex is written) when `rest` or `out` do not have
/// `skin.vertex_count()` entries or a bone with non-zero weight is not below `palette.len()`.
pub fn skin_lbs_packed(
    rest: &[Vec3],
    skin: &PackedSkin,
    palette: &BonePalette,
    out: &mut [Vec3],
) -> Result<(), SkinError> {
    let expected = skin.vertex_count;
    for (what, got) in [("rest positions", rest.len()), ("output", out.len())] {
        if got != expected {
            return Err(SkinError::VertexCount {
                what,
                expected,
                got,
            });
        }
    }
    let bone_count = palette.len();
    if skin.max_bone.is_some_and(|m| m as usize >= bone_count) {
        let (vertex, slot, bone) = skin
            .first_bone_at_least(bone_count)
            .expect("max_bone is named by some slot");
        return Err(SkinError::BoneOutOfRange {
            vertex,
            slot,
            bone,
            bone_count,
        });
    }
    match &skin.slots {
        PackedSlots::U8(slots) => {
            let table: &[BoneRows; U8_TABLE_LEN] = palette.rows[..U8_TABLE_LEN]
                .try_into()
                .expect("BonePalette keeps at least U8_TABLE_LEN rows");
            packed_chunks(table, &skin.offsets, slots, rest, out);
        }
        PackedSlots::U16(slots) => {
            packed_chunks(palette.rows.as_slice(), &skin.offsets, slots, rest, out);
        }
    }
    Ok(())
}

/// Runs [`packed_kernel`] over all vertices: with the `parallel` feature and more than
/// [`PARALLEL_CHUNK`] vertices, in chunks of that size on the rayon pool; else on this thread.
fn packed_chunks<I, T>(
    table: &T,
    offsets: &[u32],
    slots: &[Slot<I>],
    rest: &[Vec3],
    out: &mut [Vec3],
) where
    I: Copy + Sync,
    T: RowTable<I> + Sync + ?Sized,
{
    #[cfg(feature = "parallel")]
    if super::use_pool(out.len(), PARALLEL_CHUNK) {
        use rayon::prelude::*;
        const BLOCKS: usize = PARALLEL_CHUNK / LANES;
        out.par_chunks_mut(PARALLEL_CHUNK)
            .zip(rest.par_chunks(PARALLEL_CHUNK))
            .enumerate()
            .for_each(|(c, (o, r))| {
                let first = c * BLOCKS;
                let blocks = &offsets[first..=first + o.len().div_ceil(LANES)];
                packed_kernel(table, blocks, slots, r, o)
            });
        return;
    }
    packed_kernel(table, offsets, slots, rest, out);
}

/// Packed LBS over a run of whole blocks (the last may be partial): `offsets` has one entry per
/// block plus one, indexing into the whole `slots`.
#[inline(always)]
fn packed_kernel<I: Copy, T: RowTable<I> + ?Sized>(
    table: &T,
    offsets: &[u32],
    slots: &[Slot<I>],
    rest: &[Vec3],
    out: &mut [Vec3],
) {
    let mut outs = out.chunks_exact_mut(LANES);
    let mut rests = rest.chunks_exact(LANES);
    for ((o, r), off) in (&mut outs).zip(&mut rests).zip(offsets.windows(2)) {
        let block = &slots[off[0] as usize..off[1] as usize];
        let o: &mut [Vec3; LANES] = o.try_into().expect("chunks_exact_mut yields LANES");
        let r: &[Vec3; LANES] = r.try_into().expect("chunks_exact yields LANES");
        blend_block(table, block, r, o);
    }
    let (o, r) = (outs.into_remainder(), rests.remainder());
    if !o.is_empty() {
        // The last, partial block: its missing lanes are padding (zero rows), computed and
        // dropped.
        let b = offsets.len() - 2;
        let block = &slots[offsets[b] as usize..offsets[b + 1] as usize];
        let mut rr = [Vec3::ZERO; LANES];
        rr[..r.len()].copy_from_slice(r);
        let mut oo = [Vec3::ZERO; LANES];
        blend_block(table, block, &rr, &mut oo);
        o.copy_from_slice(&oo[..o.len()]);
    }
}

/// LBS of one block of [`LANES`] vertices.
#[inline(always)]
fn blend_block<I: Copy, T: RowTable<I> + ?Sized>(
    table: &T,
    block: &[Slot<I>],
    rest: &[Vec3; LANES],
    out: &mut [Vec3; LANES],
) {
    // acc[lane] = sum_j w_j rows(M_j), in slot order (skin_lbs's order: bit-identical sums).
    let mut acc = [[Vec4::ZERO; 3]; LANES];
    for s in block {
        for (a, (&w, &i)) in acc.iter_mut().zip(s.weights.iter().zip(&s.rows)) {
            let m = table.row(i);
            a[0] += m[0] * w;
            a[1] += m[1] * w;
            a[2] += m[2] * w;
        }
    }
    // Row r of lane l times (x, y, z, 1): the four terms of output coordinate r, which
    // skin_lbs sums as ((x term + y term) + z term) + t. Transposing four such products puts
    // the terms of four coordinates in four registers; adding those in order gives the same
    // sums, four coordinates at a time, written as the block's 12 contiguous floats.
    let p: [Vec4; LANES] = std::array::from_fn(|l| rest[l].extend(1.0));
    let terms: [Vec4; 3 * LANES] = std::array::from_fn(|i| acc[i / 3][i % 3] * p[i / 3]);
    let flat: &mut [f32] = bytemuck::cast_slice_mut(out.as_mut_slice());
    for (dst, t) in flat.chunks_exact_mut(4).zip(terms.chunks_exact(4)) {
        let t = Mat4::from_cols(t[0], t[1], t[2], t[3]).transpose();
        (t.x_axis + t.y_axis + t.z_axis + t.w_axis).write_to_slice(dst);
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
    if super::use_pool(out.len(), PARALLEL_CHUNK) {
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

    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// `n` vertices with `k` slots on bones `0..bones` (repeats allowed), about one weight in
    /// four zero (padding after sorting), normalised.
    fn random_skin(rng: &mut StdRng, n: usize, k: usize, bones: u32) -> SkinWeights {
        let mut indices = Vec::with_capacity(n * k);
        let mut weights = Vec::with_capacity(n * k);
        for _ in 0..n {
            let mut w: Vec<f32> = (0..k)
                .map(|_| {
                    if rng.random_range(0..4) == 0 {
                        0.0
                    } else {
                        rng.random::<f32>() + 1e-3
                    }
                })
                .collect();
            if w.iter().all(|&x| x == 0.0) {
                w[rng.random_range(0..k)] = 1.0;
            }
            let sum: f32 = w.iter().sum();
            weights.extend(w.iter().map(|x| x / sum));
            indices.extend((0..k).map(|_| rng.random_range(0..bones)));
        }
        SkinWeights::new(k, indices, weights).unwrap()
    }

    fn random_bones(rng: &mut StdRng, n: usize) -> Vec<RigidTransform> {
        (0..n)
            .map(|_| {
                let axis = Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(0.1..1.0),
                );
                RigidTransform::new(
                    Quat::from_axis_angle(axis.normalize(), rng.random_range(-3.0..3.0)),
                    Vec3::new(
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-2.0..2.0),
                        rng.random_range(-2.0..2.0),
                    ),
                )
            })
            .collect()
    }

    fn random_points(rng: &mut StdRng, n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                    rng.random_range(-3.0..3.0),
                )
            })
            .collect()
    }

    fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
        v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
    }

    /// Packed and reference LBS on the same inputs; asserts bit-identical output.
    fn assert_packed_matches(rest: &[Vec3], skin: &SkinWeights, palette: &BonePalette) {
        let packed = PackedSkin::new(skin).unwrap();
        let mut expected = vec![Vec3::NAN; rest.len()];
        skin_lbs(rest, skin, palette, &mut expected).unwrap();
        let mut got = vec![Vec3::NAN; rest.len()];
        skin_lbs_packed(rest, &packed, palette, &mut got).unwrap();
        assert_eq!(
            bits(&got),
            bits(&expected),
            "k = {}, n = {}",
            skin.k(),
            rest.len()
        );
    }

    #[test]
    fn packed_lbs_equals_reference_bit_for_bit() {
        let mut rng = StdRng::seed_from_u64(7);
        let bones = random_bones(&mut rng, 150);
        let palette = BonePalette::from_transforms(&bones);
        // Vertex counts around the block size (4) and the parallel chunk (1024), none a
        // multiple of both.
        for n in [0, 1, 2, 3, 5, 7, 13, 1021, 1025, 2 * PARALLEL_CHUNK + 3] {
            for k in 1..=MAX_INFLUENCES {
                let skin = random_skin(&mut rng, n, k, 150);
                let rest = random_points(&mut rng, n);
                let packed = PackedSkin::new(&skin).unwrap();
                assert!(packed.has_narrow_indices());
                assert_packed_matches(&rest, &skin, &palette);
            }
        }
    }

    #[test]
    fn packed_lbs_wide_indices_and_the_u8_boundary() {
        let mut rng = StdRng::seed_from_u64(8);
        let bones = random_bones(&mut rng, 600);
        let palette = BonePalette::from_transforms(&bones);
        let rest = random_points(&mut rng, 1031);
        for (bone_count, narrow) in [(255, true), (256, false), (600, false)] {
            let mut skin = random_skin(&mut rng, rest.len(), 5, bone_count);
            // Make sure the largest bone is used with a non-zero weight.
            let (mut ii, ww) = (skin.indices().to_vec(), skin.weights().to_vec());
            ii[0] = bone_count - 1;
            skin = SkinWeights::new(5, ii, ww).unwrap();
            let packed = PackedSkin::new(&skin).unwrap();
            assert_eq!(packed.max_bone_index(), Some(bone_count - 1));
            assert_eq!(packed.has_narrow_indices(), narrow, "{bone_count} bones");
            assert_packed_matches(&rest, &skin, &palette);
        }
    }

    #[test]
    fn packed_lbs_drops_zero_weight_slots() {
        // Vertex 0 uses bone 0 only; its zero-weight slots name bone 1, whose matrix is NaN.
        // skin_lbs never reads zero-weight slots; neither may the packed form.
        let skin = SkinWeights::new(
            3,
            vec![0, 1, 1, 1, 0, 1],
            vec![1.0, 0.0, 0.0, 0.5, 0.5, 0.0],
        )
        .unwrap();
        let packed = PackedSkin::new(&skin).unwrap();
        assert_eq!(packed.slot_count(), 2 * LANES);
        let nan = RigidTransform::new(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0), Vec3::ZERO);
        let palette = BonePalette::from_transforms(&[
            RigidTransform::new(Quat::from_rotation_z(0.5), Vec3::X),
            nan,
        ]);
        let rest = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 2.0)];
        let mut out = [Vec3::ZERO; 2];
        skin_lbs_packed(&rest, &packed, &palette, &mut out).unwrap();
        assert!(out[0].is_finite());
        assert!(out[1].is_nan());
        assert_packed_matches(&rest, &skin, &palette);
    }

    #[test]
    fn packed_lbs_palette_reused_across_bone_counts() {
        // The row table's zero padding must survive palettes that shrink and grow.
        let mut rng = StdRng::seed_from_u64(9);
        let rest = random_points(&mut rng, 77);
        let skin = random_skin(&mut rng, rest.len(), 4, 40);
        let mut palette = BonePalette::new();
        for n in [300, 40, 41, 255, 40, 0, 40] {
            palette.update(&random_bones(&mut rng, n));
            assert_eq!(palette.rows.len(), U8_TABLE_LEN.max(n + 1));
            assert!(palette.rows[n + 1..].iter().all(|r| *r == [Vec4::ZERO; 4]));
            assert!(palette.rows[0] == [Vec4::ZERO; 4]);
            if n >= 40 {
                assert_packed_matches(&rest, &skin, &palette);
            }
        }
    }

    #[test]
    fn packing_rejects_bones_beyond_u16() {
        let big = PACKED_MAX_BONES as u32;
        let bad = SkinWeights::new(2, vec![0, 1, big, 0], vec![1.0, 0.0, 0.75, 0.25]).unwrap();
        assert_eq!(
            PackedSkin::new(&bad),
            Err(SkinError::TooManyBones {
                vertex: 1,
                slot: 0,
                bone: big
            })
        );
        // The same bone on a zero-weight slot is dropped, not rejected.
        let fine = SkinWeights::new(2, vec![0, big, 3, 0], vec![1.0, 0.0, 0.75, 0.25]).unwrap();
        let packed = PackedSkin::new(&fine).unwrap();
        assert_eq!(packed.max_bone_index(), Some(3));
        let just_fits = SkinWeights::new(1, vec![big - 1], vec![1.0]).unwrap();
        assert!(!PackedSkin::new(&just_fits).unwrap().has_narrow_indices());
    }

    #[test]
    fn packed_lbs_checks_sizes_before_writing() {
        // Vertex 6 (block 1, lane 2) names bone 2 in slot 1.
        let mut ii = vec![0u32; 8 * 2];
        let mut ww = vec![0.0f32; 8 * 2];
        for v in 0..8 {
            ii[2 * v] = 1;
            ww[2 * v] = 1.0;
        }
        ii[2 * 6 + 1] = 2;
        (ww[2 * 6], ww[2 * 6 + 1]) = (0.5, 0.5);
        // A zero-weight slot naming bone 7: skin_lbs rejects it, the packed form ignores it.
        ii[2 * 3 + 1] = 7;
        let skin = SkinWeights::new(2, ii, ww).unwrap();
        let packed = PackedSkin::new(&skin).unwrap();
        assert_eq!(packed.vertex_count(), 8);
        assert_eq!(packed.max_bone_index(), Some(2));
        let rest = [Vec3::ONE; 8];
        let mut out = [Vec3::ZERO; 8];
        let two = BonePalette::from_transforms(&[RigidTransform::IDENTITY; 2]);
        assert_eq!(
            skin_lbs_packed(&rest, &packed, &two, &mut out),
            Err(SkinError::BoneOutOfRange {
                vertex: 6,
                slot: 1,
                bone: 2,
                bone_count: 2
            })
        );
        assert_eq!(out, [Vec3::ZERO; 8]);
        assert!(matches!(
            skin_lbs_packed(&rest, &packed, &BonePalette::new(), &mut out),
            Err(SkinError::BoneOutOfRange {
                vertex: 0,
                slot: 0,
                bone: 1,
                bone_count: 0
            })
        ));
        let three = BonePalette::from_transforms(&[RigidTransform::IDENTITY; 3]);
        assert!(matches!(
            skin_lbs_packed(&rest[..7], &packed, &three, &mut out),
            Err(SkinError::VertexCount {
                what: "rest positions",
                expected: 8,
                got: 7
            })
        ));
        assert!(matches!(
            skin_lbs_packed(&rest, &packed, &three, &mut out[..3]),
            Err(SkinError::VertexCount { what: "output", .. })
        ));
        assert_eq!(out, [Vec3::ZERO; 8]);
        skin_lbs_packed(&rest, &packed, &three, &mut out).unwrap();
        assert_eq!(out, [Vec3::ONE; 8]);
        // An empty skin skins nothing, even with an empty palette.
        let empty = PackedSkin::new(&SkinWeights::new(4, vec![], vec![]).unwrap()).unwrap();
        assert_eq!(empty.max_bone_index(), None);
        skin_lbs_packed(&[], &empty, &BonePalette::new(), &mut []).unwrap();
    }
}

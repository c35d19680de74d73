//! Linear-blend and dual-quaternion skinning.
//!
//! A skinned vertex is a blend of its bones' rigid transforms applied to its rest position:
//! - [`skin_lbs`]: linear blend skinning, `p' = (sum_j w_j M_j) p` (Magnenat-Thalmann et al.
//!   1988; the "matrix palette" formulation every GPU skinner uses).
//! - [`skin_lbs_packed`]: the same LBS on a [`PackedSkin`] (the weights rearranged once:
//!   non-zero influences only, narrow indices, four vertices blended side by side); ~1.35x
//!   faster than [`skin_lbs`] on the horse and bit for bit with the portable kernel, ~1.9x with
//!   AVX2 + FMA where the CPU has them and within a few ulps ([`PackedKernel`]). The
//!   per-frame path ([`crate::predictor`]) uses it; [`skin_lbs`] stays for one-off calls and as
//!   its reference.
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
//!
//! Layout:
//! - `transform`: [`RigidTransform`] (a bone's rotation and translation) and [`DualQuat`].
//! - `weights`: [`SkinWeights`], the validated per-vertex influences (fixed stride `k`).
//! - `palette`: [`BonePalette`], the per-frame bone data in the forms the loops read.
//! - `blend`: [`skin_lbs`] and [`skin_dqs`] over [`SkinWeights`], and the chunking they share.
//! - `packed`: [`PackedSkin`] and [`skin_lbs_packed`], the per-frame LBS path.
//!
//! [`Skinning`] names the choice between the two (a model's default, a room's override).

mod blend;
mod packed;
mod palette;
mod transform;
mod weights;

pub use blend::{skin_dqs, skin_lbs};
pub use packed::{
    PACKED_MAX_BONES, PackedKernel, PackedSkin, skin_lbs_packed, skin_lbs_packed_with,
};
pub use palette::BonePalette;
pub use transform::{DualQuat, RigidTransform};
pub use weights::SkinWeights;

/// Which skinning turns the bone transforms into vertices: a model's default (stored in its
/// file) and a room's choice (issue 22).
///
/// LBS is what the bones were fitted for (SSDR minimises the LBS error of the examples) and
/// what a palette stream's client runs on its GPU; DQS (Kavan et al. 2007, FKY08 §6.3) keeps
/// the volume at twisting joints that LBS collapses ("candy wrapper").
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Skinning {
    /// Linear blend skinning ([`skin_lbs`], [`skin_lbs_packed`]): the default.
    #[default]
    Lbs,
    /// Dual-quaternion skinning ([`skin_dqs`]).
    Dqs,
}

impl Skinning {
    /// Both, LBS first.
    pub const ALL: [Skinning; 2] = [Skinning::Lbs, Skinning::Dqs];

    /// The name a command line and a model file spell: `lbs` or `dqs`.
    pub fn name(self) -> &'static str {
        match self {
            Skinning::Lbs => "lbs",
            Skinning::Dqs => "dqs",
        }
    }

    /// Whether this is LBS (a model file leaves the default out, so LBS models keep the bytes
    /// of files written before the choice existed).
    pub fn is_lbs(&self) -> bool {
        *self == Skinning::Lbs
    }
}

impl std::fmt::Display for Skinning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Skinning {
    type Err = String;

    /// `lbs` or `dqs` (ASCII case ignored).
    fn from_str(s: &str) -> Result<Self, String> {
        Skinning::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("skinning {s:?}: expected lbs or dqs"))
    }
}

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

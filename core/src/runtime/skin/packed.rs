//! [`PackedSkin`] and [`skin_lbs_packed`]: [`SkinWeights`] rearranged once (non-zero
//! influences only, narrow row indices, four vertices blended side by side) for the per-frame
//! LBS, in a fraction of the time of [`super::skin_lbs`]: bit for bit with the portable kernel,
//! within a few ulps with the AVX2 + FMA one ([`PackedKernel`]).

use glam::{Mat4, Vec3, Vec4};

use super::palette::{BoneRows, U8_TABLE_LEN};
use super::{BonePalette, PARALLEL_CHUNK, SkinError, SkinWeights};

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
///
/// [`skin_lbs`]: super::skin_lbs
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
    ///
    /// [`skin_lbs`]: super::skin_lbs
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
/// rest[v]` as [`skin_lbs`] in a fraction of the time (see [`PackedSkin`]), with the fastest
/// kernel this CPU runs (FMA where present, see [`skin_lbs_packed_with`]): bit for bit
/// [`skin_lbs`] with the portable one, within a few ulps with the FMA one.
///
/// Errors (checked once, before any vertex is written) when `rest` or `out` do not have
/// `skin.vertex_count()` entries or a bone with non-zero weight is not below `palette.len()`.
///
/// [`skin_lbs`]: super::skin_lbs
pub fn skin_lbs_packed(
    rest: &[Vec3],
    skin: &PackedSkin,
    palette: &BonePalette,
    out: &mut [Vec3],
) -> Result<(), SkinError> {
    // The FMA kernel falls back to the portable one where the CPU lacks it.
    skin_lbs_packed_with(PackedKernel::Fma, rest, skin, palette, out)
}

/// The instructions [`skin_lbs_packed_with`] blends with.
///
/// [`PackedKernel::Portable`] is bit for bit [`skin_lbs`]. [`PackedKernel::Fma`] blends each
/// influence with fused multiply-adds, 8 floats at a time (two bone rows per instruction), and
/// rounds once per multiply-add instead of twice, so its result differs from [`skin_lbs`] in the
/// last bits (a few ulps of the coordinates; the `packed_lbs_*` tests bound it), and is the same
/// on every CPU that has the instructions: the tests hold it bit for bit to a scalar
/// `f32::mul_add` loop in the same order (`lbs_fma_reference`).
///
/// [`skin_lbs`]: super::skin_lbs
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PackedKernel {
    /// 128-bit SIMD through glam (SSE2 on x86-64, NEON on AArch64): every CPU.
    Portable,
    /// AVX2 and FMA (x86-64-v3: Intel since 2013, AMD since 2015), detected at run time through
    /// `pulp` (the workspace forbids `unsafe`; pulp's CPU-feature tokens make the intrinsics
    /// safe to call).
    Fma,
}

impl PackedKernel {
    /// Whether this CPU runs the kernel.
    pub fn available(self) -> bool {
        match self {
            Self::Portable => true,
            Self::Fma => fma::token().is_some(),
        }
    }
}

/// [`skin_lbs_packed`] with the kernel chosen by the caller (benchmarks and tests compare
/// them); a kernel this CPU lacks ([`PackedKernel::available`]) falls back to
/// [`PackedKernel::Portable`].
///
/// # Errors
/// As [`skin_lbs_packed`].
pub fn skin_lbs_packed_with(
    kernel: PackedKernel,
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
            packed_chunks(kernel, table, &skin.offsets, slots, rest, out);
        }
        PackedSlots::U16(slots) => {
            packed_chunks(
                kernel,
                palette.rows.as_slice(),
                &skin.offsets,
                slots,
                rest,
                out,
            );
        }
    }
    Ok(())
}

/// Runs [`packed_kernel`] over all vertices: with the `parallel` feature and more than
/// [`PARALLEL_CHUNK`] vertices, in chunks of that size on the rayon pool; else on this thread.
fn packed_chunks<I, T>(
    kernel: PackedKernel,
    table: &T,
    offsets: &[u32],
    slots: &[Slot<I>],
    rest: &[Vec3],
    out: &mut [Vec3],
) where
    I: Copy + Sync,
    T: RowTable<I> + Sync + ?Sized,
{
    let fma = match kernel {
        PackedKernel::Fma => fma::token(),
        PackedKernel::Portable => None,
    };
    // One run of whole blocks with the chosen kernel (inside `vectorize` the FMA one is compiled
    // for AVX2 + FMA).
    let run = |offsets: &[u32], rest: &[Vec3], out: &mut [Vec3]| match fma {
        Some(simd) => fma::run(simd, table, offsets, slots, rest, out),
        None => packed_kernel(table, offsets, slots, rest, out, Portable),
    };
    #[cfg(feature = "parallel")]
    if crate::runtime::use_pool(out.len(), PARALLEL_CHUNK) {
        use rayon::prelude::*;
        const BLOCKS: usize = PARALLEL_CHUNK / LANES;
        out.par_chunks_mut(PARALLEL_CHUNK)
            .zip(rest.par_chunks(PARALLEL_CHUNK))
            .enumerate()
            .for_each(|(c, (o, r))| {
                let first = c * BLOCKS;
                let blocks = &offsets[first..=first + o.len().div_ceil(LANES)];
                run(blocks, r, o);
            });
        return;
    }
    run(offsets, rest, out);
}

/// How one block of [`LANES`] vertices is blended: [`Portable`] or [`fma::Blend`].
trait BlockBlend: Copy {
    fn blend<I: Copy, T: RowTable<I> + ?Sized>(
        self,
        table: &T,
        block: &[Slot<I>],
        rest: &[Vec3; LANES],
        out: &mut [Vec3; LANES],
    );
}

/// [`PackedKernel::Portable`]'s block: [`blend_block`].
#[derive(Clone, Copy)]
struct Portable;

impl BlockBlend for Portable {
    #[inline(always)]
    fn blend<I: Copy, T: RowTable<I> + ?Sized>(
        self,
        table: &T,
        block: &[Slot<I>],
        rest: &[Vec3; LANES],
        out: &mut [Vec3; LANES],
    ) {
        blend_block(table, block, rest, out);
    }
}

/// Packed LBS over a run of whole blocks (the last may be partial): `offsets` has one entry per
/// block plus one, indexing into the whole `slots`.
#[inline(always)]
fn packed_kernel<I: Copy, T: RowTable<I> + ?Sized, B: BlockBlend>(
    table: &T,
    offsets: &[u32],
    slots: &[Slot<I>],
    rest: &[Vec3],
    out: &mut [Vec3],
    blend: B,
) {
    let mut outs = out.chunks_exact_mut(LANES);
    let mut rests = rest.chunks_exact(LANES);
    for ((o, r), off) in (&mut outs).zip(&mut rests).zip(offsets.windows(2)) {
        let block = &slots[off[0] as usize..off[1] as usize];
        let o: &mut [Vec3; LANES] = o.try_into().expect("chunks_exact_mut yields LANES");
        let r: &[Vec3; LANES] = r.try_into().expect("chunks_exact yields LANES");
        blend.blend(table, block, r, o);
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
        blend.blend(table, block, &rr, &mut oo);
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

/// [`PackedKernel::Fma`]: AVX2 + FMA through pulp's safe intrinsics, x86-64 only.
#[cfg(target_arch = "x86_64")]
mod fma {
    use glam::Vec3;
    use std::arch::x86_64::__m256;

    use crate::runtime::simd::Fma as V3;
    pub(super) use crate::runtime::simd::fma as token;

    use super::{BlockBlend, LANES, RowTable, Slot};

    /// `_mm_shuffle_ps`'s immediate: lanes `a`, `b` of its first operand, `c`, `d` of its second.
    const fn imm(a: i32, b: i32, c: i32, d: i32) -> i32 {
        a | (b << 2) | (c << 4) | (d << 6)
    }

    /// [`super::packed_kernel`] with [`Blend`], compiled for AVX2 + FMA: handed to pulp as a
    /// struct whose `call` is inlined into its feature context (a closure's `call_once` was not
    /// always inlined there, leaving the intrinsics as calls: ARCHITECTURE.md, "Per-frame
    /// SIMD").
    #[inline(always)]
    pub(super) fn run<I: Copy, T: RowTable<I> + ?Sized>(
        simd: V3,
        table: &T,
        offsets: &[u32],
        slots: &[Slot<I>],
        rest: &[Vec3],
        out: &mut [Vec3],
    ) {
        simd.vectorize(Run {
            simd,
            table,
            offsets,
            slots,
            rest,
            out,
        });
    }

    struct Run<'a, I, T: ?Sized> {
        simd: V3,
        table: &'a T,
        offsets: &'a [u32],
        slots: &'a [Slot<I>],
        rest: &'a [Vec3],
        out: &'a mut [Vec3],
    }

    impl<I: Copy, T: RowTable<I> + ?Sized> pulp::NullaryFnOnce for Run<'_, I, T> {
        type Output = ();

        #[inline(always)]
        fn call(self) {
            super::packed_kernel(
                self.table,
                self.offsets,
                self.slots,
                self.rest,
                self.out,
                Blend(self.simd),
            );
        }
    }

    /// [`PackedKernel::Fma`](super::PackedKernel::Fma)'s block.
    #[derive(Clone, Copy)]
    pub(super) struct Blend(pub(super) V3);

    impl BlockBlend for Blend {
        /// Per vertex, two 8-wide accumulators: rows 0 and 1 of the blended matrix, and row 2
        /// with the palette's zero pad row. Per influence: a broadcast of the weight and two
        /// fused multiply-adds of the bone's 64-byte entry (`acc = w * rows + acc`, slot
        /// order). Then each row times `(x, y, z, 1)` and three rounds of horizontal adds: the
        /// coordinate `r . p` as `(r0 x + r1 y) + (r2 z + r3)`.
        #[inline(always)]
        fn blend<I: Copy, T: RowTable<I> + ?Sized>(
            self,
            table: &T,
            block: &[Slot<I>],
            rest: &[Vec3; LANES],
            out: &mut [Vec3; LANES],
        ) {
            let simd = self.0;
            let zero = simd.avx._mm256_setzero_ps();
            let mut rows01 = [zero; LANES];
            let mut rows2 = [zero; LANES];
            for s in block {
                for l in 0..LANES {
                    let m: &[[f32; 8]; 2] = bytemuck::cast_ref(table.row(s.rows[l]));
                    let w = simd.avx._mm256_set1_ps(s.weights[l]);
                    let r01: __m256 = bytemuck::cast(m[0]);
                    let r2: __m256 = bytemuck::cast(m[1]);
                    rows01[l] = simd.fma._mm256_fmadd_ps(w, r01, rows01[l]);
                    rows2[l] = simd.fma._mm256_fmadd_ps(w, r2, rows2[l]);
                }
            }
            // Each vertex as (x, y, z, 1) in both halves, from the block's 12 rest floats
            // loaded as three 16-byte rows [x0 y0 z0 x1], [y1 z1 x2 y2], [z2 x3 y3 z3].
            let (sse, sse41, avx) = (simd.sse, simd.sse4_1, simd.avx);
            let rows: &[[f32; 4]; 3] = bytemuck::cast_ref(rest);
            let (a, b, c) = (
                bytemuck::cast(rows[0]),
                bytemuck::cast(rows[1]),
                bytemuck::cast(rows[2]),
            );
            let one = sse._mm_set1_ps(1.0);
            let x1y1 = sse._mm_shuffle_ps::<{ imm(3, 3, 0, 0) }>(a, b); // x1 x1 y1 y1
            let z1w = sse._mm_shuffle_ps::<{ imm(1, 1, 0, 0) }>(b, one); // z1 z1 1 1
            let z2w = sse._mm_shuffle_ps::<{ imm(0, 0, 0, 0) }>(c, one); // z2 z2 1 1
            let p = [
                sse41._mm_blend_ps::<0b1000>(a, one),
                sse._mm_shuffle_ps::<{ imm(0, 2, 0, 2) }>(x1y1, z1w),
                sse._mm_shuffle_ps::<{ imm(2, 3, 0, 2) }>(b, z2w),
                sse41._mm_blend_ps::<0b1000>(sse._mm_shuffle_ps::<{ imm(1, 2, 3, 3) }>(c, c), one),
            ];
            for l in 0..LANES {
                let pp = avx._mm256_insertf128_ps::<1>(avx._mm256_castps128_ps256(p[l]), p[l]);
                rows01[l] = avx._mm256_mul_ps(rows01[l], pp);
                rows2[l] = avx._mm256_mul_ps(rows2[l], pp);
            }
            // hadd(a, b) = [a0+a1, a2+a3, b0+b1, b2+b3 | a4+a5, a6+a7, b4+b5, b6+b7]: after
            // three rounds, [x0 x1 x2 x3 | y0 y1 y2 y3] and [z0 z1 z2 z3 | 0 0 0 0].
            let hadd = |a, b| simd.avx._mm256_hadd_ps(a, b);
            let xy = hadd(hadd(rows01[0], rows01[1]), hadd(rows01[2], rows01[3]));
            let z = hadd(hadd(rows2[0], rows2[1]), hadd(rows2[2], rows2[3]));
            // The four vertices' 12 floats as three 16-byte stores: [x0 y0 z0 x1], [y1 z1 x2
            // y2], [z2 x3 y3 z3], transposed in registers (shufps picks two lanes from each
            // operand: `pick::<k>(a, b) = [a_k0, a_k1, b_k2, b_k3]`).
            let x = avx._mm256_castps256_ps128(xy);
            let y = avx._mm256_extractf128_ps::<1>(xy);
            let z = avx._mm256_castps256_ps128(z);
            let xy_lo = sse._mm_unpacklo_ps(x, y); // x0 y0 x1 y1
            let xy_hi = sse._mm_unpackhi_ps(x, y); // x2 y2 x3 y3
            let z0x1 = sse._mm_shuffle_ps::<{ imm(0, 0, 2, 2) }>(z, xy_lo); // z0 z0 x1 x1
            let o0 = sse._mm_shuffle_ps::<{ imm(0, 1, 0, 2) }>(xy_lo, z0x1); // x0 y0 z0 x1
            let y1z1 = sse._mm_shuffle_ps::<{ imm(3, 3, 1, 1) }>(xy_lo, z); // y1 y1 z1 z1
            let o1 = sse._mm_shuffle_ps::<{ imm(0, 2, 0, 1) }>(y1z1, xy_hi); // y1 z1 x2 y2
            let z2x3 = sse._mm_shuffle_ps::<{ imm(2, 2, 2, 3) }>(z, xy_hi); // z2 z2 x3 y3
            let y3z3 = sse._mm_shuffle_ps::<{ imm(3, 3, 3, 3) }>(xy_hi, z); // y3 y3 z3 z3
            let o2 = sse._mm_shuffle_ps::<{ imm(0, 2, 0, 2) }>(z2x3, y3z3); // z2 x3 y3 z3
            let flat: &mut [[f32; 4]; 3] = bytemuck::cast_mut(out);
            flat[0] = bytemuck::cast(o0);
            flat[1] = bytemuck::cast(o1);
            flat[2] = bytemuck::cast(o2);
        }
    }
}

/// Elsewhere than x86-64: no FMA kernel ([`PackedKernel::Fma`] is never available).
#[cfg(not(target_arch = "x86_64"))]
mod fma {
    use crate::runtime::simd::Fma;
    pub(super) use crate::runtime::simd::fma as token;

    pub(super) fn run<I, T: ?Sized>(
        simd: Fma,
        _table: &T,
        _offsets: &[u32],
        _slots: &[super::Slot<I>],
        _rest: &[glam::Vec3],
        _out: &mut [glam::Vec3],
    ) {
        match simd {}
    }

    #[derive(Clone, Copy)]
    pub(super) struct Blend(pub(super) Fma);

    impl super::BlockBlend for Blend {
        fn blend<I: Copy, T: super::RowTable<I> + ?Sized>(
            self,
            _table: &T,
            _block: &[super::Slot<I>],
            _rest: &[glam::Vec3; super::LANES],
            _out: &mut [glam::Vec3; super::LANES],
        ) {
            match self.0 {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::skin::{MAX_INFLUENCES, RigidTransform, skin_lbs};
    use glam::Quat;

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

    /// What [`PackedKernel::Fma`] computes, one vertex at a time with scalar `f32::mul_add`: per
    /// vertex the blended rows `a_r = sum_j w_j M_j[r]` (row `r` of bone `j`'s 3x4 matrix, a fused
    /// multiply-add per entry in slot order, from +0), then each coordinate as
    /// `(a_r0 x + a_r1 y) + (a_r2 z + a_r3)`. Slow; the reference the kernel is tested against, bit
    /// for bit.
    ///
    /// Errors as `skin_lbs`.
    fn lbs_fma_reference(
        rest: &[Vec3],
        skin: &SkinWeights,
        palette: &BonePalette,
        out: &mut [Vec3],
    ) -> Result<(), SkinError> {
        // The sizes and bone indices are those skin_lbs checks: let it check them.
        skin_lbs(rest, skin, palette, out)?;
        for (v, (p, o)) in rest.iter().zip(out.iter_mut()).enumerate() {
            let (ii, ww) = skin.vertex(v);
            let mut a = [[0.0f32; 4]; 3];
            for (&bone, &w) in ii.iter().zip(ww) {
                if w == 0.0 {
                    break;
                }
                let rows = &palette.rows[bone as usize + 1];
                for (ar, mr) in a.iter_mut().zip(rows) {
                    for (x, &m) in ar.iter_mut().zip(mr.as_ref()) {
                        *x = w.mul_add(m, *x);
                    }
                }
            }
            let c = |r: [f32; 4]| (r[0] * p.x + r[1] * p.y) + (r[2] * p.z + r[3]);
            *o = Vec3::new(c(a[0]), c(a[1]), c(a[2]));
        }
        Ok(())
    }

    /// Bits, with every NaN as one (the kernels need not agree on NaN payloads).
    fn bits_nan_as_one(v: &[Vec3]) -> Vec<[u32; 3]> {
        v.iter()
            .map(|p| {
                p.to_array()
                    .map(|x| if x.is_nan() { u32::MAX } else { x.to_bits() })
            })
            .collect()
    }

    /// Packed and reference LBS on the same inputs: the portable kernel bit for bit
    /// `skin_lbs`; the FMA kernel (where the CPU has it) bit for bit its scalar reference
    /// `lbs_fma_reference`, and within rounding of `skin_lbs`.
    fn assert_packed_matches(rest: &[Vec3], skin: &SkinWeights, palette: &BonePalette) {
        let packed = PackedSkin::new(skin).unwrap();
        let mut expected = vec![Vec3::NAN; rest.len()];
        skin_lbs(rest, skin, palette, &mut expected).unwrap();
        let mut got = vec![Vec3::NAN; rest.len()];
        skin_lbs_packed_with(PackedKernel::Portable, rest, &packed, palette, &mut got).unwrap();
        let what = format!("k = {}, n = {}", skin.k(), rest.len());
        assert_eq!(bits(&got), bits(&expected), "portable, {what}");
        if !PackedKernel::Fma.available() {
            eprintln!("the FMA kernel is not checked: this CPU lacks AVX2 + FMA");
            return;
        }
        let mut fused = vec![Vec3::NAN; rest.len()];
        lbs_fma_reference(rest, skin, palette, &mut fused).unwrap();
        got.fill(Vec3::NAN);
        skin_lbs_packed_with(PackedKernel::Fma, rest, &packed, palette, &mut got).unwrap();
        assert_eq!(
            bits_nan_as_one(&got),
            bits_nan_as_one(&fused),
            "fma, {what}"
        );
        for (v, (a, b)) in got.iter().zip(&expected).enumerate() {
            if b.is_finite() {
                // Rounding of |coordinates| <= ~10 (rest points within 3 of the origin,
                // translations within 2): a few ulps of 10 in f32.
                let scale = 1.0 + rest[v].abs().max_element() * 3.0;
                assert!(
                    (*a - *b).abs().max_element() <= 8.0 * f32::EPSILON * scale * 3.0,
                    "fma vs skin_lbs, {what}, vertex {v}: {a} vs {b}"
                );
            } else {
                assert!(a.is_nan(), "{what}, vertex {v}: {a} vs {b}");
            }
        }
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

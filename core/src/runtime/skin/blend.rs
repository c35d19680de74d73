//! The reference skinning over [`SkinWeights`]: [`skin_lbs`] (linear blend) and [`skin_dqs`]
//! (dual quaternions), monomorphised over the influence count and split into
//! [`PARALLEL_CHUNK`]s on the rayon pool with the `parallel` feature.

use glam::{Affine3A, Vec3, Vec3A, Vec4};

use super::{BonePalette, PARALLEL_CHUNK, SkinError, SkinWeights};

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
    if crate::runtime::use_pool(out.len(), PARALLEL_CHUNK) {
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
            // As in the LBS kernel: slots are sorted heaviest first, so the first zero ends
            // the vertex's influences (a zero slot adds nothing to the blend).
            if ww[j] == 0.0 {
                break;
            }
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
pub(super) fn apply_blended(br: Vec4, bd: Vec4, p: Vec3A) -> Vec3A {
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
    use crate::runtime::skin::RigidTransform;

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

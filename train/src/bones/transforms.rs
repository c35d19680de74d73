//! Bone transform update of SSDR (Le & Deng 2012 eq. 7): per frame, each bone in turn is refit
//! by weighted Procrustes against the residual the other bones leave,
//! `min_{R,T} sum_i | q_i - w_ij (R p_i + T) |^2` with `q_i = v_i - sum_{k != j} w_ik (R_k p_i + T_k)`,
//! i.e. weights `w_ij^2` and targets `q_i / w_ij`. Frames are independent and run in parallel.

use crease_core::glam::Vec3A;

use super::kabsch::{PairSums, Rigid};
use super::{Problem, Weights};
use crate::par;

/// Updates `xf` (frame-major `[t * bones + b]`) in place with `passes` Gauss–Seidel sweeps over
/// the bones, and returns each frame's sum of squared vertex errors afterwards.
pub(crate) fn update(
    problem: &Problem,
    bones: usize,
    weights: &Weights,
    xf: &mut [Rigid],
    passes: usize,
) -> Vec<f64> {
    let (offsets, entries) = weights.by_bone(bones);
    let n = problem.n;
    let k = weights.k;
    par::map_chunks_mut(
        xf,
        bones,
        || vec![Vec3A::ZERO; n],
        |recon, t, xt| {
            let frame = &problem.frames[t * n..(t + 1) * n];
            // Current reconstruction of this frame.
            for (i, r) in recon.iter_mut().enumerate() {
                let p = problem.rest[i];
                let mut v = Vec3A::ZERO;
                for s in i * k..(i + 1) * k {
                    let w = weights.w[s];
                    if w > 0.0 {
                        v += w * xt[weights.idx[s] as usize].apply(p);
                    }
                }
                *r = v;
            }
            for _ in 0..passes.max(1) {
                for b in 0..bones {
                    let members = &entries[offsets[b] as usize..offsets[b + 1] as usize];
                    if members.is_empty() {
                        continue;
                    }
                    let old = xt[b];
                    let mut sums = PairSums::default();
                    for &(i, w) in members {
                        let i = i as usize;
                        let p = problem.rest[i];
                        let q = frame[i] - recon[i] + w * old.apply(p);
                        let w = w as f64;
                        sums.add_scaled(w * w, w, p, q);
                    }
                    let Some(new) = sums.solve(old.m) else {
                        continue;
                    };
                    for &(i, w) in members {
                        let i = i as usize;
                        let p = problem.rest[i];
                        recon[i] += w * (new.apply(p) - old.apply(p));
                    }
                    xt[b] = new;
                }
            }
            frame
                .iter()
                .zip(recon.iter())
                .map(|(v, r)| (*v - *r).length_squared() as f64)
                .sum()
        },
    )
}

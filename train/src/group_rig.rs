//! Control groups from a coarse rig (issue 23): the geometry-local methods (HZY11 §5.1.1) give each
//! bone the `k_c` control points geodesically nearest to its centre. With a rig of over a thousand
//! small bones (HZY11 Table 1) those sets change from one small bone to its neighbour, and
//! neighbouring bones' regressors, each fitted to 14 examples, disagree. A coarse rig (tens to a
//! few hundred bones; `crease train --group-bones auto` takes 150) fitted to the same examples
//! gives a steadier choice: each fine bone takes the control set of the coarse bone that shares
//! most of its vertices, so every fine bone of a segment sees the same points. Only the grouping
//! changes: each fine bone keeps its own regressor, trained on its own rotations.
//!
//! Measured on the generated hands (BENCHMARKS.md, "Accuracy beside HZY11 Table 2"): with each fine
//! bone's own nearest points, 1,355 bones predicted worse than 40 in the palm layout's
//! leave-one-out; grouped by a 150-bone rig they predict better in every comparison (and by any rig
//! of 40 to 300 bones in that leave-one-out). Coarser groupings that are not a fitted rig
//! (geometric or motion clusters of the fine bones, the nearest control point) were tried and did
//! worse; see that section.

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::runtime::skin::SkinWeights;

use crate::bones::{self, FitError, FitInput, FitOptions, IterationStat};

/// The coarse rig that groups a fine rig's bones.
#[derive(Clone, Debug)]
pub struct GroupRig {
    /// The coarse rig's bones.
    pub bone_count: usize,
    /// The coarse rig's weights (they place its bones' centres).
    pub skin: SkinWeights,
    /// Per fine bone, the coarse bone whose control set it takes ([`dominant`]).
    pub of_bone: Vec<u32>,
    /// The coarse fit's RMS error (bbox largest side = 1).
    pub fit_rms: f64,
}

/// Fits a `count`-bone rig to the examples (rest pose first, as for the fine rig, with the
/// fine rig's options but for the bone count) and assigns each of the fine rig's
/// `fine_bones` to one of its bones.
pub fn fit(
    rest: &Mesh,
    frames: &[&[Vec3]],
    fine_skin: &SkinWeights,
    fine_bones: usize,
    options: &FitOptions,
    count: usize,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<GroupRig, FitError> {
    let coarse = bones::fit(
        FitInput {
            rest,
            frames,
            rest_frame: Some(0),
        },
        &FitOptions {
            bones: count,
            ..options.clone()
        },
        progress,
    )?;
    let of_bone = dominant(fine_skin, fine_bones, &coarse.skin, coarse.bone_count);
    Ok(GroupRig {
        bone_count: coarse.bone_count,
        skin: coarse.skin,
        of_bone,
        fit_rms: coarse.report.rms_normalized,
    })
}

/// Per fine bone, the coarse bone sharing most of its weight: `argmax_c sum_v w_vb W_vc` over
/// the vertices `v` (fine weights `w`, coarse `W`; the lower index on ties). A fine bone that
/// moves no vertex takes the coarse bone of the most weight overall.
pub fn dominant(
    fine: &SkinWeights,
    fine_bones: usize,
    coarse: &SkinWeights,
    coarse_bones: usize,
) -> Vec<u32> {
    // Sparse rows: a fine bone overlaps a few coarse bones.
    let mut overlap: Vec<Vec<(u32, f64)>> = vec![Vec::new(); fine_bones];
    let mut total = vec![0.0f64; coarse_bones];
    for ((fb, fw), (cb, cw)) in fine.iter().zip(coarse.iter()) {
        for (&c, &wc) in cb.iter().zip(cw) {
            if let Some(t) = total.get_mut(c as usize).filter(|_| wc > 0.0) {
                *t += f64::from(wc);
            }
        }
        for (&b, &wb) in fb.iter().zip(fw) {
            let Some(row) = overlap.get_mut(b as usize).filter(|_| wb > 0.0) else {
                continue;
            };
            for (&c, &wc) in cb.iter().zip(cw) {
                if wc <= 0.0 || c as usize >= coarse_bones {
                    continue;
                }
                let w = f64::from(wb) * f64::from(wc);
                match row.iter_mut().find(|(d, _)| *d == c) {
                    Some((_, sum)) => *sum += w,
                    None => row.push((c, w)),
                }
            }
        }
    }
    let heaviest = first_max(total.iter().enumerate().map(|(c, &w)| (c as u32, w))).unwrap_or(0);
    overlap
        .into_iter()
        .map(|row| first_max(row.into_iter()).unwrap_or(heaviest))
        .collect()
}

/// The index of the largest value, the lowest index among equals.
fn first_max(items: impl Iterator<Item = (u32, f64)>) -> Option<u32> {
    items
        .max_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))
        .map(|(c, _)| c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Four vertices; fine bones 0..3, coarse bones 0..2 (K = 2 both).
    #[test]
    fn each_fine_bone_takes_the_coarse_bone_of_most_shared_weight() {
        let fine = SkinWeights::new(
            2,
            // v0: fine 0; v1: fine 0 and 1; v2: fine 1; v3: fine 1 (0.3) and 2 (0.7).
            vec![0, 1, 0, 1, 1, 0, 1, 2],
            vec![1.0, 0.0, 0.5, 0.5, 1.0, 0.0, 0.3, 0.7],
        )
        .unwrap();
        let coarse = SkinWeights::new(
            2,
            // v0: coarse 0; v1: 0 (0.6), 1 (0.4); v2: coarse 1; v3: coarse 1.
            vec![0, 1, 0, 1, 1, 0, 1, 0],
            vec![1.0, 0.0, 0.6, 0.4, 1.0, 0.0, 1.0, 0.0],
        )
        .unwrap();
        // Dense overlaps by hand: fine 0 = (1 + 0.5*0.6, 0.5*0.4) = (1.3, 0.2) -> 0;
        // fine 1 = (0.5*0.6, 0.5*0.4 + 1 + 0.3) = (0.3, 1.5) -> 1; fine 2 = (0, 0.7) -> 1;
        // fine 3 moves nothing: the coarse bone of most weight (0: 1.6, 1: 2.4) -> 1.
        assert_eq!(dominant(&fine, 4, &coarse, 2), vec![0, 1, 1, 1]);
    }

    #[test]
    fn ties_go_to_the_lower_coarse_bone() {
        let fine = SkinWeights::new(1, vec![0, 0], vec![1.0, 1.0]).unwrap();
        let coarse = SkinWeights::new(1, vec![1, 0], vec![1.0, 1.0]).unwrap();
        assert_eq!(dominant(&fine, 1, &coarse, 2), vec![0]);
    }
}

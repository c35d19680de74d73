//! How many control points a shape needs, and which parts the chosen ones leave undetermined
//! (issue 42), both measured inside the training set, never on a test set.
//!
//! - **The control-point curve** ([`control_curve`]): for each count `n`, the automatic control
//!   points (FKY08 §3, [`crate::controls::auto_control_points`]) and the leave-one-out mesh
//!   error with them: each non-rest example held out in turn, the rotations regressed from the
//!   others, eq. 11 from its control points, LBS, the error normalised as [`crate::metrics`]
//!   does. The rig (bones, weights, edge skin) is the one fitted on every example, as in
//!   [`crate::select`]: the curve is about the control points, and refitting the bones per
//!   fold would multiply its cost by the bone fit's.
//! - **Undetermined bones** ([`undetermined`]): the same leave-one-out with the model's own
//!   control points, per bone. A bone's *spread* is the mean angle between its rotation in each
//!   non-rest example and its rotation in the rest pose (how much the examples move it); its
//!   *error* is the mean angle between its held-out rotation and the one the regression
//!   predicts without that example. A bone the examples move ([`MIN_SPREAD_DEG`]) whose error is
//!   at least [`UNDETERMINED_RATIO`] of its spread is one the control points do not determine:
//!   whatever its rotation in a new pose, they say little about it. Such bones, joined where
//!   they share vertices (weights above [`SHARED_WEIGHT`]), form the regions
//!   [`Coverage::regions`] names: the report colours their vertices, and `crease train` warns.
//!
//! A bone turned about its own axis by the examples moves only a thin shape; the spread is a
//! rotation angle, not a distance, so such a bone counts as much as one that swings a limb.
//! Regions smaller than [`MIN_REGION_SHARE`] of the vertices are not reported.

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::predict::RotationScratch;

use crate::base::{TrainError, TrainedBase};
use crate::controls::auto_control_points;
use crate::regress::{self, RegressInput, RegressOptions};
use crate::select::loo_errors;
pub use crate::selection::{Coverage, CurvePoint, Region};

/// A bone the examples turn by less than this mean angle (degrees) is never undetermined.
pub const MIN_SPREAD_DEG: f64 = 5.0;
/// A bone whose leave-one-out rotation error is at least this share of its spread is
/// undetermined by the control points (module docs).
pub const UNDETERMINED_RATIO: f64 = 0.5;
/// Two bones share a region where a vertex weighs both above this.
pub const SHARED_WEIGHT: f32 = 0.1;
/// Regions with fewer vertices than this share of the mesh's are not reported.
pub const MIN_REGION_SHARE: f64 = 0.01;

/// The control-point curve (module docs): one point per count of `counts`, in order, with the
/// model's regression `options` and `beta`, up to the first count the automatic choice cannot
/// give (more points than the examples' components allow), whose reason comes back beside the
/// points. `frames` are the training meshes, rest pose first, as given to
/// [`crate::pipeline::train_base`].
///
/// A count whose leave-one-out cannot run (fewer than 3 examples, a translation solve that
/// cannot be built) also ends the curve, with its reason.
pub fn control_curve(
    base: &TrainedBase,
    frames: &[&[Vec3]],
    options: &RegressOptions,
    beta: f32,
    counts: &[usize],
) -> (Vec<CurvePoint>, Option<String>) {
    let kappa = match options.method {
        regress::Method::Rbf => options.rbf_ridge,
        _ => options.kcca.kappa,
    };
    let mut curve = Vec::with_capacity(counts.len());
    for &count in counts {
        let controls = match auto_control_points(&base.rig.rest, frames, count) {
            Ok(c) => c,
            Err(e) => {
                return (
                    curve,
                    Some(format!("{count} automatic control points: {e}")),
                );
            }
        };
        let rms = match loo_errors(
            base,
            &controls,
            frames,
            options,
            &[(options.kernel, kappa)],
            &[beta],
            &|_, _| {},
        ) {
            Ok(e) => e[0],
            Err(e) => return (curve, Some(format!("{count} control points: {e}"))),
        };
        curve.push(CurvePoint {
            count,
            controls,
            rms,
        });
    }
    (curve, None)
}

/// Per-bone spread and leave-one-out rotation error with `base`'s own control points and
/// `options`, and the regions they leave undetermined (module docs).
///
/// # Errors
/// Fewer than 3 examples (no leave-one-out).
pub fn undetermined(base: &TrainedBase, options: &RegressOptions) -> Result<Coverage, TrainError> {
    let rig = &base.rig;
    let bones = rig.bone_count;
    let n = base.rotations.len();
    if n < 3 {
        return Err(TrainError::Select(format!(
            "leave-one-out needs at least 3 examples, got {n}"
        )));
    }
    let angle = |a: Quat, b: Quat| f64::from(a.angle_between(b)).to_degrees();
    let mut spread = vec![0.0f64; bones];
    let mut error = vec![0.0f64; bones];
    let mut scratch = RotationScratch::default();
    let mut predicted = vec![Quat::IDENTITY; bones];
    for held in 1..n {
        let keep: Vec<usize> = (0..n).filter(|&i| i != held).collect();
        let controls: Vec<Vec<Vec3>> = keep
            .iter()
            .map(|&i| base.example_controls[i].clone())
            .collect();
        let rotations: Vec<Vec<Quat>> = keep.iter().map(|&i| base.rotations[i].clone()).collect();
        let model = regress::build_rotation_model(
            RegressInput {
                rest: &rig.rest,
                skin: &rig.skin,
                bone_count: bones,
                control_vertices: &base.control_vertices,
                controls: &controls,
                rotations: &rotations,
                group_rig: base.group_rig.as_ref(),
            },
            options,
        );
        model.predict(&base.example_controls[held], &mut scratch, &mut predicted);
        for b in 0..bones {
            spread[b] += angle(base.rotations[held][b], base.rotations[0][b]);
            error[b] += angle(base.rotations[held][b], predicted[b]);
        }
    }
    let folds = (n - 1) as f64;
    spread.iter_mut().for_each(|s| *s /= folds);
    error.iter_mut().for_each(|e| *e /= folds);
    let flagged: Vec<bool> = (0..bones)
        .map(|b| spread[b] >= MIN_SPREAD_DEG && error[b] >= UNDETERMINED_RATIO * spread[b])
        .collect();
    let regions = regions(base, &flagged, &spread, &error);
    Ok(Coverage {
        spread_deg: spread,
        error_deg: error,
        regions,
    })
}

/// The flagged bones joined where a vertex weighs two of them above [`SHARED_WEIGHT`], with
/// their vertices (heaviest bone flagged); the regions of at least [`MIN_REGION_SHARE`] of the
/// vertices, largest first.
fn regions(base: &TrainedBase, flagged: &[bool], spread: &[f64], error: &[f64]) -> Vec<Region> {
    let rig = &base.rig;
    let bones = rig.bone_count;
    // Union-find over the flagged bones.
    let mut parent: Vec<usize> = (0..bones).collect();
    fn find(parent: &mut [usize], mut b: usize) -> usize {
        while parent[b] != b {
            parent[b] = parent[parent[b]];
            b = parent[b];
        }
        b
    }
    let mut heaviest = Vec::with_capacity(rig.rest.vertex_count());
    for (indices, weights) in rig.skin.iter() {
        // Slots are ordered heaviest first (SkinWeights::new).
        heaviest.push(indices[0] as usize);
        let shared: Vec<usize> = indices
            .iter()
            .zip(weights)
            .filter(|&(&b, &w)| w > SHARED_WEIGHT && flagged[b as usize])
            .map(|(&b, _)| b as usize)
            .collect();
        for pair in shared.windows(2) {
            let (a, b) = (find(&mut parent, pair[0]), find(&mut parent, pair[1]));
            parent[a] = b;
        }
    }
    let mut by_root: std::collections::BTreeMap<usize, Region> = std::collections::BTreeMap::new();
    for b in (0..bones).filter(|&b| flagged[b]) {
        let root = find(&mut parent, b);
        by_root
            .entry(root)
            .or_insert_with(|| Region {
                bones: Vec::new(),
                vertices: Vec::new(),
                centroid: [0.0; 3],
                spread_deg: 0.0,
                error_deg: 0.0,
            })
            .bones
            .push(b as u32);
    }
    for (v, &b) in heaviest.iter().enumerate() {
        if flagged[b] {
            let root = find(&mut parent, b);
            if let Some(r) = by_root.get_mut(&root) {
                r.vertices.push(v as u32);
            }
        }
    }
    let min_vertices = MIN_REGION_SHARE * rig.rest.vertex_count() as f64;
    let mut out: Vec<Region> = by_root
        .into_values()
        .filter(|r| !r.vertices.is_empty() && r.vertices.len() as f64 >= min_vertices)
        .map(|mut r| {
            let c: Vec3 = r
                .vertices
                .iter()
                .map(|&v| rig.rest.positions[v as usize])
                .sum::<Vec3>()
                / r.vertices.len() as f32;
            r.centroid = c.to_array();
            let k = r.bones.len() as f64;
            r.spread_deg = r.bones.iter().map(|&b| spread[b as usize]).sum::<f64>() / k;
            r.error_deg = r.bones.iter().map(|&b| error[b as usize]).sum::<f64>() / k;
            r
        })
        .collect();
    out.sort_by_key(|r| std::cmp::Reverse(r.vertices.len()));
    out
}

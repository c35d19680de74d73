//! What the report's pictures show of a pose: the prediction of one method, its per-vertex
//! error and its per-bone rotation error, recomputed for the poses the report draws (the
//! evaluation keeps only per-frame errors). A held-out test set is predicted by one model
//! trained on the training set; a leave-one-out fold by a model trained, bones included,
//! without its pose, as `crease eval --loo` trains it.

use std::sync::Arc;

use anyhow::Context;
use crease_core::glam::{Quat, Vec3};
use crease_core::predictor::Predictor;
use crease_train::base::TrainedBase;
use crease_train::eval::{EvalOptions, oracle_transforms, rms_normalized};
use crease_train::pipeline::{self, TrainInput};
use crease_train::regress::{Method, RegressOptions};
use crease_train::selection::{Candidate, Selection};

/// One predicted pose.
#[derive(Debug)]
pub(super) struct Pose {
    /// The example's name.
    pub name: String,
    /// The true vertex positions.
    pub truth: Vec<Vec3>,
    /// The predicted ones.
    pub predicted: Vec<Vec3>,
    /// Per vertex, `|predicted - truth|` over the rest mesh's largest bounding-box side.
    pub vertex_error: Vec<f32>,
    /// RMS of `vertex_error` (the evaluation's per-frame error).
    pub rms: f64,
    /// Per bone, degrees between the predicted rotation and the reference one (the oracle's
    /// fit to the true pose, or a training example's fitted rotation).
    pub bone_error_deg: Vec<f64>,
}

/// A base and a predictor of one method, trained as the evaluation trains it.
#[derive(Debug)]
pub(super) struct Fitted {
    /// Bones, controls, edge skin.
    pub base: TrainedBase,
    /// The method's predictor.
    pub predictor: Predictor,
}

/// Trains `method` on `train` with the evaluation's options; `selected`, when the evaluation
/// chose the kernel, kappa and beta by leave-one-out, is its choice for this training run.
pub(super) fn fit(
    train: TrainInput<'_>,
    options: &EvalOptions,
    method: Method,
    selected: Option<&Candidate>,
) -> anyhow::Result<Fitted> {
    let base = pipeline::train_base(train, &options.train, &mut |_| {})
        .context("training the report's model")?;
    let regress = RegressOptions {
        method,
        ..options.train.regress.clone()
    };
    let (regress, beta) = match selected {
        Some(c) => {
            let s = Selection {
                best: c.clone(),
                table: Vec::new(),
                seconds: 0.0,
            };
            (s.apply(&regress), c.beta)
        }
        None => (regress, options.beta),
    };
    let model = Arc::new(base.model(&regress, beta));
    let predictor = Predictor::new(model, Some(beta)).context("the report's predictor")?;
    Ok(Fitted { base, predictor })
}

/// `frame` predicted from its control points (`controls`, model order) by `predictor`, its
/// errors against the truth and, per bone, against `reference` rotations.
pub(super) fn predict(
    predictor: &Predictor,
    controls: &[u32],
    name: &str,
    frame: &[Vec3],
    reference: &[Quat],
) -> anyhow::Result<Pose> {
    let model = predictor.model();
    let scale = model.rig.rest.bbox_diagonal_scale();
    let at: Vec<Vec3> = controls.iter().map(|&v| frame[v as usize]).collect();
    let mut ctx = predictor.new_context();
    let predicted = predictor
        .predict(&mut ctx, &at, None)
        .with_context(|| format!("predicting {name}"))?
        .to_vec();
    let vertex_error = predicted
        .iter()
        .zip(frame)
        .map(|(p, t)| p.distance(*t) / scale)
        .collect();
    let bone_error_deg = ctx
        .transforms()
        .iter()
        .zip(reference)
        .map(|(t, r)| {
            // The smaller angle between the two rotations (q and -q are the same rotation).
            let d = f64::from(t.rotation.dot(*r).abs().min(1.0));
            2.0 * d.acos().to_degrees()
        })
        .collect();
    Ok(Pose {
        name: name.to_owned(),
        rms: rms_normalized(&predicted, frame, scale),
        truth: frame.to_vec(),
        predicted,
        vertex_error,
        bone_error_deg,
    })
}

/// The oracle's rotations of `frame` (bone transforms fitted to it with `base`'s weights).
pub(super) fn oracle_rotations(base: &TrainedBase, frame: &[Vec3]) -> Vec<Quat> {
    oracle_transforms(&base.rig.rest, &base.rig.skin, base.rig.bone_count, frame)
        .iter()
        .map(|t| t.rotation)
        .collect()
}

/// Indices of the `k` largest values, largest first (NaN counts as largest).
pub(super) fn worst(values: &[f64], k: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..values.len()).collect();
    order.sort_by(|&a, &b| {
        let (x, y) = (values[a], values[b]);
        y.partial_cmp(&x)
            .unwrap_or_else(|| x.is_nan().cmp(&y.is_nan()).reverse())
    });
    order.truncate(k);
    order
}

/// The shared top of the colour scale of a set of poses: the largest per-vertex error's 99.5th
/// percentile over all of them (a few outlying vertices do not wash out the rest).
pub(super) fn scale_max(poses: &[Pose]) -> f32 {
    let mut all: Vec<f32> = poses
        .iter()
        .flat_map(|p| p.vertex_error.iter().copied())
        .filter(|e| e.is_finite())
        .collect();
    if all.is_empty() {
        return 1.0;
    }
    all.sort_by(f32::total_cmp);
    let k = ((all.len() as f64 * 0.995) as usize).min(all.len() - 1);
    all[k].max(f32::MIN_POSITIVE)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn worst_first() {
        assert_eq!(worst(&[0.1, 0.5, 0.3, 0.9], 2), vec![3, 1]);
        assert_eq!(worst(&[0.1, f64::NAN, 0.3], 1), vec![1]);
        assert_eq!(worst(&[0.1], 3), vec![0]);
    }
}

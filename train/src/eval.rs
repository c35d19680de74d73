//! Evaluation: how well each method predicts poses it never saw (HZY11 Table 2 protocol).
//!
//! Errors are RMS vertex distances with the rest pose's largest bounding-box side scaled to 1.
//! Rows, from no deformation to the floors of each layer:
//!
//! - `rest`: the rest pose itself (no deformation);
//! - `oracle`: bone transforms fitted directly to the held-out pose with the rig's weights
//!   fixed: the floor of the bone layer;
//! - `oracle-rotations`: those fitted rotations, translations solved by FKY08 eq. 11 from the
//!   pose's control points: the floor of every rotation predictor;
//! - `rbf`, `global`, `local-geometry`, `local-pose`, `local`: the predictors
//!   ([`crate::regress::Method`]).
//!
//! Two protocols: a held-out test set (trained once on the training set), and leave-one-out
//! over the training set, where the held-out pose is removed from everything, the bone fit
//! included.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::runtime::predictor::Predictor;
use crease_core::runtime::skin::{BonePalette, RigidTransform, SkinWeights, skin_lbs};

use crate::bones::{self, IterationStat};
use crate::pipeline::{self, TrainError, TrainInput, TrainOptions, TrainedBase};
use crate::regress::{Method, RegressOptions};
use crate::select::{self, Candidate};

/// Gauss–Seidel sweeps of the oracle's transform fit.
const ORACLE_PASSES: usize = 12;

/// Per-method error statistics over the evaluated frames.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct MethodStats {
    /// Mean of the per-frame RMS errors.
    pub rms_mean: f64,
    /// Largest per-frame RMS error.
    pub rms_max: f64,
    /// Microseconds per frame of the method's run-time path (0 for rows without one).
    pub us_per_frame: f64,
    /// Per-frame RMS errors, in frame order.
    pub frames: Vec<f64>,
    /// With model selection, the candidate chosen for each training run (one per fold).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub selected: Vec<Candidate>,
}

/// One table: method name -> statistics.
pub type EvalTable = BTreeMap<String, MethodStats>;

/// The row order of printed tables.
pub const ROWS: [&str; 8] = [
    "rest",
    "oracle",
    "oracle-rotations",
    "rbf",
    "global",
    "local-geometry",
    "local-pose",
    "local",
];

/// Options of an evaluation.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Training (bones, controls, regression defaults).
    pub train: TrainOptions,
    /// Methods to compare.
    pub methods: Vec<Method>,
    /// Translation-solve beta (FKY08 eq. 11) of the oracle rows, and of the methods unless
    /// `train.select` chooses it.
    pub beta: f32,
}

/// Frames of one held-out set: names and positions.
#[derive(Clone, Copy, Debug)]
pub struct HeldOut<'a> {
    /// Frame names (for reports).
    pub names: &'a [String],
    /// Frame positions.
    pub frames: &'a [&'a [Vec3]],
}

/// RMS vertex distance, normalised by `scale` (the rest pose's largest bounding-box side).
pub fn rms_normalized(a: &[Vec3], b: &[Vec3], scale: f32) -> f64 {
    let sse: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length_squared() as f64)
        .sum();
    (sse / a.len().max(1) as f64).sqrt() / scale as f64
}

/// Trains on `train` once and evaluates every row on `test`.
pub fn evaluate_test(
    train: TrainInput<'_>,
    test: HeldOut<'_>,
    options: &EvalOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<EvalTable, TrainError> {
    let base = pipeline::train_base(train, &options.train, progress)?;
    let mut table = EvalTable::new();
    evaluate_frames(&base, train.frames, test.frames, options, &mut table)?;
    Ok(table)
}

/// Leave-one-out over the training examples but the rest pose (frame 0): each fold trains on
/// the others, bones included, and evaluates the held-out one. `on_fold(i, n)` reports progress.
pub fn evaluate_loo(
    train: TrainInput<'_>,
    options: &EvalOptions,
    on_fold: &mut dyn FnMut(usize, usize),
) -> Result<EvalTable, TrainError> {
    let n = train.frames.len();
    let mut table = EvalTable::new();
    for held in 1..n {
        on_fold(held, n - 1);
        let frames: Vec<&[Vec3]> = (0..n)
            .filter(|&i| i != held)
            .map(|i| train.frames[i])
            .collect();
        let names: Vec<String> = (0..n)
            .filter(|&i| i != held)
            .map(|i| train.names[i].clone())
            .collect();
        let input = TrainInput {
            rest: train.rest,
            frames: &frames,
            names: &names,
        };
        let base = pipeline::train_base(input, &options.train, &mut |_| {})?;
        evaluate_frames(&base, &frames, &[train.frames[held]], options, &mut table)?;
    }
    Ok(table)
}

/// Appends the errors of `frames` under every row to `table` (statistics recomputed).
fn evaluate_frames(
    base: &TrainedBase,
    train_frames: &[&[Vec3]],
    frames: &[&[Vec3]],
    options: &EvalOptions,
    table: &mut EvalTable,
) -> Result<(), TrainError> {
    let rest = &base.rig.rest;
    let scale = rest.bbox_diagonal_scale();
    let controls_of = |f: &[Vec3]| -> Vec<Vec3> {
        base.control_vertices
            .iter()
            .map(|&v| f[v as usize])
            .collect()
    };
    let mut out = vec![Vec3::ZERO; rest.vertex_count()];

    // rest
    for f in frames {
        push(
            table,
            "rest",
            rms_normalized(&rest.positions, f, scale),
            0.0,
        );
    }

    // oracle and oracle-rotations: share one predictor (the regressors are not used).
    let any = base.model(
        &RegressOptions {
            method: Method::Global,
            ..options.train.regress.clone()
        },
        options.beta,
    );
    let predictor = Predictor::new(Arc::new(any), Some(options.beta))
        .map_err(|e| TrainError::Controls(e.to_string()))?;
    let mut ctx = predictor.new_context();
    for f in frames {
        let fitted = oracle_transforms(rest, &base.rig.skin, base.rig.bone_count, f);
        skin_into(rest, &base.rig.skin, &fitted, &mut out);
        push(table, "oracle", rms_normalized(&out, f, scale), 0.0);
        let rotations: Vec<Quat> = fitted.iter().map(|t| t.rotation).collect();
        let t = Instant::now();
        predictor
            .solve_with_rotations(&mut ctx, &rotations, &controls_of(f))
            .and_then(|()| predictor.skin(&mut ctx))
            .map_err(|e| TrainError::Controls(e.to_string()))?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        push(
            table,
            "oracle-rotations",
            rms_normalized(ctx.positions(), f, scale),
            us,
        );
    }

    // the predictors
    for &method in &options.methods {
        let regress = RegressOptions {
            method,
            ..options.train.regress.clone()
        };
        let (regress, beta) = match &options.train.select {
            Some(grid) => {
                let s = select::select(base, train_frames, &regress, grid)?;
                table
                    .entry(method.name().to_string())
                    .or_default()
                    .selected
                    .push(s.best.clone());
                (s.apply(&regress), s.best.beta)
            }
            None => (regress, options.beta),
        };
        let model = base.model(&regress, beta);
        let predictor = Predictor::new(Arc::new(model), Some(beta))
            .map_err(|e| TrainError::Controls(e.to_string()))?;
        let mut ctx = predictor.new_context();
        for f in frames {
            let controls = controls_of(f);
            let t = Instant::now();
            let got = predictor
                .predict(&mut ctx, &controls, None)
                .map_err(|e| TrainError::Controls(e.to_string()))?;
            let us = t.elapsed().as_secs_f64() * 1e6;
            let e = rms_normalized(got, f, scale);
            push(table, method.name(), e, us);
        }
    }
    Ok(())
}

fn push(table: &mut EvalTable, row: &str, rms: f64, us: f64) {
    let s = table.entry(row.to_string()).or_default();
    let n = s.frames.len() as f64;
    s.frames.push(rms);
    s.rms_mean = (s.rms_mean * n + rms) / (n + 1.0);
    s.rms_max = s.rms_max.max(rms);
    s.us_per_frame = (s.us_per_frame * n + us) / (n + 1.0);
}

/// Bone transforms fitted to `frame` with the weights fixed: each bone starts from the Kabsch
/// fit of its weighted vertices, then SSDR's transform sweeps refine all of them together.
pub fn oracle_transforms(
    rest: &Mesh,
    skin: &SkinWeights,
    bone_count: usize,
    frame: &[Vec3],
) -> Vec<RigidTransform> {
    let init = bones::weighted_kabsch_per_bone(rest, skin, bone_count, frame);
    bones::fit_frame_transforms(rest, skin, &init, frame, ORACLE_PASSES).unwrap_or(init)
}

fn skin_into(rest: &Mesh, skin: &SkinWeights, transforms: &[RigidTransform], out: &mut [Vec3]) {
    let palette = BonePalette::from_transforms(transforms);
    skin_lbs(&rest.positions, skin, &palette, out).expect("sizes agree by construction");
}

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
//! Every row with a run-time path (`oracle-rotations`, each method, each `METHOD+refine`) also
//! gets a `ROW+dqs` row beside it (issue 22): the same bone transforms skinned with dual
//! quaternions (Kavan et al. 2007; FKY08 §6 skins so on the GPU) instead of LBS. The bones are
//! fitted for LBS (SSDR minimises the examples' LBS error) and eq. 11 solves the translations
//! for LBS (FKY08 §5 replaces DQS by LBS there to keep the solve linear), so the DQS rows show
//! what that approximation costs on each set.
//!
//! Two protocols: a held-out test set (trained once on the training set), and leave-one-out
//! over the training set, where the held-out pose is removed from everything, the bone fit
//! included.
//!
//! **With detailed examples** ([`evaluate_test_layers`], [`evaluate_loo_layers`]; HZY11 Table 2
//! and Figs. 5, 8) every predictor row also gets the detail layer (pose-dependent, from the
//! control points) on its predicted base, and the row carries `base_rms_mean` (the base mesh,
//! as `rms_mean`), `detail_rms_mean` (the full detailed output) and `crease_rms_mean` (the
//! detailed output on the crease regions: the [`CREASE_FRACTION`] of detailed vertices whose
//! displacement varies most over the training examples). The detailed ground truth of a pose
//! is its detailed example resampled on the subdivided true base, `S B + h n` with `h` found by
//! the ray casts of training: every point of it lies on the detailed surface (closest point
//! for the rare fallbacks), in one-to-one correspondence with the output. A base error of a
//! few millimetres swamps sub-millimetre detail in those two, so each row also carries
//! `crease_h_rms_mean`: the error of its displacements `h` alone on the crease regions. Extra
//! rows:
//!
//! - `static-detail`: the base of [`DETAIL_BASELINE_METHOD`] with the rest pose's displacements
//!   in every pose (HZY11 Fig. 8a);
//! - `cascaded-detail`: that base with displacements regressed from its predicted bone
//!   rotations instead of the control points (HZY11 Fig. 5c);
//! - `true-base`, `true-base-static`: the true base with pose-dependent or static detail,
//!   which isolates the detail layer from the base layer's error.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::predictor::{FrameContext, Predictor, Refinement};
use crease_core::runtime::skin::{BonePalette, RigidTransform, SkinWeights, Skinning, skin_lbs};

use crease_core::model::{DetailLayer, TrainedModel};
use crease_core::runtime::detail::DetailSynth;
use crease_core::runtime::displacement::{DetailInput, DetailRegressor};

use crate::base::{TrainError, TrainInput, TrainOptions, TrainedBase};
use crate::bones::{self, IterationStat};
use crate::detail::layer::{self as detail_layer, DetailFrames, DetailOptions};
pub use crate::metrics::rms_normalized;
use crate::pipeline;
use crate::regress::{Method, RegressOptions};
use crate::select;
use crate::selection::Candidate;

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
    /// With detailed examples: mean per-frame RMS of the base mesh (= `rms_mean`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub base_rms_mean: Option<f64>,
    /// With detailed examples: mean per-frame RMS of the detailed output against the detailed
    /// ground truth (module docs).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail_rms_mean: Option<f64>,
    /// With detailed examples: the same on the crease regions only.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crease_rms_mean: Option<f64>,
    /// With detailed examples: the RMS error of the displacements `h` alone on the crease
    /// regions (the detail layer's own error, whatever the base did).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub crease_h_rms_mean: Option<f64>,
    /// Per-frame detailed RMS errors, in frame order.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub detail_frames: Vec<f64>,
    /// Per-frame crease-region RMS errors, in frame order.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub crease_frames: Vec<f64>,
}

/// One table: method name -> statistics.
pub type EvalTable = BTreeMap<String, MethodStats>;

/// The rows of `table` in the order of [`ROWS`], each row's `+dqs` row after it, then its
/// `+refine` and `+refine+dqs` rows, then any other rows (the refinement's baselines) in name
/// order.
pub fn rows(table: &EvalTable) -> Vec<&str> {
    let mut out: Vec<&str> = Vec::new();
    for row in ROWS {
        for suffix in ["", DQS_SUFFIX, "+refine", "+refine+dqs"] {
            if let Some((k, _)) = table.get_key_value(&format!("{row}{suffix}")) {
                out.push(k);
            }
        }
    }
    for k in table.keys() {
        if !out.contains(&k.as_str()) {
            out.push(k);
        }
    }
    out
}

/// The row order of printed tables.
pub const ROWS: [&str; 12] = [
    "rest",
    "oracle",
    "oracle-rotations",
    "rbf",
    "global",
    "local-geometry",
    "local-pose",
    "local",
    "static-detail",
    "cascaded-detail",
    "true-base",
    "true-base-static",
];

/// The suffix of a row's dual-quaternion twin (module docs).
pub const DQS_SUFFIX: &str = "+dqs";

/// Fraction of detailed vertices that make the crease regions (module docs).
pub const CREASE_FRACTION: f64 = 0.05;

/// The base method of the `static-detail` and `cascaded-detail` rows (HZY11 compares detail
/// models on its own, local, base); the last evaluated method when it is not evaluated.
pub const DETAIL_BASELINE_METHOD: Method = Method::Local;

/// Detailed examples of an evaluation (module docs).
#[derive(Clone, Copy, Debug)]
pub struct DetailEval<'a> {
    /// The detailed version of every training frame.
    pub train: DetailFrames<'a>,
    /// The detailed version of every held-out frame ([`evaluate_test_layers`] only).
    pub test: Option<DetailFrames<'a>>,
    /// Subdivision, ray distance, kernel.
    pub options: &'a DetailOptions,
}

/// What a fold's detail rows need: the three regressors, the evaluated frames' ground truth,
/// the crease regions and a synthesis.
struct FoldDetail<'a> {
    levels: u32,
    pose: DetailRegressor,
    fixed: DetailRegressor,
    cascaded: DetailRegressor,
    /// `S B + h n` of each evaluated frame.
    truth: &'a [Truth],
    /// The crease-region vertices, from this fold's training displacements.
    crease: Vec<u32>,
    synth: DetailSynth,
}

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
    /// Issue 20's bone-level refinement: when set, every method also gets a `METHOD+refine`
    /// row (its rotations refined with the regression as the prior), and the table a
    /// `refine-from-rest` row (the control points alone, from the rest rotations, no prior),
    /// a `nearest` row (the nearest training example's rotations, eq. 11 alone) and a
    /// `nearest+refine` row (refined from those, with them as the prior).
    pub refine: Option<Refinement>,
}

/// Frames of one held-out set: names and positions.
#[derive(Clone, Copy, Debug)]
pub struct HeldOut<'a> {
    /// Frame names (for reports).
    pub names: &'a [String],
    /// Frame positions.
    pub frames: &'a [&'a [Vec3]],
}

/// Trains on `train` once and evaluates every row on `test`.
pub fn evaluate_test(
    train: TrainInput<'_>,
    test: HeldOut<'_>,
    options: &EvalOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<EvalTable, TrainError> {
    evaluate_test_layers(train, test, None, options, progress)
}

/// [`evaluate_test`] with the detail layer when `detail` gives the detailed examples of both
/// sets (module docs).
pub fn evaluate_test_layers(
    train: TrainInput<'_>,
    test: HeldOut<'_>,
    detail: Option<DetailEval<'_>>,
    options: &EvalOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<EvalTable, TrainError> {
    let base = pipeline::train_base(train, &options.train, progress)?;
    let mut table = EvalTable::new();
    let prepared = match detail {
        Some(d) => {
            let test_frames = d.test.ok_or_else(|| {
                TrainError::Detail(detail_layer::DetailTrainError::Shape(
                    "no detailed version of the test frames".into(),
                ))
            })?;
            Some(PreparedDetail::new(
                train,
                d,
                Some((test.frames, test_frames)),
            )?)
        }
        None => None,
    };
    let fold = match &prepared {
        Some(p) => Some(p.fold(&base, None, &p.test_truth)?),
        None => None,
    };
    evaluate_frames(&base, train.frames, test.frames, options, fold, &mut table)?;
    Ok(table)
}

/// The detailed ground truth of one pose: `S B + h n` and its `h`.
struct Truth {
    positions: Vec<Vec3>,
    h: Vec<f32>,
}

/// The detail data shared by the folds: the synthesis, every training frame's `h` and ground
/// truth, and the ground truth of the test frames.
struct PreparedDetail<'a> {
    options: &'a DetailOptions,
    synth: DetailSynth,
    train_h: Vec<Vec<f32>>,
    /// `S B + h n` of every training frame (leave-one-out's ground truth).
    train_truth: Vec<Truth>,
    test_truth: Vec<Truth>,
}

impl<'a> PreparedDetail<'a> {
    fn new(
        train: TrainInput<'_>,
        detail: DetailEval<'a>,
        test: Option<(&[&[Vec3]], DetailFrames<'_>)>,
    ) -> Result<Self, TrainError> {
        let options = detail.options;
        let mut synth = DetailSynth::from_mesh(train.rest, options.levels)
            .map_err(detail_layer::DetailTrainError::from)?;
        let max_distance = options.max_distance * train.rest.bbox_diagonal_scale();
        let (train_h, _) = detail_layer::resample(
            &mut synth,
            train.frames,
            detail.train,
            max_distance,
            |_, _| {},
        )?;
        let truth = |synth: &mut DetailSynth, frames: &[&[Vec3]], h: &[Vec<f32>]| {
            frames
                .iter()
                .zip(h)
                .map(|(f, h)| {
                    let mut positions = vec![Vec3::ZERO; synth.vertex_count()];
                    synth.synthesize(f, h, &mut positions).map(|()| Truth {
                        positions,
                        h: h.clone(),
                    })
                })
                .collect::<Result<Vec<_>, _>>()
                .map_err(detail_layer::DetailTrainError::from)
        };
        let train_truth = truth(&mut synth, train.frames, &train_h)?;
        let test_truth = match test {
            Some((frames, detailed)) => {
                let (h, _) =
                    detail_layer::resample(&mut synth, frames, detailed, max_distance, |_, _| {})?;
                truth(&mut synth, frames, &h)?
            }
            None => Vec::new(),
        };
        Ok(Self {
            options,
            synth,
            train_h,
            train_truth,
            test_truth,
        })
    }

    /// The regressors and crease regions of a fold trained on every training frame but `held`
    /// (the held-out pose takes no part in either).
    fn fold<'t>(
        &'t self,
        base: &TrainedBase,
        held: Option<usize>,
        truth: &'t [Truth],
    ) -> Result<FoldDetail<'t>, TrainError> {
        let h: Vec<&[f32]> = self
            .train_h
            .iter()
            .enumerate()
            .filter(|&(i, _)| Some(i) != held)
            .map(|(_, h)| h.as_slice())
            .collect();
        let fit = |input: DetailInput| -> Result<DetailRegressor, TrainError> {
            let x = detail_layer::inputs(input, &base.example_controls, &base.rotations);
            let d_in = x.len() / h.len().max(1);
            let options = DetailOptions {
                input,
                ..self.options.clone()
            };
            detail_layer::fit(&h, &x, d_in, &options).map_err(|e| TrainError::Detail(e.into()))
        };
        let pose = fit(DetailInput::Controls)?;
        let fixed = DetailRegressor::fixed(DetailInput::Controls, pose.d_in, h[0].to_vec());
        Ok(FoldDetail {
            levels: self.options.levels,
            cascaded: fit(DetailInput::Rotations)?,
            pose,
            fixed,
            truth,
            crease: detail_layer::crease_vertices(&h, CREASE_FRACTION),
            synth: self.synth.clone(),
        })
    }
}

/// The training set of leave-one-out fold `held`: every example but that one, in order (the
/// rest pose, frame 0, is never held out). [`evaluate_loo`] trains each fold on it, and so
/// does anything that retrains a fold to show it (the CLI's report).
#[derive(Clone, Debug)]
pub struct LooFold<'a> {
    /// The held-out example's index in the training set.
    pub held: usize,
    /// The other examples' frames.
    pub frames: Vec<&'a [Vec3]>,
    /// Their names.
    pub names: Vec<String>,
}

impl<'a> LooFold<'a> {
    /// Fold `held` of `train`.
    pub fn new(train: TrainInput<'a>, held: usize) -> Self {
        let n = train.frames.len();
        Self {
            held,
            frames: (0..n)
                .filter(|&i| i != held)
                .map(|i| train.frames[i])
                .collect(),
            names: (0..n)
                .filter(|&i| i != held)
                .map(|i| train.names[i].clone())
                .collect(),
        }
    }

    /// The fold's training input on `rest`.
    pub fn input<'b>(&'b self, rest: &'b Mesh) -> TrainInput<'b> {
        TrainInput {
            rest,
            frames: &self.frames,
            names: &self.names,
        }
    }
}

/// Leave-one-out over the training examples but the rest pose (frame 0): each fold trains on
/// the others, bones included, and evaluates the held-out one. `on_fold(i, n)` reports progress.
pub fn evaluate_loo(
    train: TrainInput<'_>,
    options: &EvalOptions,
    on_fold: &mut dyn FnMut(usize, usize),
) -> Result<EvalTable, TrainError> {
    evaluate_loo_layers(train, None, options, on_fold)
}

/// [`evaluate_loo`] with the detail layer when `detail` gives the detailed training examples:
/// each fold's detail regressors are refitted without the held-out pose.
pub fn evaluate_loo_layers(
    train: TrainInput<'_>,
    detail: Option<DetailEval<'_>>,
    options: &EvalOptions,
    on_fold: &mut dyn FnMut(usize, usize),
) -> Result<EvalTable, TrainError> {
    let n = train.frames.len();
    let mut table = EvalTable::new();
    let prepared = match detail {
        Some(d) => Some(PreparedDetail::new(train, d, None)?),
        None => None,
    };
    for held in 1..n {
        on_fold(held, n - 1);
        let fold = LooFold::new(train, held);
        let frames = &fold.frames;
        let base = pipeline::train_base(fold.input(train.rest), &options.train, &mut |_| {})?;
        let fold = match &prepared {
            Some(p) => Some(p.fold(&base, Some(held), &p.train_truth[held..=held])?),
            None => None,
        };
        evaluate_frames(
            &base,
            frames,
            &[train.frames[held]],
            options,
            fold,
            &mut table,
        )?;
    }
    Ok(table)
}

/// Appends the errors of `frames` under every row to `table` (statistics recomputed).
fn evaluate_frames(
    base: &TrainedBase,
    train_frames: &[&[Vec3]],
    frames: &[&[Vec3]],
    options: &EvalOptions,
    mut detail: Option<FoldDetail<'_>>,
    table: &mut EvalTable,
) -> Result<(), TrainError> {
    let rest = &base.rig.rest;
    let scale = rest.bbox_diagonal_scale();
    let controls_of = |f: &[Vec3]| control_positions(base, f);
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
            .map_err(|e| TrainError::Controls(e.to_string()))?;
        let us = t.elapsed().as_secs_f64() * 1e6;
        push_both_skinnings(table, "oracle-rotations", &predictor, &mut ctx, f, us)?;
    }

    // the detail layer on the true base
    if let Some(d) = detail.as_mut() {
        let mut xi = vec![0.0; d.pose.example_count()];
        let mut h = vec![0.0; d.synth.vertex_count()];
        let mut out = vec![Vec3::ZERO; d.synth.vertex_count()];
        for (k, f) in frames.iter().enumerate() {
            let x: Vec<f32> = controls_of(f).iter().flat_map(|p| p.to_array()).collect();
            for (row, r) in [("true-base", &d.pose), ("true-base-static", &d.fixed)] {
                r.predict(&x, &mut xi, &mut h);
                d.synth
                    .synthesize(f, &h, &mut out)
                    .map_err(|e| TrainError::Detail(e.into()))?;
                push(table, row, 0.0, 0.0);
                push_detail(table, row, 0.0, &out, &h, &d.truth[k], &d.crease, scale);
            }
        }
    }

    // the predictors
    let baseline = if options.methods.contains(&DETAIL_BASELINE_METHOD) {
        Some(DETAIL_BASELINE_METHOD)
    } else {
        options.methods.last().copied()
    };
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
        let mut model = base.model(&regress, beta);
        if let Some(d) = &detail {
            model.detail = Some(DetailLayer {
                levels: d.levels,
                regressor: d.pose.clone(),
            });
        }
        let model = Arc::new(model);
        if let Some(refine) = options.refine {
            let mut rows = vec![(format!("{}+refine", method.name()), refine)];
            if Some(method) == options.methods.first().copied() {
                let from_rest = Refinement {
                    from_rest: true,
                    ..refine
                };
                rows.push(("refine-from-rest".to_owned(), from_rest));
            }
            for (row, refine) in rows {
                let mut predictor = Predictor::new(Arc::clone(&model), Some(beta))
                    .map_err(|e| TrainError::Controls(e.to_string()))?;
                predictor.set_refinement(Some(refine));
                let mut ctx = predictor.new_context();
                let dqs = !refine.from_rest;
                for f in frames {
                    let t = Instant::now();
                    predictor
                        .predict_transforms(&mut ctx, &controls_of(f), None)
                        .map_err(|e| TrainError::Controls(e.to_string()))?;
                    let us = t.elapsed().as_secs_f64() * 1e6;
                    if dqs {
                        push_both_skinnings(table, &row, &predictor, &mut ctx, f, us)?;
                    } else {
                        let us = us + skin_timed(&predictor, &mut ctx, Skinning::Lbs)?;
                        push(table, &row, rms_normalized(ctx.positions(), f, scale), us);
                    }
                }
            }
            if Some(method) == options.methods.first().copied() {
                nearest_rows(base, &model, beta, refine, frames, table)?;
            }
        }
        let predictor =
            Predictor::new(model, Some(beta)).map_err(|e| TrainError::Controls(e.to_string()))?;
        let mut ctx = predictor.new_context();
        for (k, f) in frames.iter().enumerate() {
            let controls = controls_of(f);
            let t = Instant::now();
            predictor
                .predict_transforms(&mut ctx, &controls, None)
                .map_err(|e| TrainError::Controls(e.to_string()))?;
            let us = t.elapsed().as_secs_f64() * 1e6;
            // LBS last: the detail rows below build on the LBS base in the context.
            let e = push_both_skinnings(table, method.name(), &predictor, &mut ctx, f, us)?;
            let Some(d) = &detail else { continue };
            let mut rows = vec![(method.name(), &d.pose)];
            if Some(method) == baseline {
                rows.push(("static-detail", &d.fixed));
                rows.push(("cascaded-detail", &d.cascaded));
            }
            for (row, r) in rows {
                predictor
                    .predict_detail_with(&mut ctx, r)
                    .map_err(|e| TrainError::Controls(e.to_string()))?;
                if row != method.name() {
                    push(table, row, e, 0.0);
                }
                let (out, h) = (ctx.detail_positions(), ctx.displacements());
                push_detail(table, row, e, out, h, &d.truth[k], &d.crease, scale);
            }
        }
    }
    Ok(())
}

/// Skins the context's transforms (found in `transforms_us`) with DQS, then with LBS, and adds
/// the frame to `row+dqs` and `row`; returns the LBS error. The context is left with the LBS
/// mesh.
fn push_both_skinnings(
    table: &mut EvalTable,
    row: &str,
    predictor: &Predictor,
    ctx: &mut FrameContext,
    truth: &[Vec3],
    transforms_us: f64,
) -> Result<f64, TrainError> {
    let scale = predictor.model().rig.rest.bbox_diagonal_scale();
    let us = transforms_us + skin_timed(predictor, ctx, Skinning::Dqs)?;
    let e = rms_normalized(ctx.positions(), truth, scale);
    push(table, &format!("{row}{DQS_SUFFIX}"), e, us);
    let us = transforms_us + skin_timed(predictor, ctx, Skinning::Lbs)?;
    let e = rms_normalized(ctx.positions(), truth, scale);
    push(table, row, e, us);
    Ok(e)
}

/// Skins the context's transforms with `skinning`; the microseconds it took.
fn skin_timed(
    predictor: &Predictor,
    ctx: &mut FrameContext,
    skinning: Skinning,
) -> Result<f64, TrainError> {
    let t = Instant::now();
    predictor
        .skin_with(ctx, skinning)
        .map_err(|e| TrainError::Controls(e.to_string()))?;
    Ok(t.elapsed().as_secs_f64() * 1e6)
}

/// The `nearest` and `nearest+refine` rows (issue 20's extrapolating baselines): every frame
/// starts from the rotations of the training example whose control points are nearest
/// (Euclidean, over all control points), then `nearest` solves eq. 11 with them and
/// `nearest+refine` refines from them with them as the prior.
fn nearest_rows(
    base: &TrainedBase,
    model: &Arc<TrainedModel>,
    beta: f32,
    refine: Refinement,
    frames: &[&[Vec3]],
    table: &mut EvalTable,
) -> Result<(), TrainError> {
    let rest = &base.rig.rest;
    let scale = rest.bbox_diagonal_scale();
    let err = |e: crease_core::predictor::PredictError| TrainError::Controls(e.to_string());
    let mut refined = Predictor::new(Arc::clone(model), Some(beta)).map_err(err)?;
    refined.set_refinement(Some(refine));
    let mut ctx = refined.new_context();
    for f in frames {
        let controls = control_positions(base, f);
        let t = Instant::now();
        let nearest = base
            .example_controls
            .iter()
            .map(|example| -> f32 {
                example
                    .iter()
                    .zip(&controls)
                    .map(|(a, b)| a.distance_squared(*b))
                    .sum()
            })
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(k, _)| k)
            .ok_or_else(|| TrainError::Controls("no training examples".into()))?;
        let start = &base.rotations[nearest];
        let search_us = t.elapsed().as_secs_f64() * 1e6;
        for row in ["nearest", "nearest+refine"] {
            let t = Instant::now();
            if row == "nearest" {
                refined.solve_with_rotations(&mut ctx, start, &controls)
            } else {
                refined.refine_from(&mut ctx, start, &controls)
            }
            .and_then(|()| refined.skin(&mut ctx))
            .map_err(err)?;
            let us = search_us + t.elapsed().as_secs_f64() * 1e6;
            push(table, row, rms_normalized(ctx.positions(), f, scale), us);
        }
    }
    Ok(())
}

/// The control points' positions in `frame`, in model order.
fn control_positions(base: &TrainedBase, frame: &[Vec3]) -> Vec<Vec3> {
    base.control_vertices
        .iter()
        .map(|&v| frame[v as usize])
        .collect()
}

/// Adds a frame's detailed errors to `row`: its base error `base`, the full and crease-region
/// RMS of `out` against the truth, and the crease-region RMS of its displacements `h`.
#[allow(clippy::too_many_arguments)]
fn push_detail(
    table: &mut EvalTable,
    row: &str,
    base: f64,
    out: &[Vec3],
    h: &[f32],
    truth: &Truth,
    crease: &[u32],
    scale: f32,
) {
    let detail = rms_normalized(out, &truth.positions, scale);
    let rms = |sq: &dyn Fn(usize) -> f64| {
        let sse: f64 = crease.iter().map(|&v| sq(v as usize)).sum();
        (sse / crease.len().max(1) as f64).sqrt() / f64::from(scale)
    };
    let creases = rms(&|v| f64::from((out[v] - truth.positions[v]).length_squared()));
    let displacement = rms(&|v| f64::from(h[v] - truth.h[v]).powi(2));
    let s = table.entry(row.to_string()).or_default();
    let n = s.detail_frames.len() as f64;
    let mean = |old: Option<f64>, x: f64| Some((old.unwrap_or(0.0) * n + x) / (n + 1.0));
    s.base_rms_mean = mean(s.base_rms_mean, base);
    s.detail_rms_mean = mean(s.detail_rms_mean, detail);
    s.crease_rms_mean = mean(s.crease_rms_mean, creases);
    s.crease_h_rms_mean = mean(s.crease_h_rms_mean, displacement);
    s.detail_frames.push(detail);
    s.crease_frames.push(creases);
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

//! `crease train` as a function: examples in, [`TrainedModel`] out. Its inputs, options,
//! errors and report live in [`crate::base`] (re-exported here).
//!
//! 1. proxy bones and weights ([`crate::bones`]);
//! 2. control points: given, or automatic ([`crate::controls`]);
//! 3. rotation regressors of the chosen method ([`crate::regress`]), the bones grouped by a
//!    coarse rig fitted beside the fine one when asked ([`crate::group_rig`]);
//! 4. the edge skin of the translation solver ([`crate::edges`]): by default the vector edge
//!    skin (its ridge cross-validated), or FKY08 eq. 10's scalar weights;
//! 5. with detailed examples ([`train_layers`]), the detail layer
//!    ([`crate::detail::layer`]: subdivide, resample, regress; HZY11 §4, §5.2).

use std::time::Instant;

use crease_core::glam::{Quat, Vec3};
use crease_core::model::{Rig, RigExample, TrainedModel};
use crease_core::runtime::edge_skin::EdgeSkin;

pub use crate::base::{
    ControlSpec, EdgeModel, GroupRigReport, TrainError, TrainInput, TrainOptions, TrainReport,
    TrainedBase,
};
use crate::bones::{self, FitInput, IterationStat};
use crate::controls;
use crate::coverage;
use crate::detail::layer::{self as detail_layer, DetailFrames};
use crate::edges;
use crate::group_rig;
use crate::regress::{Method, RegressOptions};
use crate::select;
use crate::selection::ControlCoverage;

/// Trains a model's base layer. `progress` sees the bone fit's steps.
pub fn train(
    input: TrainInput<'_>,
    options: &TrainOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<(TrainedModel, TrainReport), TrainError> {
    train_layers(input, None, options, progress, &mut |_, _| {})
}

/// Trains both layers: the base layer as [`train`] does and, when `detailed` gives the
/// detailed version of every example, the detail layer on top (`options.detail`).
/// `detail_progress(done, total)` follows the detailed examples' resampling.
pub fn train_layers(
    input: TrainInput<'_>,
    detailed: Option<DetailFrames<'_>>,
    options: &TrainOptions,
    progress: &mut dyn FnMut(&IterationStat),
    detail_progress: &mut dyn FnMut(usize, usize),
) -> Result<(TrainedModel, TrainReport), TrainError> {
    train_layers_with(
        input,
        detailed,
        options,
        TrainProgress {
            fit: progress,
            detail: detail_progress,
            select: &|_, _| {},
        },
    )
}

/// The progress callbacks of [`train_layers_with`].
pub struct TrainProgress<'a> {
    /// The bone fit's steps.
    pub fit: &'a mut dyn FnMut(&IterationStat),
    /// `(done, total)` of the detailed examples' resampling.
    pub detail: &'a mut dyn FnMut(usize, usize),
    /// `(done, folds)` of model selection's leave-one-out folds (from worker threads).
    pub select: &'a (dyn Fn(usize, usize) + Sync),
}

impl std::fmt::Debug for TrainProgress<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TrainProgress")
    }
}

/// [`train_layers`] that also reports model selection's progress.
pub fn train_layers_with(
    input: TrainInput<'_>,
    detailed: Option<DetailFrames<'_>>,
    options: &TrainOptions,
    progress: TrainProgress<'_>,
) -> Result<(TrainedModel, TrainReport), TrainError> {
    let TrainProgress {
        fit: progress,
        detail: detail_progress,
        select: select_progress,
    } = progress;
    let mut base = train_base(input, options, progress)?;
    let t = Instant::now();
    let (regress, beta) = match &options.select {
        Some(grid) => {
            let s = select::select_with_progress(
                &base,
                input.frames,
                &options.regress,
                grid,
                select_progress,
            )?;
            let chosen = (s.apply(&options.regress), s.best.beta);
            base.report.selection = Some(s);
            chosen
        }
        None => (options.regress.clone(), options.beta),
    };
    let mut model = base.model(&regress, beta);
    if let Some(names) = &options.control_names
        && names.len() == model.controls.len()
    {
        for (c, name) in model.controls.iter_mut().zip(names) {
            c.name.clone_from(name);
        }
    }
    base.report.regress_seconds = t.elapsed().as_secs_f64();
    base.report.seconds += base.report.regress_seconds;
    if options.coverage && input.frames.len() >= 3 {
        base.report.coverage = Some(measure_coverage(
            &base,
            input.frames,
            &regress,
            beta,
            &options.control_curve,
        )?);
    }
    if let Some(detailed) = detailed {
        let (layer, report, _) = detail_layer::train(
            input.rest,
            input.frames,
            detailed,
            &base.example_controls,
            &base.rotations,
            &options.detail,
            detail_progress,
        )?;
        base.report.seconds += report.extract_seconds + report.fit_seconds;
        base.report.detail = Some(report);
        model.detail = Some(layer);
    }
    Ok((model, base.report))
}

/// [`coverage`] of `base`'s control points with the chosen regression: the undetermined
/// bones, and the curve at `counts`.
fn measure_coverage(
    base: &TrainedBase,
    frames: &[&[Vec3]],
    regress: &RegressOptions,
    beta: f32,
    counts: &[usize],
) -> Result<ControlCoverage, TrainError> {
    let t = Instant::now();
    let bones = coverage::undetermined(base, regress)?;
    let (curve, curve_stopped) = coverage::control_curve(base, frames, regress, beta, counts);
    Ok(ControlCoverage {
        curve,
        curve_stopped,
        bones,
        seconds: t.elapsed().as_secs_f64(),
    })
}

/// Fits everything but the regressors (see [`TrainedBase`]).
pub fn train_base(
    input: TrainInput<'_>,
    options: &TrainOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<TrainedBase, TrainError> {
    let start = Instant::now();
    if input.frames.len() < 2 {
        return Err(TrainError::TooFewExamples(input.frames.len()));
    }
    let fit = bones::fit(
        FitInput {
            rest: input.rest,
            frames: input.frames,
            rest_frame: Some(0),
        },
        &options.fit,
        progress,
    )?;

    let t = Instant::now();
    let control_vertices = match &options.controls {
        ControlSpec::Vertices(v) => {
            if let Some(&bad) = v.iter().find(|&&i| i as usize >= input.rest.vertex_count()) {
                return Err(TrainError::Controls(format!(
                    "vertex {bad} out of range (the mesh has {})",
                    input.rest.vertex_count()
                )));
            }
            v.clone()
        }
        ControlSpec::Auto(count) => controls::auto_control_points(input.rest, input.frames, *count)
            .map_err(|e| TrainError::Controls(e.to_string()))?,
        ControlSpec::Select(count) => {
            controls::auto_control_points(input.rest, input.frames, *count)
                .map_err(|e| TrainError::Controls(e.to_string()))?
        }
    };
    if control_vertices.is_empty() {
        return Err(TrainError::Controls("none given".into()));
    }
    let controls_seconds = t.elapsed().as_secs_f64();

    let rotations: Vec<Vec<Quat>> = fit
        .transforms
        .iter()
        .map(|frame| frame.iter().map(|x| x.rotation).collect())
        .collect();
    let example_controls: Vec<Vec<Vec3>> = input
        .frames
        .iter()
        .map(|f| control_vertices.iter().map(|&v| f[v as usize]).collect())
        .collect();

    let t = Instant::now();
    let mesh_edges = input.rest.edges();
    let edge_k = options
        .edge_influences
        .unwrap_or(options.fit.max_influences);
    let (edge_skin, edge_vectors) = match options.edge_model {
        EdgeModel::Scalar => {
            let weights = edges::try_fit_edge_weights(
                &input.rest.positions,
                &mesh_edges,
                input.frames,
                &rotations,
                &fit.skin,
                edge_k,
            )?;
            let skin = EdgeSkin::from_weights(&input.rest.positions, &mesh_edges, &weights)
                .map_err(edges::EdgeWeightError::from)?;
            (skin, None)
        }
        EdgeModel::Vector { ridge } => {
            let (skin, report) = edges::fit_edge_vectors(
                &input.rest.positions,
                &mesh_edges,
                input.frames,
                &rotations,
                &fit.skin,
                edge_k,
                ridge,
            )?;
            (skin, Some(report))
        }
    };
    let edges_seconds = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let group_rig = match options.group_bones {
        Some(count) if count < fit.bone_count => Some(group_rig::fit(
            input.rest,
            input.frames,
            &fit.skin,
            fit.bone_count,
            &options.fit,
            count,
            // Its steps report as the fine fit's do, with its own bone count.
            &mut *progress,
        )?),
        _ => None,
    };
    let group_rig_report = group_rig.as_ref().map(|g| GroupRigReport {
        bones: g.bone_count,
        fit_rms: g.fit_rms,
        seconds: t.elapsed().as_secs_f64(),
    });

    let rig = Rig {
        rest: input.rest.clone(),
        bone_count: fit.bone_count,
        skin: fit.skin,
        examples: input
            .names
            .iter()
            .zip(fit.transforms)
            .map(|(name, transforms)| RigExample {
                name: name.clone(),
                transforms,
            })
            .collect(),
        fit_rms: Some(fit.report.rms_normalized as f32),
    };
    let report = TrainReport {
        fit: fit.report,
        controls_seconds,
        regress_seconds: 0.0,
        edges_seconds,
        edge_vectors,
        selection: None,
        control_selection: None,
        detail: None,
        group_rig: group_rig_report,
        coverage: None,
        seconds: start.elapsed().as_secs_f64(),
    };
    let mut base = TrainedBase {
        rig,
        control_vertices,
        example_controls,
        rotations,
        edges: mesh_edges,
        edge_skin,
        group_rig,
        report,
    };
    if let ControlSpec::Select(count) = options.controls {
        let pool = controls::auto_control_points(
            input.rest,
            input.frames,
            count.saturating_mul(2).min(input.rest.vertex_count()),
        )
        .map_err(|e| TrainError::Controls(e.to_string()))?;
        // Scored with the global model whatever the method: the search is about which points
        // carry the pose, the cheapest model answers it, and train and eval then agree.
        let scoring = RegressOptions {
            method: Method::Global,
            ..options.regress.clone()
        };
        let sel = select::select_controls(
            &base,
            input.frames,
            &base.control_vertices,
            &pool,
            &scoring,
            options.beta,
        )?;
        base.example_controls = input
            .frames
            .iter()
            .map(|f| sel.chosen.iter().map(|&v| f[v as usize]).collect())
            .collect();
        base.control_vertices = sel.chosen.clone();
        base.report.control_selection = Some(sel);
        base.report.seconds = start.elapsed().as_secs_f64();
    }
    Ok(base)
}

//! `crease train` as a function: examples in, [`TrainedModel`] out.
//!
//! 1. proxy bones and weights ([`crate::bones`]);
//! 2. control points: given, or automatic ([`crate::controls`]);
//! 3. rotation regressors of the chosen method ([`crate::regress`]);
//! 4. the edge skin of the translation solver ([`crate::edges`]): by default the vector edge
//!    skin (its ridge cross-validated), or FKY08 eq. 10's scalar weights;
//! 5. with detailed examples ([`train_layers`]), the detail layer
//!    ([`crate::detail::layer`]: subdivide, resample, regress; HZY11 §4, §5.2).

use std::time::Instant;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::model::{ControlPoint, Rig, RigExample, TrainedModel};
use crease_core::runtime::edge_skin::EdgeSkin;

use crate::bones::{self, FitInput, FitOptions, FitReport, IterationStat};
use crate::controls;
use crate::detail::layer::{
    self as detail_layer, DetailFrames, DetailOptions, DetailReport, DetailTrainError,
};
use crate::edges;
use crate::regress::{self, Method, RegressInput, RegressOptions};
use crate::select::{self, SelectGrid, Selection};

/// Where the control points come from.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlSpec {
    /// These vertex indices (from a manifest or the command line).
    Vertices(Vec<u32>),
    /// Chosen automatically: this many (PCA + varimax, FKY08 §3).
    Auto(usize),
    /// This many: the `Auto` choice improved by swaps with twice as many PCA + varimax
    /// representatives, scored by leave-one-out inside the training set
    /// ([`select::select_controls`]).
    Select(usize),
}

/// Options of [`train`].
#[derive(Clone, Debug)]
pub struct TrainOptions {
    /// Proxy-bone fit.
    pub fit: FitOptions,
    /// Control points.
    pub controls: ControlSpec,
    /// Names of the control points (e.g. a manifest's `control_point_names`), used when there
    /// is one per chosen point; otherwise they are named `c0`, `c1`, ...
    pub control_names: Option<Vec<String>>,
    /// Regression.
    pub regress: RegressOptions,
    /// Bones per edge in the edge skin; defaults to the vertex K.
    pub edge_influences: Option<usize>,
    /// The edge skin of the translation solver.
    pub edge_model: EdgeModel,
    /// Default beta stored in the model (FKY08 eq. 11; HZY11 Fig. 11: about 3 for keyframing,
    /// 0.3 for noisy mocap).
    pub beta: f32,
    /// Choose the kernel, its regularisation and beta by leave-one-out inside the training set
    /// over this grid ([`crate::select`]), overriding `regress.kernel`, the KCCA `kappa` (RBF
    /// ridge) and `beta`.
    pub select: Option<SelectGrid>,
    /// The detail layer, trained when [`train_layers`] gets detailed examples.
    pub detail: DetailOptions,
}

impl Default for TrainOptions {
    fn default() -> Self {
        Self {
            fit: FitOptions::default(),
            controls: ControlSpec::Auto(8),
            control_names: None,
            regress: RegressOptions::default(),
            edge_influences: None,
            edge_model: EdgeModel::default(),
            beta: 1.0,
            select: None,
            detail: DetailOptions::default(),
        }
    }
}

/// How the translation solver predicts edges (see `crease_core::runtime::edge_skin`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum EdgeModel {
    /// FKY08 eq. 10: scalar weights, `e^s = sum_b w^_b R_b e^0`.
    Scalar,
    /// Free rest-frame vectors per (edge, bone) on the endpoints' bones
    /// ([`edges::fit_edge_vectors`]); `ridge: None` cross-validates it.
    Vector {
        /// Relative ridge (`lambda = ridge * frames`).
        ridge: Option<f64>,
    },
}

impl Default for EdgeModel {
    fn default() -> Self {
        Self::Vector { ridge: None }
    }
}

/// Errors of [`train`].
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// The proxy-bone fit refused the input.
    #[error(transparent)]
    Fit(#[from] bones::FitError),
    /// Control points could not be chosen or are invalid.
    #[error("control points: {0}")]
    Controls(String),
    /// The edge skin could not be fitted.
    #[error("edge skin: {0}")]
    Edges(#[from] edges::EdgeWeightError),
    /// Model selection failed.
    #[error("model selection: {0}")]
    Select(String),
    /// Too few examples.
    #[error("need at least 2 examples (the rest pose and one more), got {0}")]
    TooFewExamples(usize),
    /// The detail layer could not be trained.
    #[error(transparent)]
    Detail(#[from] DetailTrainError),
}

/// Timings and reports of a training run.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TrainReport {
    /// The bone fit.
    pub fit: FitReport,
    /// Seconds choosing control points.
    pub controls_seconds: f64,
    /// Seconds fitting the rotation regressors.
    pub regress_seconds: f64,
    /// Seconds fitting the edge skin.
    pub edges_seconds: f64,
    /// The vector edge skin's ridge and its cross-validation (`None` for scalar weights).
    pub edge_vectors: Option<edges::EdgeVectorReport>,
    /// Model selection, when asked for (its time is part of `regress_seconds`).
    pub selection: Option<Selection>,
    /// Control-point selection, for [`ControlSpec::Select`] (its time is part of `seconds`).
    pub control_selection: Option<select::ControlSelection>,
    /// The detail layer, when trained (its time is part of `seconds`).
    pub detail: Option<DetailReport>,
    /// Total seconds.
    pub seconds: f64,
}

/// Examples to train on: a rest mesh and frames (the rest pose among them, as frame 0).
#[derive(Clone, Copy, Debug)]
pub struct TrainInput<'a> {
    /// Rest pose.
    pub rest: &'a Mesh,
    /// Example frames, rest pose first.
    pub frames: &'a [&'a [Vec3]],
    /// One name per frame.
    pub names: &'a [String],
}

/// Everything of a trained model but the rotation regressors: the part shared by all methods
/// (evaluation fits it once and compares methods on it).
#[derive(Clone, Debug)]
pub struct TrainedBase {
    /// The rig (rest, bones, weights, examples' transforms).
    pub rig: Rig,
    /// Control-point vertices.
    pub control_vertices: Vec<u32>,
    /// Per example, the control positions.
    pub example_controls: Vec<Vec<Vec3>>,
    /// Per example, per bone, rotations.
    pub rotations: Vec<Vec<Quat>>,
    /// Mesh edges and their weights (FKY08 eq. 10).
    pub edges: Vec<[u32; 2]>,
    /// The edge skin of the translation solver.
    pub edge_skin: EdgeSkin,
    /// Timings so far.
    pub report: TrainReport,
}

impl TrainedBase {
    /// Fits the rotation regressors of `options.method` and assembles the model.
    pub fn model(&self, options: &RegressOptions, beta: f32) -> TrainedModel {
        let rotations = regress::build_rotation_model(
            RegressInput {
                rest: &self.rig.rest,
                skin: &self.rig.skin,
                bone_count: self.rig.bone_count,
                control_vertices: &self.control_vertices,
                controls: &self.example_controls,
                rotations: &self.rotations,
            },
            options,
        );
        TrainedModel {
            rig: self.rig.clone(),
            controls: self
                .control_vertices
                .iter()
                .enumerate()
                .map(|(i, &vertex)| ControlPoint {
                    vertex,
                    name: format!("c{i}"),
                })
                .collect(),
            method: options.method.name().to_string(),
            rotations,
            edges: self.edges.clone(),
            edge_skin: self.edge_skin.clone(),
            beta,
            detail: None,
        }
    }
}

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
    let mut base = train_base(input, options, progress)?;
    let t = Instant::now();
    let (regress, beta) = match &options.select {
        Some(grid) => {
            let s = select::select(&base, input.frames, &options.regress, grid)?;
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
        seconds: start.elapsed().as_secs_f64(),
    };
    let mut base = TrainedBase {
        rig,
        control_vertices,
        example_controls,
        rotations,
        edges: mesh_edges,
        edge_skin,
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

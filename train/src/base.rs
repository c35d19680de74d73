//! The shared base of training: what goes in ([`TrainInput`], [`TrainOptions`]), what can go
//! wrong ([`TrainError`]), what comes out besides the model ([`TrainReport`]), and the part of a
//! model that every method shares ([`TrainedBase`]: bones, controls, edge skin), fitted once by
//! [`crate::pipeline::train_base`] and turned into a model per method by
//! [`TrainedBase::model`]. [`crate::select`], [`crate::pipeline`] and [`crate::eval`] all build
//! on it.

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::model::{ControlPoint, Rig, TrainedModel};
use crease_core::runtime::edge_skin::EdgeSkin;

use crate::bones::{self, FitOptions, FitReport};
use crate::detail::layer::{DetailOptions, DetailReport, DetailTrainError};
use crate::edges;
use crate::group_rig::GroupRig;
use crate::regress::{self, RegressInput, RegressOptions};
use crate::selection::{ControlCoverage, ControlSelection, SelectGrid, Selection};

/// Where the control points come from.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlSpec {
    /// These vertex indices (from a manifest or the command line).
    Vertices(Vec<u32>),
    /// Chosen automatically: this many (PCA + varimax, FKY08 §3).
    Auto(usize),
    /// This many: the `Auto` choice improved by swaps with twice as many PCA + varimax
    /// representatives, scored by leave-one-out inside the training set
    /// ([`crate::select::select_controls`]).
    Select(usize),
}

/// Options of [`crate::pipeline::train`].
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
    /// The detail layer, trained when [`crate::pipeline::train_layers`] gets detailed examples.
    pub detail: DetailOptions,
    /// For the geometry-local methods: group the bones by the control points of a coarse rig
    /// of this many bones fitted beside them ([`crate::group_rig`]); `None`, or not fewer than
    /// the rig's bones, keeps each bone's own nearest points (HZY11 §5.1.1).
    pub group_bones: Option<usize>,
    /// Measure the control points inside the training set after training
    /// ([`crate::coverage`]): the bones they leave undetermined, and the control-point curve
    /// at these counts of automatic points (none: no curve). Off by default (the library's
    /// callers, the demo's start among them, do not pay for it); `crease train` turns it on.
    pub coverage: bool,
    /// The counts of the control-point curve ([`TrainOptions::coverage`]).
    pub control_curve: Vec<usize>,
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
            group_bones: None,
            coverage: false,
            control_curve: Vec::new(),
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

/// Errors of [`crate::pipeline::train`].
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
    pub control_selection: Option<ControlSelection>,
    /// The detail layer, when trained (its time is part of `seconds`).
    pub detail: Option<DetailReport>,
    /// The coarse rig that groups the bones, when asked for (its time is part of `seconds`).
    pub group_rig: Option<GroupRigReport>,
    /// What [`crate::coverage`] measured of the control points, when
    /// [`TrainOptions::coverage`] is on.
    pub coverage: Option<ControlCoverage>,
    /// Total seconds.
    pub seconds: f64,
}

/// How the fit of the grouping rig went ([`TrainOptions::group_bones`]).
#[derive(Clone, Debug, serde::Serialize)]
pub struct GroupRigReport {
    /// Its bones.
    pub bones: usize,
    /// Its fit's RMS error (bbox largest side = 1).
    pub fit_rms: f64,
    /// Seconds fitting it.
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
    /// The coarse rig that groups the bones for the geometry-local methods, when asked for.
    pub group_rig: Option<GroupRig>,
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
                group_rig: self.group_rig.as_ref(),
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
            skinning: Default::default(),
        }
    }
}

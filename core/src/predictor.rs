//! The per-frame pipeline: control points in, skinned vertices out.
//!
//! ```text
//! controls (+ validity) -> hold last valid -> rotations (predict) -> translations (eq. 11)
//!                       -> bone palette -> LBS or DQS into the context's vertex buffer
//! [on request, for models with a detail layer]
//!   -> h = D xi(c) + b (displacement) -> S · base, normals, + h n (detail) into the context
//! ```
//!
//! The detail layer is a separate call ([`Predictor::predict_detail`]) after the base frame, so
//! a server synthesises it only while someone asked for it. Its buffers (~5 MB for a 150K-vertex
//! output) are allocated by the first detail frame of a context, never again.
//!
//! A [`Predictor`] is shared, immutable state (an `Arc` of the model plus the translation
//! system factored for one beta); a [`FrameContext`] holds everything one stream of frames
//! needs and is reused frame after frame, so nothing is allocated per frame.
//!
//! **Occluded control points.** A frame may mark control points invalid (a hidden marker). The
//! predictor then uses the last valid position of that point in this context (initially its
//! rest-pose position). A control coordinate that is NaN or infinite counts as invalid too, so
//! no frame ever produces a non-finite mesh.

use std::sync::{Arc, OnceLock};

use glam::{Quat, Vec3};

use crate::model::TrainedModel;
use crate::runtime::confidence::{Confidence, ConfidenceScratch};
use crate::runtime::detail::{DetailError, DetailSynth};
use crate::runtime::displacement::{BlockedRows, DetailInput, DetailRegressor, rotations_input};
use crate::runtime::predict::RotationScratch;
use crate::runtime::refine::{BoneRefiner, RefineScratch};
use crate::runtime::skin::{
    BonePalette, PackedSkin, RigidTransform, SkinError, Skinning, skin_dqs, skin_lbs_packed,
};
use crate::runtime::translations::{TranslationError, TranslationScratch, TranslationSolver};

/// What a frame got wrong.
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    /// The frame carries the wrong number of control points.
    #[error("expected {expected} control points, got {got}")]
    ControlCount {
        /// The model's control-point count.
        expected: usize,
        /// What the frame carried.
        got: usize,
    },
    /// The validity mask has the wrong length.
    #[error("validity mask has {got} entries, expected {expected}")]
    MaskLength {
        /// The model's control-point count.
        expected: usize,
        /// The mask's length.
        got: usize,
    },
    /// Given rotations of the wrong count (one per bone).
    #[error("expected {expected} bone rotations, got {got}")]
    RotationCount {
        /// The rig's bone count.
        expected: usize,
        /// How many were given.
        got: usize,
    },
    /// beta out of range.
    #[error("beta must be finite and > 0, got {0}")]
    Beta(f32),
    /// The translation system could not be built.
    #[error(transparent)]
    Translations(#[from] TranslationError),
    /// Skinning failed (model inconsistency; validated models cannot).
    #[error(transparent)]
    Skin(#[from] SkinError),
    /// Detail was asked of a model without a detail layer.
    #[error("the model has no detail layer (train it on detailed examples)")]
    NoDetailLayer,
    /// The detail layer's subdivision could not be built, or a buffer disagrees with it.
    #[error(transparent)]
    Detail(#[from] DetailError),
    /// A detail regressor does not fit this model.
    #[error("detail regressor: {0}")]
    DetailRegressor(String),
}

/// Shared per-model state of the per-frame pipeline.
#[derive(Debug)]
pub struct Predictor {
    model: Arc<TrainedModel>,
    /// The rig's skin weights packed once for the per-frame LBS ([`skin_lbs_packed`]).
    skin: PackedSkin,
    /// How [`Predictor::skin`] blends the bones (the model's default until
    /// [`Predictor::set_skinning`]).
    skinning: Skinning,
    solver: TranslationSolver,
    beta: f32,
    /// `S`, its topology and the blocked `D` for the detail layer, built by the first call
    /// that needs it (a predictor nobody asks for detail never builds it); the synthesis is
    /// cloned, buffers and all, into a context by its first detail frame, the topology shared.
    detail: OnceLock<Result<DetailRuntime, DetailError>>,
    /// The bone-level refinement after the regression, when switched on
    /// ([`Predictor::set_refinement`]).
    refine: Option<(BoneRefiner, Refinement)>,
    /// The scale of the per-frame confidence (`None` for a model of one example).
    confidence: Option<Confidence>,
}

/// The detail layer's per-frame structures, built from the model on its first detail frame:
/// the synthesis every context clones, and `D` in blocks of rows for the regression.
#[derive(Debug)]
struct DetailRuntime {
    synth: DetailSynth,
    d: BlockedRows,
}

/// The bone-level refinement's settings (`runtime::refine`, issue 20).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refinement {
    /// Local-global rounds per frame.
    pub iterations: usize,
    /// Weight of the regression prior, relative to each bone's data term, at confidence 1;
    /// it falls as `1 / confidence^2` as a frame leaves the training span, and a frame at an
    /// example (confidence 0) is not refined at all.
    pub strength: f32,
    /// Start from the rest rotations with no prior: the control points alone (a baseline).
    pub from_rest: bool,
}

impl Refinement {
    /// What rooms and `crease synth` refine with unless told otherwise (issue 42): 8 rounds
    /// with the regression prior at 1/100 of each bone's data term at confidence 1. On the
    /// horse-poses protocol (BENCHMARKS.md "Poses far from few examples") 8 rounds keep most of
    /// 20 rounds' gain at 2/5 of the cost: ~0.86 ms a frame on the 150-bone horse, 5% of a core
    /// per room at 60 Hz (a frame at an example, confidence 0, is left as the regression
    /// predicts it and costs nothing extra).
    pub const ROOM_DEFAULT: Refinement = Refinement {
        iterations: 8,
        strength: 0.01,
        from_rest: false,
    };

    /// The most iterations a room accepts (each costs about one translation solve and a pass
    /// over the bone pairs: ~105 µs on the 150-bone horse, BENCHMARKS.md 2026-12-07).
    pub const MAX_ITERATIONS: usize = 32;

    /// Checks settings a user sent: `1..=MAX_ITERATIONS` iterations, a finite strength > 0.
    ///
    /// # Errors
    /// What is wrong, naming the field and the value.
    pub fn validate(&self) -> Result<(), String> {
        if !(1..=Self::MAX_ITERATIONS).contains(&self.iterations) {
            return Err(format!(
                "iterations must be 1 to {}, got {}",
                Self::MAX_ITERATIONS,
                self.iterations
            ));
        }
        if !(self.strength.is_finite() && self.strength > 0.0) {
            return Err(format!(
                "strength must be finite and > 0, got {}",
                self.strength
            ));
        }
        Ok(())
    }
}

/// The detail layer's per-stream buffers.
#[derive(Clone, Debug)]
struct DetailFrame {
    synth: DetailSynth,
    /// The regressor's input (controls or rotations).
    x: Vec<f32>,
    /// Kernel vector.
    xi: Vec<f32>,
    /// Displacements.
    h: Vec<f32>,
    /// The detailed vertices.
    out: Vec<Vec3>,
}

/// Reusable per-stream buffers; one per room or per synthesis job.
#[derive(Clone, Debug)]
pub struct FrameContext {
    controls: Vec<Vec3>,
    rotation_scratch: RotationScratch,
    rotations: Vec<Quat>,
    translations: Vec<Vec3>,
    translation_scratch: TranslationScratch,
    transforms: Vec<RigidTransform>,
    palette: BonePalette,
    positions: Vec<Vec3>,
    held: usize,
    detail: Option<Box<DetailFrame>>,
    refine_scratch: RefineScratch,
    confidence: f32,
    confidence_scratch: ConfidenceScratch,
}

impl FrameContext {
    /// The bone transforms of the last frame.
    pub fn transforms(&self) -> &[RigidTransform] {
        &self.transforms
    }

    /// The skinned vertices of the last frame.
    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }

    /// The control positions the last frame used (occluded ones held).
    pub fn controls(&self) -> &[Vec3] {
        &self.controls
    }

    /// The last frame's distance from the training examples (`runtime::confidence`: 0 at an
    /// example, 1 as far as the farthest example is from its nearest neighbour).
    pub fn confidence(&self) -> f32 {
        self.confidence
    }

    /// How many control values were held (occluded or non-finite) in the last frame.
    pub fn held_controls(&self) -> usize {
        self.held
    }

    /// The displacements `h` of the last detail frame (empty before the first).
    pub fn displacements(&self) -> &[f32] {
        self.detail.as_deref().map_or(&[], |d| &d.h)
    }

    /// The detailed vertices of the last detail frame (empty before the first).
    pub fn detail_positions(&self) -> &[Vec3] {
        self.detail.as_deref().map_or(&[], |d| &d.out)
    }
}

impl Predictor {
    /// Factors the translation system for `beta` (the model's default when `None`).
    pub fn new(model: Arc<TrainedModel>, beta: Option<f32>) -> Result<Self, PredictError> {
        let beta = beta.unwrap_or(model.beta);
        check_beta(beta)?;
        let control_vertices: Vec<u32> = model.controls.iter().map(|c| c.vertex).collect();
        let solver = TranslationSolver::new(
            &model.rig.rest.positions,
            &model.edges,
            &model.rig.skin,
            &model.edge_skin,
            &control_vertices,
            model.rig.bone_count,
            beta,
        )?;
        let skin = PackedSkin::new(&model.rig.skin)?;
        let confidence = Confidence::new(&model.rotations);
        Ok(Self {
            skinning: model.skinning,
            model,
            skin,
            solver,
            beta,
            detail: OnceLock::new(),
            refine: None,
            confidence,
        })
    }

    /// Switches the bone-level refinement on (`Some`) or off. Builds its precomputed local step
    /// (a pass over the mesh's edges: setup, not a per-frame operation).
    pub fn set_refinement(&mut self, refinement: Option<Refinement>) {
        self.refine = refinement.map(|r| (self.build_refiner(), r));
    }

    /// Chooses how [`Predictor::skin`] blends the bones (issue 22; a model's default is
    /// [`TrainedModel::skinning`]). Free: nothing is rebuilt.
    pub fn set_skinning(&mut self, skinning: Skinning) {
        self.skinning = skinning;
    }

    /// How [`Predictor::skin`] blends the bones.
    pub fn skinning(&self) -> Skinning {
        self.skinning
    }

    /// The refinement's settings, when on.
    pub fn refinement(&self) -> Option<Refinement> {
        self.refine.as_ref().map(|(_, r)| *r)
    }

    fn build_refiner(&self) -> BoneRefiner {
        let m = &self.model;
        let control_vertices: Vec<u32> = m.controls.iter().map(|c| c.vertex).collect();
        BoneRefiner::new(
            &m.rig.rest.positions,
            &m.edges,
            &m.rig.skin,
            &m.edge_skin,
            &control_vertices,
            m.rig.bone_count,
            self.beta,
        )
    }

    /// The detail layer's synthesis: `Ok(None)` for a model without one; built on first use.
    fn detail_synth(&self) -> Result<Option<&DetailSynth>, PredictError> {
        Ok(self.detail_runtime()?.map(|d| &d.synth))
    }

    /// The detail layer's per-frame structures, built on first use.
    fn detail_runtime(&self) -> Result<Option<&DetailRuntime>, PredictError> {
        let Some(layer) = &self.model.detail else {
            return Ok(None);
        };
        let built = self.detail.get_or_init(|| {
            Ok(DetailRuntime {
                synth: DetailSynth::from_mesh(&self.model.rig.rest, layer.levels)?,
                d: BlockedRows::new(&layer.regressor),
            })
        });
        match built {
            Ok(d) => Ok(Some(d)),
            Err(e) => Err(e.clone().into()),
        }
    }

    /// The triangles of the detailed output (the subdivided base topology), when the model has
    /// a detail layer (`None` too if its subdivision cannot be built, which
    /// [`Predictor::predict_detail`] reports).
    pub fn detail_triangles(&self) -> Option<&[[u32; 3]]> {
        self.detail_synth()
            .ok()
            .flatten()
            .map(|d| d.subdivision().triangles())
    }

    /// Vertices of the detailed output, when the model has a detail layer (without building
    /// the subdivision).
    pub fn detail_vertex_count(&self) -> Option<usize> {
        self.model.detail_vertex_count()
    }

    /// The model.
    pub fn model(&self) -> &Arc<TrainedModel> {
        &self.model
    }

    /// The translation solver (FKY08 eq. 11) this predictor built for the model: its sizes
    /// are what a frame's solve costs.
    pub fn translation_solver(&self) -> &TranslationSolver {
        &self.solver
    }

    /// Current control-point weight of the translation solve.
    pub fn beta(&self) -> f32 {
        self.beta
    }

    /// Changes beta (refactors the translation system; not a per-frame operation).
    pub fn set_beta(&mut self, beta: f32) -> Result<(), PredictError> {
        check_beta(beta)?;
        self.solver.set_beta(beta)?;
        self.beta = beta;
        if let Some(r) = self.refinement() {
            self.refine = Some((self.build_refiner(), r));
        }
        Ok(())
    }

    /// A context with every buffer sized for this model; control points start at rest.
    pub fn new_context(&self) -> FrameContext {
        let m = &self.model;
        let bones = m.rig.bone_count;
        FrameContext {
            controls: m
                .controls
                .iter()
                .map(|c| m.rig.rest.positions[c.vertex as usize])
                .collect(),
            rotation_scratch: RotationScratch::default(),
            rotations: vec![Quat::IDENTITY; bones],
            translations: vec![Vec3::ZERO; bones],
            translation_scratch: self.solver.scratch(),
            transforms: vec![RigidTransform::IDENTITY; bones],
            palette: BonePalette::from_transforms(&vec![RigidTransform::IDENTITY; bones]),
            positions: m.rig.rest.positions.clone(),
            held: 0,
            detail: None,
            refine_scratch: self
                .refine
                .as_ref()
                .map(|(r, _)| r.scratch())
                .unwrap_or_default(),
            confidence: 0.0,
            confidence_scratch: ConfidenceScratch::default(),
        }
    }

    /// Control points -> bone transforms (rotations predicted, translations solved), into
    /// `ctx.transforms()`.
    pub fn predict_transforms(
        &self,
        ctx: &mut FrameContext,
        controls: &[Vec3],
        valid: Option<&[bool]>,
    ) -> Result<(), PredictError> {
        let n = self.check_control_count(controls)?;
        if let Some(mask) = valid
            && mask.len() != n
        {
            return Err(PredictError::MaskLength {
                expected: n,
                got: mask.len(),
            });
        }
        ctx.held = 0;
        for (i, (&c, held)) in controls.iter().zip(ctx.controls.iter_mut()).enumerate() {
            if c.is_finite() && valid.is_none_or(|m| m[i]) {
                *held = c;
            } else {
                ctx.held += 1;
            }
        }
        self.model
            .rotations
            .predict(&ctx.controls, &mut ctx.rotation_scratch, &mut ctx.rotations);
        self.place_rotations(ctx, true);
        Ok(())
    }

    /// The refinement started from (and pulled toward) the given rotations instead of the
    /// regression's: the `nearest+refine` row of the evaluation starts it from the nearest
    /// training example's. Without a refinement switched on, this is
    /// [`Predictor::solve_with_rotations`]. Occluded (non-finite) controls are held.
    pub fn refine_from(
        &self,
        ctx: &mut FrameContext,
        rotations: &[Quat],
        controls: &[Vec3],
    ) -> Result<(), PredictError> {
        self.set_rotations_and_controls(ctx, rotations, controls)?;
        self.place_rotations(ctx, false);
        Ok(())
    }

    /// The second half of a frame, from `ctx.rotations` (the regression's, or a given start)
    /// and `ctx.controls`: the confidence, then the refinement when on, else eq. 11 alone.
    /// `skip_at_examples`: a frame at an example (confidence 0) keeps the regression's
    /// rotations, which reproduce the example.
    fn place_rotations(&self, ctx: &mut FrameContext, skip_at_examples: bool) {
        ctx.confidence = self.confidence.as_ref().map_or(0.0, |c| {
            c.of(
                &self.model.rotations,
                &ctx.controls,
                &mut ctx.confidence_scratch,
            )
        });
        match &self.refine {
            Some((_, r)) if skip_at_examples && !r.from_rest && ctx.confidence == 0.0 => {
                self.solve_translations_into(ctx);
            }
            Some((refiner, r)) => {
                let strength = if r.from_rest {
                    ctx.rotations.fill(Quat::IDENTITY);
                    0.0
                } else {
                    // Confidence 0 (a given start exactly at an example's controls): the
                    // prior holds the start (an infinite weight's limit).
                    f64::from(r.strength) / f64::from(ctx.confidence.max(1e-6)).powi(2)
                };
                // On error (non-finite input, which the regressors never emit) the previous
                // translations stay, as in the plain solve.
                let _ = refiner.refine(
                    &self.solver,
                    &mut ctx.rotations,
                    None,
                    strength,
                    &ctx.controls,
                    r.iterations,
                    &mut ctx.refine_scratch,
                    &mut ctx.translations,
                );
                self.set_transforms(ctx);
            }
            None => self.solve_translations_into(ctx),
        }
    }

    /// The model's control-point count, when `controls` has it.
    fn check_control_count(&self, controls: &[Vec3]) -> Result<usize, PredictError> {
        let n = self.model.controls.len();
        if controls.len() != n {
            return Err(PredictError::ControlCount {
                expected: n,
                got: controls.len(),
            });
        }
        Ok(n)
    }

    fn set_rotations_and_controls(
        &self,
        ctx: &mut FrameContext,
        rotations: &[Quat],
        controls: &[Vec3],
    ) -> Result<(), PredictError> {
        self.check_control_count(controls)?;
        let bones = self.model.rig.bone_count;
        if rotations.len() != bones {
            return Err(PredictError::RotationCount {
                expected: bones,
                got: rotations.len(),
            });
        }
        ctx.rotations.copy_from_slice(rotations);
        for (held, &c) in ctx.controls.iter_mut().zip(controls) {
            if c.is_finite() {
                *held = c;
            }
        }
        Ok(())
    }

    /// Puts a recorded frame into `ctx`: its controls (as the prediction used them) and its
    /// bone transforms, as [`Predictor::predict_transforms`] would have left them, without
    /// predicting or solving. [`Predictor::skin`] and [`Predictor::predict_detail`] then give
    /// that frame's meshes: what `crease take export` does with a take's frames.
    ///
    /// # Errors
    /// [`PredictError::ControlCount`] / [`PredictError::RotationCount`] when the counts do not
    /// fit the model.
    pub fn load_frame(
        &self,
        ctx: &mut FrameContext,
        controls: &[Vec3],
        transforms: &[RigidTransform],
    ) -> Result<(), PredictError> {
        self.check_control_count(controls)?;
        if transforms.len() != self.model.rig.bone_count {
            return Err(PredictError::RotationCount {
                expected: self.model.rig.bone_count,
                got: transforms.len(),
            });
        }
        for (held, &c) in ctx.controls.iter_mut().zip(controls) {
            if c.is_finite() {
                *held = c;
            }
        }
        for (((r, t), out), x) in ctx
            .rotations
            .iter_mut()
            .zip(ctx.translations.iter_mut())
            .zip(ctx.transforms.iter_mut())
            .zip(transforms)
        {
            *r = x.rotation;
            *t = x.translation;
            *out = *x;
        }
        Ok(())
    }

    /// Given rotations (one per bone) and the context's current controls, solves translations
    /// (FKY08 eq. 11) and sets the context's transforms: the "oracle rotations" path of the
    /// evaluation and the second half of [`Predictor::predict_transforms`].
    pub fn solve_with_rotations(
        &self,
        ctx: &mut FrameContext,
        rotations: &[Quat],
        controls: &[Vec3],
    ) -> Result<(), PredictError> {
        self.set_rotations_and_controls(ctx, rotations, controls)?;
        self.solve_translations_into(ctx);
        Ok(())
    }

    fn solve_translations_into(&self, ctx: &mut FrameContext) {
        // On error (only non-finite rotations, which the regressors never emit) the previous
        // translations stay: a frame never produces NaN.
        let _ = self.solver.solve(
            &ctx.rotations,
            &ctx.controls,
            &mut ctx.translation_scratch,
            &mut ctx.translations,
        );
        self.set_transforms(ctx);
    }

    /// The context's transforms from its rotations and translations (a non-finite translation
    /// becomes zero: a frame never produces NaN).
    fn set_transforms(&self, ctx: &mut FrameContext) {
        for ((t, &q), &p) in ctx
            .transforms
            .iter_mut()
            .zip(&ctx.rotations)
            .zip(&ctx.translations)
        {
            *t = if p.is_finite() {
                RigidTransform {
                    rotation: q,
                    translation: p,
                }
            } else {
                RigidTransform {
                    rotation: q,
                    translation: Vec3::ZERO,
                }
            };
        }
    }

    /// Skins the rest mesh with the context's current transforms into `ctx.positions()`, as
    /// [`Predictor::skinning`] says.
    pub fn skin(&self, ctx: &mut FrameContext) -> Result<(), PredictError> {
        self.skin_with(ctx, self.skinning)
    }

    /// [`Predictor::skin`] with the given skinning, whatever the predictor's (the evaluation's
    /// `+dqs` rows): LBS (FKY08 §5's `v^s = sum_b w_b (R_b v^0 + t_b)`) on the packed skin, or
    /// DQS on the rig's weights (Kavan et al. 2007's dual quaternion linear blending, DLB: the
    /// weights' blend of the bones' unit dual quaternions, normalised; FKY08 §6 skins so on the
    /// GPU). Neither allocates. The translations come from eq. 11 either way, which FKY08 §5
    /// solves with LBS in place of DQS (to stay linear), so a DQS frame is that approximation.
    pub fn skin_with(
        &self,
        ctx: &mut FrameContext,
        skinning: Skinning,
    ) -> Result<(), PredictError> {
        ctx.palette.update(&ctx.transforms);
        let rest = &self.model.rig.rest.positions;
        match skinning {
            Skinning::Lbs => skin_lbs_packed(rest, &self.skin, &ctx.palette, &mut ctx.positions)?,
            Skinning::Dqs => {
                skin_dqs(rest, &self.model.rig.skin, &ctx.palette, &mut ctx.positions)?
            }
        }
        Ok(())
    }

    /// Rest vertex `v` skinned with the context's current transforms (LBS, FKY08 eq. 1,
    /// whatever [`Predictor::skinning`] says): the few vertices a caller needs without skinning
    /// the whole mesh (a palette stream's control residual; palette streams are LBS only).
    ///
    /// # Panics
    /// If `v` is not a rest vertex.
    pub fn skin_vertex(&self, ctx: &FrameContext, v: usize) -> Vec3 {
        let p = self.model.rig.rest.positions[v];
        let (bones, weights) = self.model.rig.skin.vertex(v);
        bones
            .iter()
            .zip(weights)
            .map(|(&b, &w)| w * ctx.transforms[b as usize].transform_point(p))
            .sum()
    }

    /// The whole frame: controls -> transforms -> skinned vertices.
    pub fn predict<'c>(
        &self,
        ctx: &'c mut FrameContext,
        controls: &[Vec3],
        valid: Option<&[bool]>,
    ) -> Result<&'c [Vec3], PredictError> {
        self.predict_transforms(ctx, controls, valid)?;
        self.skin(ctx)?;
        Ok(&ctx.positions)
    }

    /// The detail layer of the context's last frame (after [`Predictor::predict`]): the
    /// model's displacements `h(c)` on the subdivided base mesh (HZY11 eq. 4). The first call
    /// on a context allocates its detail buffers; later ones allocate nothing.
    ///
    /// # Errors
    /// [`PredictError::NoDetailLayer`] for a model without one.
    pub fn predict_detail<'c>(
        &self,
        ctx: &'c mut FrameContext,
    ) -> Result<&'c [Vec3], PredictError> {
        self.predict_detail_with(ctx, self.detail_regressor()?)
    }

    /// The model's detail regressor.
    fn detail_regressor(&self) -> Result<&DetailRegressor, PredictError> {
        Ok(&self
            .model
            .detail
            .as_ref()
            .ok_or(PredictError::NoDetailLayer)?
            .regressor)
    }

    /// The context's detail buffers for `regressor`, checked against the model and filled
    /// with the regressor's input of the last frame, the base positions, and the layer's
    /// per-frame structures.
    fn prepare_detail<'c>(
        &self,
        ctx: &'c mut FrameContext,
        regressor: &DetailRegressor,
    ) -> Result<(&'c mut DetailFrame, &'c [Vec3], &DetailRuntime), PredictError> {
        let runtime = self.detail_runtime()?.ok_or(PredictError::NoDetailLayer)?;
        let template = &runtime.synth;
        let d_in = self.detail_input_len(ctx, regressor, template.vertex_count())?;
        let frame = Self::detail_frame(
            &mut ctx.detail,
            &ctx.controls,
            &ctx.rotations,
            template,
            regressor,
            d_in,
        );
        Ok((frame, &ctx.positions, runtime))
    }

    /// [`Predictor::predict_detail`] with another regressor of the same layer (the evaluation's
    /// static and cascaded baselines).
    ///
    /// # Errors
    /// [`PredictError::NoDetailLayer`] for a model without one;
    /// [`PredictError::DetailRegressor`] when `regressor` has the wrong vertex count or input.
    pub fn predict_detail_with<'c>(
        &self,
        ctx: &'c mut FrameContext,
        regressor: &DetailRegressor,
    ) -> Result<&'c [Vec3], PredictError> {
        let (frame, base, runtime) = self.prepare_detail(ctx, regressor)?;
        // The model's own regressor in its blocked form (built once), another one as it is.
        let own =
            (self.model.detail.as_ref()).is_some_and(|l| std::ptr::eq(&l.regressor, regressor));
        let blocked = own.then_some(&runtime.d);
        let xi = &mut frame.xi[..regressor.example_count()];
        regressor.kernel_vector(&frame.x, xi);
        let xi = &*xi;
        // h = D xi + b regressed block by block inside the synthesis's last pass (one sweep of
        // D beside the positions it moves, HZY11 eq. 4).
        let rows = |first: usize, rows: &mut [f32]| match blocked {
            Some(d) => d.apply_rows(xi, first, rows),
            None => regressor.apply_rows(xi, first, rows),
        };
        frame
            .synth
            .synthesize_regressed(base, &rows, &mut frame.h, &mut frame.out)?;
        Ok(&frame.out)
    }

    /// The detail kernel vector `xi` of the context's last frame (after
    /// [`Predictor::predict_transforms`]; HZY11 eq. 4): what a palette stream's detail frame
    /// carries, without synthesising the detail layer. Allocates only on a context's first
    /// detail frame.
    ///
    /// # Errors
    /// [`PredictError::NoDetailLayer`] for a model without one; the regressor's
    /// [`PredictError::DetailRegressor`] when it does not fit the model.
    pub fn predict_detail_xi<'c>(
        &self,
        ctx: &'c mut FrameContext,
    ) -> Result<&'c [f32], PredictError> {
        let regressor = self.detail_regressor()?;
        let (frame, _, _) = self.prepare_detail(ctx, regressor)?;
        let n = regressor.example_count();
        regressor.kernel_vector(&frame.x, &mut frame.xi[..n]);
        Ok(&frame.xi[..n])
    }

    /// The rest of [`Predictor::predict_detail_with`]'s checks: `regressor` fits the detailed
    /// mesh (`nv` vertices) and the context's input; returns the input's dimension.
    fn detail_input_len(
        &self,
        ctx: &FrameContext,
        regressor: &DetailRegressor,
        nv: usize,
    ) -> Result<usize, PredictError> {
        if regressor.vertex_count() != nv {
            return Err(PredictError::DetailRegressor(format!(
                "{} displacement rows, the detailed mesh has {nv} vertices",
                regressor.vertex_count()
            )));
        }
        let d_in = match regressor.input {
            DetailInput::Controls => 3 * ctx.controls.len(),
            DetailInput::Rotations => 4 * ctx.rotations.len(),
        };
        if regressor.d_in != d_in {
            return Err(PredictError::DetailRegressor(format!(
                "input of dimension {} from {}, this model gives {d_in}",
                regressor.d_in,
                regressor.input.name()
            )));
        }
        Ok(d_in)
    }

    /// The context's detail buffers (made on its first detail frame) with the regressor's
    /// input of the last frame filled in.
    fn detail_frame<'c>(
        detail: &'c mut Option<Box<DetailFrame>>,
        controls: &[Vec3],
        rotations: &[Quat],
        template: &DetailSynth,
        regressor: &DetailRegressor,
        d_in: usize,
    ) -> &'c mut DetailFrame {
        let nv = template.vertex_count();
        let frame = detail.get_or_insert_with(|| {
            Box::new(DetailFrame {
                synth: template.clone(),
                x: Vec::new(),
                xi: Vec::new(),
                h: vec![0.0; nv],
                out: vec![Vec3::ZERO; nv],
            })
        });
        // Resized only when a regressor of another shape comes (evaluation), never per frame.
        frame.x.resize(d_in, 0.0);
        frame
            .xi
            .resize(regressor.example_count().max(frame.xi.len()), 0.0);
        match regressor.input {
            DetailInput::Controls => {
                for (x, c) in frame.x.chunks_exact_mut(3).zip(controls) {
                    x.copy_from_slice(&c.to_array());
                }
            }
            DetailInput::Rotations => rotations_input(rotations, &mut frame.x),
        }
        frame
    }
}

fn check_beta(beta: f32) -> Result<(), PredictError> {
    if beta.is_finite() && beta > 0.0 {
        Ok(())
    } else {
        Err(PredictError::Beta(beta))
    }
}

//! Model selection inside the training set: the regression kernel and its width, the KCCA
//! regularisation `kappa` (or the RBF ridge) and the translation weight `beta` (FKY08 eq. 11),
//! chosen by leave-one-out over the training examples, never by looking at a test set.
//!
//! Each candidate is scored by the quantity the user sees: the RMS vertex error of the whole
//! predicted mesh (rotations regressed without the held-out example, translations solved by
//! eq. 11 from its control points, LBS), normalised as [`crate::metrics`] does. The rig (bones,
//! weights, edge skin) is the one fitted on all training examples, held-out one included: the
//! selection is about the regression, and refitting the bones per fold (as `crease eval --loo`
//! does) would multiply its cost by the bone fit's. The rest pose (example 0) is never held
//! out: every model keeps it as its anchor.
//!
//! Cost: `kernels x kappas` regressions per fold (the betas share them: one factorisation per
//! beta, then a triangular solve per fold), folds in parallel.

use std::time::Instant;

use crease_core::glam::{Quat, Vec3};
use crease_core::runtime::predict::RotationScratch;
use crease_core::runtime::skin::{BonePalette, RigidTransform, skin_lbs};
use crease_core::runtime::translations::{TranslationScratch, TranslationSolver};

use crate::base::{TrainError, TrainedBase};
use crate::metrics::rms_normalized;
use crate::par;
use crate::regress::{self, KernelChoice, RegressInput, RegressOptions};
use crate::selection::with_choice;
pub use crate::selection::{Candidate, ControlSelection, SelectGrid, Selection};

/// Scores every candidate of `grid` for `options.method` by leave-one-out over `base`'s
/// examples (see the module docs). `frames` are the training meshes, rest pose first, as given
/// to [`crate::pipeline::train_base`].
pub fn select(
    base: &TrainedBase,
    frames: &[&[Vec3]],
    options: &RegressOptions,
    grid: &SelectGrid,
) -> Result<Selection, TrainError> {
    select_with_progress(base, frames, options, grid, &|_, _| {})
}

/// [`select`], calling `on_fold(done, folds)` as each leave-one-out fold finishes (from the
/// worker threads, in completion order).
pub fn select_with_progress(
    base: &TrainedBase,
    frames: &[&[Vec3]],
    options: &RegressOptions,
    grid: &SelectGrid,
    on_fold: &(dyn Fn(usize, usize) + Sync),
) -> Result<Selection, TrainError> {
    let start = Instant::now();
    if grid.kernels.is_empty() || grid.kappas.is_empty() || grid.betas.is_empty() {
        return Err(TrainError::Select("the candidate grid is empty".into()));
    }
    let candidates: Vec<(KernelChoice, f64)> = grid
        .kernels
        .iter()
        .flat_map(|&k| grid.kappas.iter().map(move |&kappa| (k, kappa)))
        .collect();
    let errors = loo_errors(
        base,
        &base.control_vertices,
        frames,
        options,
        &candidates,
        &grid.betas,
        on_fold,
    )?;
    let mut table = Vec::with_capacity(errors.len());
    for (c, &(kernel, kappa)) in candidates.iter().enumerate() {
        for (b, &beta) in grid.betas.iter().enumerate() {
            table.push(Candidate {
                kernel,
                kappa,
                beta,
                rms: errors[c * grid.betas.len() + b],
            });
        }
    }
    let best = table
        .iter()
        .filter(|c| c.rms.is_finite())
        .min_by(|a, b| a.rms.total_cmp(&b.rms))
        .cloned()
        .ok_or_else(|| TrainError::Select("no candidate gave a finite error".into()))?;
    Ok(Selection {
        best,
        table,
        seconds: start.elapsed().as_secs_f64(),
    })
}

/// Mean leave-one-out mesh error over the non-rest examples, per `(kernel, kappa)` of
/// `candidates` (major) and `beta` of `betas`, with the control points `controls` (the rig and
/// its edge skin from `base`); `on_fold(done, folds)` after each fold.
pub(crate) fn loo_errors(
    base: &TrainedBase,
    controls: &[u32],
    frames: &[&[Vec3]],
    options: &RegressOptions,
    candidates: &[(KernelChoice, f64)],
    betas: &[f32],
    on_fold: &(dyn Fn(usize, usize) + Sync),
) -> Result<Vec<f64>, TrainError> {
    let n = frames.len();
    if n < 3 {
        return Err(TrainError::Select(format!(
            "leave-one-out selection needs at least 3 examples, got {n}"
        )));
    }
    if let Some(b) = betas.iter().find(|b| !(b.is_finite() && **b >= 0.0)) {
        return Err(TrainError::Select(format!(
            "beta {b}: must be finite and >= 0"
        )));
    }
    let rig = &base.rig;
    let solvers = betas
        .iter()
        .map(|&beta| {
            TranslationSolver::new(
                &rig.rest.positions,
                &base.edges,
                &rig.skin,
                &base.edge_skin,
                controls,
                rig.bone_count,
                beta,
            )
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| TrainError::Select(format!("translation solver: {e}")))?;
    let scale = rig.rest.bbox_diagonal_scale();
    let example_controls: Vec<Vec<Vec3>> = frames
        .iter()
        .map(|f| controls.iter().map(|&v| f[v as usize]).collect())
        .collect();

    // Per fold (held-out example i >= 1): per (kernel, kappa), per beta, the error.
    let done = std::sync::atomic::AtomicUsize::new(0);
    let per_fold: Vec<Vec<f64>> = par::map_range(
        n - 1,
        || FoldScratch::new(rig.bone_count, rig.rest.vertex_count()),
        |s, f| {
            let held = f + 1;
            let keep: Vec<usize> = (0..n).filter(|&i| i != held).collect();
            let kept_controls: Vec<Vec<Vec3>> =
                keep.iter().map(|&i| example_controls[i].clone()).collect();
            let rotations: Vec<Vec<Quat>> =
                keep.iter().map(|&i| base.rotations[i].clone()).collect();
            let input = RegressInput {
                rest: &rig.rest,
                skin: &rig.skin,
                bone_count: rig.bone_count,
                control_vertices: controls,
                controls: &kept_controls,
                rotations: &rotations,
                group_rig: base.group_rig.as_ref(),
            };
            let target = frames[held];
            let ctl = &example_controls[held];
            let mut errors = Vec::with_capacity(candidates.len() * solvers.len());
            for &(kernel, kappa) in candidates {
                let o = with_choice(options, kernel, kappa);
                let model = regress::build_rotation_model(input, &o);
                model.predict(ctl, &mut s.rot_scratch, &mut s.rotations);
                for solver in &solvers {
                    errors.push(s.mesh_error(solver, rig, ctl, target, scale));
                }
            }
            on_fold(
                done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1,
                n - 1,
            );
            errors
        },
    );
    let folds = per_fold.len() as f64;
    Ok((0..candidates.len() * solvers.len())
        .map(|idx| per_fold.iter().map(|e| e[idx]).sum::<f64>() / folds)
        .collect())
}

/// Most passes of [`select_controls`]' swap search.
pub const CONTROL_SWAP_PASSES: usize = 12;

/// Improves the control set `start` by swaps with the candidates of `pool`: each pass scores
/// every `(member, candidate)` swap by the leave-one-out mesh error inside the training set
/// (same protocol as [`select`], with `options` and `beta` fixed) and applies the best one if
/// it lowers the error, for at most [`CONTROL_SWAP_PASSES`] passes. This replaces FKY08 §3's
/// interactive step ("we interactively choose n_c samples from these representative points"):
/// `start` and `pool` are PCA + varimax representatives ([`crate::controls`]), and the choice
/// among them is cross-validated instead of made by hand. The result is never worse than
/// `start` by this criterion.
///
/// Cost: per pass, `|start| x |pool \ start|` leave-one-out evaluations (each one translation
/// factorisation and one regression per fold).
pub fn select_controls(
    base: &TrainedBase,
    frames: &[&[Vec3]],
    start: &[u32],
    pool: &[u32],
    options: &RegressOptions,
    beta: f32,
) -> Result<ControlSelection, TrainError> {
    let t0 = Instant::now();
    if start.is_empty() {
        return Err(TrainError::Select("no starting control points".into()));
    }
    let candidate = [(options.kernel, options.kcca.kappa)];
    let score = |set: &[u32]| -> Result<f64, TrainError> {
        Ok(loo_errors(base, set, frames, options, &candidate, &[beta], &|_, _| {})?[0])
    };
    let mut chosen = start.to_vec();
    let mut current = score(&chosen)?;
    let mut errors = vec![current];
    let mut swaps = Vec::new();
    let mut trial = chosen.clone();
    for _ in 0..CONTROL_SWAP_PASSES {
        let mut best: Option<(f64, usize, u32)> = None;
        for slot in 0..chosen.len() {
            for &c in pool.iter().filter(|c| !chosen.contains(c)) {
                trial.copy_from_slice(&chosen);
                trial[slot] = c;
                let e = score(&trial)?;
                if e.is_finite() && e < current && best.is_none_or(|(b, _, _)| e < b) {
                    best = Some((e, slot, c));
                }
            }
        }
        let Some((e, slot, c)) = best else { break };
        swaps.push((chosen[slot], c));
        chosen[slot] = c;
        current = e;
        errors.push(e);
    }
    Ok(ControlSelection {
        chosen,
        errors,
        swaps,
        pool: pool.to_vec(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// Per-worker buffers of one fold.
struct FoldScratch {
    rot_scratch: RotationScratch,
    rotations: Vec<Quat>,
    translations: Vec<Vec3>,
    transforms: Vec<RigidTransform>,
    palette: BonePalette,
    solve: TranslationScratch,
    mesh: Vec<Vec3>,
}

impl FoldScratch {
    fn new(bones: usize, vertices: usize) -> Self {
        Self {
            rot_scratch: RotationScratch::default(),
            rotations: vec![Quat::IDENTITY; bones],
            translations: vec![Vec3::ZERO; bones],
            transforms: vec![RigidTransform::IDENTITY; bones],
            palette: BonePalette::default(),
            solve: TranslationScratch::default(),
            mesh: vec![Vec3::ZERO; vertices],
        }
    }

    /// Translations by eq. 11 for the predicted rotations, LBS, RMS against `target`.
    fn mesh_error(
        &mut self,
        solver: &TranslationSolver,
        rig: &crease_core::model::Rig,
        controls: &[Vec3],
        target: &[Vec3],
        scale: f32,
    ) -> f64 {
        if solver
            .solve(
                &self.rotations,
                controls,
                &mut self.solve,
                &mut self.translations,
            )
            .is_err()
        {
            return f64::INFINITY;
        }
        for ((t, &r), &x) in self
            .transforms
            .iter_mut()
            .zip(&self.rotations)
            .zip(&self.translations)
        {
            *t = RigidTransform::new(r, x);
        }
        self.palette.update(&self.transforms);
        match skin_lbs(
            &rig.rest.positions,
            &rig.skin,
            &self.palette,
            &mut self.mesh,
        ) {
            Ok(()) => rms_normalized(&self.mesh, target, scale),
            Err(_) => f64::INFINITY,
        }
    }
}

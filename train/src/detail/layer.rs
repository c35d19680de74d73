//! Training the whole detail layer (HZY11 §4, §5.2; DESIGN.md data flow steps 2 and 9): every
//! base example is Loop-subdivided (`S · B_i`, the run time's own [`DetailSynth`], so training
//! and synthesis use the same `S` and the same normals), its detailed example is resampled
//! along the subdivided normals ([`DisplacementTarget`]: `h_i`), and the regressor
//! `h(x) = D xi(x) + b` is fitted on the examples' inputs ([`super::regress::fit`]).
//!
//! The ray search is bounded by [`DetailOptions::max_distance`], a fraction of the rest mesh's
//! largest bounding-box side; rays that find nothing within it fall back to the closest
//! detailed point. The bound matters where surfaces touch: on the generated hand, rays of
//! 5 mm from a fingertip pressed into the palm hit the palm's skin 3-4 mm away, and those
//! spurious `h` outweighed the ~1 mm creases in the fit. The default, 0.75% (1.5 mm on the
//! 0.2 m hand), is a little deeper than the deepest crease the generator makes (1 mm).

use std::time::Instant;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::model::DetailLayer;
use crease_core::runtime::detail::DetailSynth;
use crease_core::runtime::displacement::{DetailInput, DetailRegressor, rotations_input};
use crease_core::runtime::kernel::Kernel;

use super::extract::{DetailError, DisplacementTarget, ExtractStats};
use super::regress::{self, DetailFitError};
use crate::kcca::KccaOptions;

/// Options of the detail layer.
#[derive(Clone, Debug)]
pub struct DetailOptions {
    /// Loop subdivision levels of `S` (1 or 2; the generated hand needs 2 for 150K vertices).
    pub levels: u32,
    /// Ray search distance as a fraction of the rest mesh's largest bounding-box side (module
    /// docs).
    pub max_distance: f32,
    /// Regression kernel; `None`: Gaussian of the default width (RMS spread of the inputs).
    pub kernel: Option<Kernel>,
    /// KCCA options (kappa).
    pub kcca: KccaOptions,
    /// What the regressor reads: the control points (HZY11 §5.2) or the bone rotations
    /// (the cascaded baseline, HZY11 Fig. 5c).
    pub input: DetailInput,
}

impl Default for DetailOptions {
    fn default() -> Self {
        Self {
            levels: 2,
            max_distance: 0.0075,
            kernel: None,
            kcca: KccaOptions::default(),
            input: DetailInput::Controls,
        }
    }
}

/// The detailed examples paired with the base examples: one detailed frame per base frame, in
/// the same order, sharing one topology (any resolution).
#[derive(Clone, Copy, Debug)]
pub struct DetailFrames<'a> {
    /// Detailed vertex positions, one slice per example.
    pub frames: &'a [&'a [Vec3]],
    /// The detailed triangles.
    pub triangles: &'a [[u32; 3]],
}

/// Errors of the detail layer's training.
#[derive(Debug, thiserror::Error)]
pub enum DetailTrainError {
    /// Resampling a detailed example failed (the example is named inside).
    #[error(transparent)]
    Extract(#[from] DetailError),
    /// The regression refused its input.
    #[error(transparent)]
    Fit(#[from] DetailFitError),
    /// The subdivision of the base topology failed.
    #[error(transparent)]
    Synth(#[from] crease_core::runtime::detail::DetailError),
    /// Counts disagree.
    #[error("detail layer: {0}")]
    Shape(String),
}

/// What training the detail layer did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct DetailReport {
    /// Subdivision levels.
    pub levels: u32,
    /// Detailed (subdivided) vertices.
    pub vertices: usize,
    /// The ray search distance, in model units.
    pub max_distance: f32,
    /// Ray hits and closest-point fallbacks over all examples, and the largest `|h|`.
    pub hits: usize,
    /// Closest-point fallbacks.
    pub fallbacks: usize,
    /// Largest `|h|`, in model units.
    pub max_abs_h: f32,
    /// Seconds subdividing and resampling.
    pub extract_seconds: f64,
    /// Seconds fitting the regressor.
    pub fit_seconds: f64,
}

/// The resampled displacements `h_i` of each base frame against its detailed frame
/// (module docs), with `synth` built on the base topology. `progress(done, total)` after each
/// example. The maximum distance is in model units.
pub fn resample(
    synth: &mut DetailSynth,
    base_frames: &[&[Vec3]],
    detailed: DetailFrames<'_>,
    max_distance: f32,
    mut progress: impl FnMut(usize, usize),
) -> Result<(Vec<Vec<f32>>, ExtractStats), DetailTrainError> {
    if base_frames.len() != detailed.frames.len() {
        return Err(DetailTrainError::Shape(format!(
            "{} detailed frames for {} base frames",
            detailed.frames.len(),
            base_frames.len()
        )));
    }
    let nv = synth.vertex_count();
    let zero = vec![0.0; nv];
    let mut high = vec![Vec3::ZERO; nv];
    let mut normals = Vec::with_capacity(nv);
    let mut stats = ExtractStats::default();
    let mut all = Vec::with_capacity(base_frames.len());
    for (example, (base, target)) in base_frames.iter().zip(detailed.frames).enumerate() {
        let wrap = |e| DetailError::Example {
            example,
            source: Box::new(e),
        };
        synth.synthesize(base, &zero, &mut high)?;
        let target = DisplacementTarget::new(target, detailed.triangles).map_err(wrap)?;
        let mut h = vec![0.0; nv];
        normals.clear();
        normals.extend(synth.normals().iter().map(|&n| Vec3::from(n)));
        let s = target
            .displacements(&high, &normals, max_distance, &mut h)
            .map_err(wrap)?;
        stats = stats.merge(s);
        all.push(h);
        progress(example + 1, base_frames.len());
    }
    Ok((all, stats))
}

/// The regressor inputs of the examples, `examples x d_in` row-major: the control positions
/// (`controls[l]`) or the bone rotations (`rotations[l]`, [`rotations_input`]).
pub fn inputs(
    input: DetailInput,
    controls: &[Vec<Vec3>],
    rotations: &[Vec<crease_core::glam::Quat>],
) -> Vec<f32> {
    match input {
        DetailInput::Controls => controls
            .iter()
            .flat_map(|c| c.iter().flat_map(|p| p.to_array()))
            .collect(),
        DetailInput::Rotations => rotations
            .iter()
            .flat_map(|r| {
                let mut x = vec![0.0; 4 * r.len()];
                rotations_input(r, &mut x);
                x
            })
            .collect(),
    }
}

/// Fits the detail layer's regressor on displacements `h` and inputs `x` (`h.len()` rows of
/// `d_in` values) with `options`' kernel and input.
pub fn fit<H: AsRef<[f32]>>(
    h: &[H],
    x: &[f32],
    d_in: usize,
    options: &DetailOptions,
) -> Result<DetailRegressor, DetailFitError> {
    regress::fit(options.input, x, d_in, h, options.kernel, &options.kcca)
}

/// Trains the detail layer on a base rest mesh, its example frames (rest first) and their
/// detailed versions; `controls`/`rotations` are the examples' control positions and fitted
/// bone rotations (the inputs, [`inputs`]). Returns the layer, its report and the resampled
/// `h_i` (the evaluation reuses them).
#[allow(clippy::too_many_arguments)]
pub fn train(
    rest: &Mesh,
    base_frames: &[&[Vec3]],
    detailed: DetailFrames<'_>,
    controls: &[Vec<Vec3>],
    rotations: &[Vec<crease_core::glam::Quat>],
    options: &DetailOptions,
    progress: impl FnMut(usize, usize),
) -> Result<(DetailLayer, DetailReport, Vec<Vec<f32>>), DetailTrainError> {
    let t = Instant::now();
    let mut synth = DetailSynth::from_mesh(rest, options.levels)?;
    let max_distance = options.max_distance * rest.bbox_diagonal_scale();
    let (h, stats) = resample(&mut synth, base_frames, detailed, max_distance, progress)?;
    let extract_seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let x = inputs(options.input, controls, rotations);
    let d_in = x.len() / h.len().max(1);
    let regressor = fit(&h, &x, d_in, options)?;
    let report = DetailReport {
        levels: options.levels,
        vertices: synth.vertex_count(),
        max_distance,
        hits: stats.hits,
        fallbacks: stats.fallbacks,
        max_abs_h: stats.max_abs,
        extract_seconds,
        fit_seconds: t.elapsed().as_secs_f64(),
    };
    Ok((
        DetailLayer {
            levels: options.levels,
            regressor,
        },
        report,
        h,
    ))
}

/// The crease regions of an evaluation: the `fraction` of detailed vertices whose `h` varies
/// most (max - min) over the training examples, ascending. Chosen from training data only.
pub fn crease_vertices<H: AsRef<[f32]>>(h: &[H], fraction: f64) -> Vec<u32> {
    let Some(first) = h.first().map(AsRef::as_ref) else {
        return Vec::new();
    };
    let mut spread: Vec<(f32, u32)> = (0..first.len())
        .map(|v| {
            let (lo, hi) = h
                .iter()
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, u), hl| {
                    let x = hl.as_ref()[v];
                    (l.min(x), u.max(x))
                });
            (hi - lo, v as u32)
        })
        .collect();
    spread.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    let count = ((first.len() as f64 * fraction).round() as usize).clamp(1, first.len());
    let mut out: Vec<u32> = spread[..count].iter().map(|&(_, v)| v).collect();
    out.sort_unstable();
    out
}

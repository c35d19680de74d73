//! What model selection searches and what it finds: the candidate grid of kernels, KCCA
//! regularisations and betas, the scored candidates, and the outcomes of choosing the regression
//! ([`crate::select::select`]) and the control points ([`crate::select::select_controls`]),
//! and what [`crate::coverage`] measures of the control points (the curve, undetermined bones).
//! Plain data, so the training options and reports ([`crate::base`]) can hold them without
//! depending on the search itself.

use crate::regress::{KernelChoice, Method, RegressOptions};

/// The candidates: every combination of `kernels x kappas x betas` is scored.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct SelectGrid {
    /// Regression kernels (Gaussian widths as multiples of the data's spread, polynomials).
    pub kernels: Vec<KernelChoice>,
    /// KCCA `kappa` ([`crate::kcca::KccaOptions::kappa`]); the RBF baseline uses it as its
    /// ridge.
    pub kappas: Vec<f64>,
    /// Translation weights `beta`.
    pub betas: Vec<f32>,
}

impl Default for SelectGrid {
    /// Gaussian widths 0.5–2 of the default, Gaussian plus linear (widths 1 and 2, linear
    /// weights 0.1 and 1), the quadratic and cubic polynomial kernels (FKY08 §7 uses both
    /// kinds), `kappa` 1e-4–1e-1, `beta` 0.3–10 (HZY11 Fig. 11's range).
    fn default() -> Self {
        let mut kernels: Vec<KernelChoice> = [0.5f32, 0.7, 1.0, 1.4, 2.0]
            .into_iter()
            .map(|scale| KernelChoice::Gaussian { scale })
            .collect();
        for scale in [1.0, 2.0] {
            kernels.extend([0.1, 1.0].map(|gamma| KernelChoice::GaussianLinear { scale, gamma }));
        }
        kernels.extend([2u32, 3].map(|degree| KernelChoice::Polynomial { c: 1.0, degree }));
        Self {
            kernels,
            kappas: vec![1e-4, 1e-3, 1e-2, 1e-1],
            betas: vec![0.3, 1.0, 3.0, 10.0],
        }
    }
}

/// One scored candidate.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Kernel.
    pub kernel: KernelChoice,
    /// KCCA `kappa` (RBF ridge).
    pub kappa: f64,
    /// Translation weight.
    pub beta: f32,
    /// Mean over the held-out examples of the normalised RMS vertex error.
    pub rms: f64,
}

/// The outcome of [`crate::select::select`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct Selection {
    /// The candidate with the lowest held-out error.
    pub best: Candidate,
    /// Every candidate, in grid order (kernel-major, then kappa, then beta).
    pub table: Vec<Candidate>,
    /// Wall time.
    pub seconds: f64,
}

impl Selection {
    /// `options` with the selected kernel and regularisation.
    pub fn apply(&self, options: &RegressOptions) -> RegressOptions {
        with_choice(options, self.best.kernel, self.best.kappa)
    }
}

/// `options` with `kernel` and `kappa` (the RBF ridge for [`Method::Rbf`]).
pub(crate) fn with_choice(
    options: &RegressOptions,
    kernel: KernelChoice,
    kappa: f64,
) -> RegressOptions {
    let mut o = options.clone();
    o.kernel = kernel;
    if o.method == Method::Rbf {
        o.rbf_ridge = kappa;
    } else {
        o.kcca.kappa = kappa;
    }
    o
}

/// The outcome of [`crate::select::select_controls`].
#[derive(Clone, Debug, serde::Serialize)]
pub struct ControlSelection {
    /// The chosen control vertices.
    pub chosen: Vec<u32>,
    /// The starting set's leave-one-out error, then the error after each accepted swap.
    pub errors: Vec<f64>,
    /// The accepted swaps, `(removed, added)`.
    pub swaps: Vec<(u32, u32)>,
    /// The candidate pool.
    pub pool: Vec<u32>,
    /// Wall time.
    pub seconds: f64,
}

/// One point of the control-point curve.
#[derive(Clone, Debug, serde::Serialize)]
pub struct CurvePoint {
    /// Number of automatic control points.
    pub count: usize,
    /// The control vertices chosen for it.
    pub controls: Vec<u32>,
    /// Mean leave-one-out RMS mesh error with them (bbox side = 1).
    pub rms: f64,
}

/// A connected group of bones the control points leave undetermined.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Region {
    /// Its bones.
    pub bones: Vec<u32>,
    /// The vertices whose heaviest bone is one of them.
    pub vertices: Vec<u32>,
    /// Their centroid in the rest pose.
    pub centroid: [f32; 3],
    /// The bones' mean spread over the examples, degrees.
    pub spread_deg: f64,
    /// The bones' mean leave-one-out rotation error, degrees.
    pub error_deg: f64,
}

/// What [`crate::coverage::undetermined`] measured.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Coverage {
    /// Per bone: mean angle to its rest rotation over the non-rest examples, degrees.
    pub spread_deg: Vec<f64>,
    /// Per bone: mean leave-one-out rotation error, degrees.
    pub error_deg: Vec<f64>,
    /// The undetermined regions, largest first.
    pub regions: Vec<Region>,
}

/// What `crease train` measured of its control points ([`crate::coverage`], issue 42).
#[derive(Clone, Debug, serde::Serialize)]
pub struct ControlCoverage {
    /// The control-point curve, one point per count asked for
    /// ([`crate::base::TrainOptions::control_curve`]) up to the first the automatic choice
    /// cannot give.
    pub curve: Vec<CurvePoint>,
    /// Why the curve stops before the last count asked for, if it does.
    pub curve_stopped: Option<String>,
    /// Per-bone spread and leave-one-out error with the model's own control points, and the
    /// regions they leave undetermined.
    pub bones: Coverage,
    /// Wall time.
    pub seconds: f64,
}

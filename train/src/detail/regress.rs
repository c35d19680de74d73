//! The detail regressor of HZY11 §5.2: per detailed vertex, the displacement `h` along the
//! normal of the subdivided base mesh as a function of the pose, fitted by kernel CCA with a
//! 1-D output per vertex, and collapsed into one dense matrix so the run time is one kernel
//! vector and one matrix-vector product for all vertices:
//!
//! ```text
//! h(x) = D xi(x) + b,    xi_l(x) = k(x, x_l),    D: vertices x examples       (HZY11 eq. 4)
//! ```
//!
//! The input `x` is the full control vector (HZY11 §5.2; [`DetailInput::Controls`]), or for
//! the cascaded baseline of HZY11 Fig. 5c the bone rotations the base layer predicts
//! ([`DetailInput::Rotations`]: unit quaternions, sign-aligned to the rest, concatenated). The
//! static baseline of HZY11 Fig. 8a ([`DetailModel::fixed`]) keeps the rest pose's
//! displacements in every pose.
//!
//! Each vertex is its own 1-D KCCA ([`fit_kcca_per_block`] with `block = 1`): with a single
//! output the canonical output direction is trivial and the fit is a kernel ridge with the
//! KCCA's linear recalibration (see [`crate::kcca`]); the centred kernel matrix is decomposed
//! once for all vertices.

use crease_core::runtime::kernel::Kernel;
use serde::{Deserialize, Serialize};

use crate::kcca::{KccaOptions, LinearModel, default_sigma, fit_kcca_per_block};

/// What the detail regressor reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetailInput {
    /// The full control vector (HZY11 §5.2).
    Controls,
    /// The predicted bone rotations (HZY11 Fig. 5c, "cascaded").
    Rotations,
}

/// A fitted detail layer: `h = D xi(x) + b` (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetailModel {
    /// What `x` is.
    pub input: DetailInput,
    /// The kernel of `xi`.
    pub kernel: Kernel,
    /// Training inputs, `n x d_in` row-major (the `x_l` of `xi`).
    pub examples: Vec<f32>,
    /// `D` (`vertices x n`) and `b`; `d_in` is the input dimension.
    pub model: LinearModel,
}

/// Errors of the detail fit.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DetailFitError {
    /// Inputs and displacements disagree in example count or a vector has the wrong length.
    #[error("detail fit: {0}")]
    Shape(String),
    /// A value is not finite.
    #[error("detail fit: {what} {index} is not finite")]
    NotFinite {
        /// Which array.
        what: &'static str,
        /// Flat index of the value.
        index: usize,
    },
}

impl DetailModel {
    /// Fits the detail regressor (module docs). `inputs` is `n x d_in` row-major, `h[l]` the
    /// displacements of example `l` (one per detailed vertex). A Gaussian kernel of width
    /// `sigma_scale * default_sigma(inputs)` when `kernel` is `None`.
    pub fn fit(
        input: DetailInput,
        inputs: &[f32],
        d_in: usize,
        h: &[Vec<f32>],
        kernel: Option<Kernel>,
        opts: &KccaOptions,
    ) -> Result<DetailModel, DetailFitError> {
        let n = h.len();
        if n == 0 || d_in == 0 || inputs.len() != n * d_in {
            return Err(DetailFitError::Shape(format!(
                "{} input values for {n} examples of dimension {d_in}",
                inputs.len()
            )));
        }
        let vertices = h[0].len();
        if let Some((l, hl)) = h.iter().enumerate().find(|(_, hl)| hl.len() != vertices) {
            return Err(DetailFitError::Shape(format!(
                "example {l} has {} displacements, example 0 has {vertices}",
                hl.len()
            )));
        }
        if let Some(index) = inputs.iter().position(|v| !v.is_finite()) {
            return Err(DetailFitError::NotFinite {
                what: "input",
                index,
            });
        }
        // y: n x vertices, row-major (one row per example).
        let mut y = Vec::with_capacity(n * vertices);
        for hl in h {
            y.extend_from_slice(hl);
        }
        if let Some(index) = y.iter().position(|v| !v.is_finite()) {
            return Err(DetailFitError::NotFinite {
                what: "displacement",
                index,
            });
        }
        let kernel = kernel.unwrap_or(Kernel::Gaussian {
            sigma: default_sigma(inputs, d_in),
        });
        let opts = KccaOptions {
            n_bases: 1,
            ..opts.clone()
        };
        let model = fit_kcca_per_block(inputs, d_in, &y, 1, kernel, &opts);
        Ok(DetailModel {
            input,
            kernel,
            examples: inputs.to_vec(),
            model,
        })
    }

    /// The static-detail baseline (HZY11 Fig. 8a): `h` is `rest` in every pose.
    pub fn fixed(input: DetailInput, d_in: usize, rest: &[f32]) -> DetailModel {
        DetailModel {
            input,
            kernel: Kernel::Gaussian { sigma: 1.0 },
            examples: Vec::new(),
            model: LinearModel {
                d_in,
                d_out: rest.len(),
                n: 0,
                m: Vec::new(),
                b: rest.to_vec(),
            },
        }
    }

    /// Number of detailed vertices.
    pub fn vertex_count(&self) -> usize {
        self.model.d_out
    }

    /// The kernel vector of input `x` into `xi` (length = training examples).
    pub fn kernel_vector(&self, x: &[f32], xi: &mut [f32]) {
        if self.model.n > 0 {
            self.kernel
                .kernel_vector(x, &self.examples, self.model.d_in, xi);
        }
    }

    /// `h = D xi(x) + b` into `out`; `xi` is scratch of at least
    /// [`DetailModel::example_count`] values (only that prefix is used). Allocates nothing.
    ///
    /// # Panics
    /// If `xi` is shorter than the example count or `out` is not one value per vertex.
    pub fn predict(&self, x: &[f32], xi: &mut [f32], out: &mut [f32]) {
        let xi = &mut xi[..self.model.n];
        self.kernel_vector(x, xi);
        self.model.predict(xi, out);
    }

    /// Number of training examples (length of `xi`).
    pub fn example_count(&self) -> usize {
        self.model.n
    }
}

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
//! static baseline of HZY11 Fig. 8a ([`DetailRegressor::fixed`]) keeps the rest pose's
//! displacements in every pose.
//!
//! The result is `crease-core`'s [`DetailRegressor`], what a model file stores and the
//! predictor runs.
//!
//! Each vertex is its own 1-D KCCA ([`fit_kcca_per_block`] with `block = 1`): with a single
//! output the canonical output direction is trivial and the fit is a kernel ridge with the
//! KCCA's linear recalibration (see [`crate::kcca`]); the centred kernel matrix is decomposed
//! once for all vertices.

pub use crease_core::runtime::displacement::{DetailInput, DetailRegressor};
use crease_core::runtime::kernel::Kernel;
use crease_core::runtime::predict::LinearOperator;

use crate::kcca::{KccaOptions, default_sigma, fit_kcca_per_block};

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

/// Fits the detail regressor (module docs). `inputs` is `n x d_in` row-major, `h[l]` the
/// displacements of example `l` (one per detailed vertex; owned vectors or borrowed slices). A Gaussian kernel of width
/// `default_sigma(inputs)` when `kernel` is `None`.
pub fn fit<H: AsRef<[f32]>>(
    input: DetailInput,
    inputs: &[f32],
    d_in: usize,
    h: &[H],
    kernel: Option<Kernel>,
    opts: &KccaOptions,
) -> Result<DetailRegressor, DetailFitError> {
    let n = h.len();
    if n == 0 || d_in == 0 || inputs.len() != n * d_in {
        return Err(DetailFitError::Shape(format!(
            "{} input values for {n} examples of dimension {d_in}",
            inputs.len()
        )));
    }
    let vertices = h[0].as_ref().len();
    if let Some((l, hl)) = h
        .iter()
        .map(AsRef::as_ref)
        .enumerate()
        .find(|(_, hl)| hl.len() != vertices)
    {
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
        y.extend_from_slice(hl.as_ref());
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
    Ok(DetailRegressor {
        input,
        kernel,
        d_in,
        examples: inputs.to_vec(),
        operator: LinearOperator {
            rows: model.d_out,
            cols: model.n,
            m: model.m,
            b: model.b,
        },
    })
}

//! Kernel CCA regression collapsed to one linear operator (FKY08 §4), and the direct RBF
//! (kernel ridge) baseline of FKY08 Fig. 3.
//!
//! Both fit `n` example pairs `(x_l, y_l)` (inputs `x`: control vectors, `n x d_in`; outputs
//! `y`: e.g. bone quaternions, `n x d_out`, both row-major) and return a [`LinearModel`]
//!
//! ```text
//! y(x) = M xi(x) + b,    xi_l(x) = k(x, x_l)          (FKY08 eq. 7, §4.3, §6.1)
//! ```
//!
//! so the run time evaluates one kernel vector and one matrix-vector product for all bones.
//!
//! # KCCA regression (FKY08 §4.1–4.3)
//!
//! The input side is kernelised, the output side is not (FKY08 §4.2: a nonlinear output map would
//! make reconstruction expensive). With the centred kernel matrix `K~ = J K J`,
//! `J = I - 1 1^T / n`, and the centred outputs `Y~ = J Y`:
//!
//! 1. `K~ = Q L Q^T` (eigen-decomposition, shared by every output block). Eigenvalues below
//!    [`EIGEN_RELATIVE_TOLERANCE`] of the largest are the null space (the constant vector is
//!    always in it) and are dropped: a pseudo-inverse, not a blow-up of rounding noise.
//! 2. Regularised KCCA (Hardoon et al. 2004) replaces the input covariance `K~^2` of FKY08 eq. 6
//!    by `K~^2 + kappa K~`. The bases solve the SVD of FKY08 eq. 3 in dual form:
//!    `(K~^2 + kappa K~)^(-1/2) K~ Y~ (Y~^T Y~ + eps I)^(-1/2) = U S V^T`. In the eigenbasis
//!    the left factor is `Q diag(sqrt(l / (l + kappa)))`, so only the small matrix
//!    `G = diag(sqrt(l / (l + kappa))) Q^T Y~ (Y~^T Y~ + eps I)^(-1/2)` is decomposed.
//! 3. `F_c = Q diag(1 / sqrt(l^2 + kappa l)) U` (FKY08 eq. 4 in dual form),
//!    `U_d = (Y~^T Y~ + eps I)^(-1/2) V` (eq. 5), keeping `n_f` pairs.
//! 4. Reduced coordinates `C_r = F_c^T K~` (eq. 7 on the training inputs), `D_r = U_d^T Y~^T`.
//! 5. `B_c = D_r C_r^T (C_r C_r^T + lambda I)^-1` (eq. 8, a small ridge for safety) and
//!    `H_d = Y~^T D_r^T (D_r D_r^T + lambda I)^-1` (eq. 9).
//! 6. On centred kernel vectors the predictor is `y = mean_y + M~ xi~(x)` with
//!    `M~ = H_d B_c F_c^T` (FKY08 §4.3, `M_b`) and `xi~ = J (xi - K 1 / n)`. Folding the centring
//!    in gives the plain form above: `M = M~ J`, `b = mean_y - M K 1 / n` ([`CentredModel::fold`]).
//!
//! Each output block (FKY08 §4.3: "a distinct set of CCA bases specifically tailored for each
//! bone") runs steps 2–6 on its own columns; the blocks' rows are stacked into one `M`.
//!
//! A note on what `kappa` does: `F_c` spans the columns of `(K~ + kappa I)^-1 Y~`, the kernel
//! ridge coefficients with ridge `kappa`, and `B_c`, `H_d` recalibrate linearly on top. So
//! `kappa` is the smoothing knob; `kappa -> 0` interpolates the examples.

use crease_core::runtime::kernel::Kernel;
use nalgebra::{DMatrix, DVector, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::par;

/// Eigenvalues of the centred kernel matrix (or of a small Gram matrix) below this fraction of
/// the largest are treated as zero. f64 eigen-solvers are accurate to about `n * 1e-16` of the
/// largest eigenvalue; `1e-10` leaves a wide margin above that noise while keeping every
/// direction a regularised fit could still use.
pub const EIGEN_RELATIVE_TOLERANCE: f64 = 1e-10;

/// Options of [`fit_kcca_per_block`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct KccaOptions {
    /// CCA basis pairs kept per block, `n_f` (FKY08 Table 1: 8). Capped at
    /// `min(block, n - 1, rank of K~)`: CCA has at most `min(dims)` pairs (FKY08 §4.1) and the
    /// centred kernel matrix has rank at most `n - 1`.
    pub n_bases: usize,
    /// Kernel-side regularisation `kappa` of `K~^2 + kappa K~` (Hardoon et al. 2004), as a
    /// fraction of the largest eigenvalue of `K~`, so one value suits kernels of any scale.
    /// Without it KCCA finds perfect correlations on any data and overfits. It acts as a kernel
    /// ridge (see the module docs); `1e-3` damps directions carrying under a thousandth of the
    /// kernel's energy. On noisy synthetic quaternion targets (n = 30–80, noise 0.02–0.05) it
    /// held out best among 1e-8..1e-1; noise-free data prefers less (cross-validate
    /// it per data set).
    pub kappa: f64,
    /// Ridge `eps` of the output covariance `Y~^T Y~ + eps I`, as a fraction of its mean
    /// eigenvalue: keeps the whitening finite when an output component is constant.
    pub output_ridge: f64,
    /// Ridge of the reduced regressions `B_c` (FKY08 eq. 8) and `H_d` (eq. 9), as a fraction of
    /// the mean eigenvalue of their Gram matrices: numerical safety only.
    pub regression_ridge: f64,
}

impl Default for KccaOptions {
    fn default() -> Self {
        Self {
            n_bases: 8,
            kappa: 1e-3,
            output_ridge: 1e-8,
            regression_ridge: 1e-8,
        }
    }
}

/// A fitted predictor `y = M xi + b` on raw kernel vectors `xi_l = k(x, x_l)` (FKY08 §4.3 `M_b`,
/// §6.1), in the precision the run time uses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LinearModel {
    /// Input (control vector) dimension the kernel vector is computed from.
    pub d_in: usize,
    /// Output dimension (rows of `m`).
    pub d_out: usize,
    /// Number of training examples (columns of `m`, length of `xi`).
    pub n: usize,
    /// `d_out x n`, row-major.
    pub m: Vec<f32>,
    /// `d_out` offsets.
    pub b: Vec<f32>,
}

impl LinearModel {
    /// `out = M xi + b`. Allocates nothing.
    ///
    /// # Panics
    /// If `xi.len() != n` or `out.len() != d_out`.
    pub fn predict(&self, xi: &[f32], out: &mut [f32]) {
        assert_eq!(xi.len(), self.n, "kernel vector length != n");
        assert_eq!(out.len(), self.d_out, "output length != d_out");
        // `max(1)`: with n = 0 rows are empty and chunks_exact(0) would panic.
        for ((o, row), &b) in out
            .iter_mut()
            .zip(self.m.chunks_exact(self.n.max(1)))
            .zip(&self.b)
        {
            *o = b + row.iter().zip(xi).map(|(&m, &x)| m * x).sum::<f32>();
        }
        if self.n == 0 {
            out.copy_from_slice(&self.b);
        }
    }
}

/// A fitted predictor on centred kernel vectors, before [`CentredModel::fold`]:
/// `y = mean_y + M~ J (xi - kernel_row_means)` (FKY08 §4.3 `M_b = H_d B_c F_c^T`, with the
/// centring of kernel CCA made explicit). Kept public so the folding can be checked.
#[derive(Clone, Debug, PartialEq)]
pub struct CentredModel {
    /// Input dimension.
    pub d_in: usize,
    /// Output dimension.
    pub d_out: usize,
    /// Number of training examples.
    pub n: usize,
    /// `M~`, `d_out x n`.
    pub m: DMatrix<f64>,
    /// Mean training output.
    pub mean_y: DVector<f64>,
    /// `K 1 / n`: row means of the raw kernel matrix.
    pub kernel_row_means: DVector<f64>,
}

impl CentredModel {
    /// Folds the centring into one operator: `M = M~ J`, `b = mean_y - M (K 1 / n)`, so that
    /// `M xi + b = mean_y + M~ J (xi - K 1 / n)` for every `xi`.
    pub fn fold(&self) -> LinearModel {
        let mut m = self.m.clone();
        // M~ J: subtract each row's mean.
        for mut row in m.row_iter_mut() {
            let mean = row.sum() / self.n.max(1) as f64;
            row.add_scalar_mut(-mean);
        }
        let b = &self.mean_y - &m * &self.kernel_row_means;
        LinearModel {
            d_in: self.d_in,
            d_out: self.d_out,
            n: self.n,
            m: m.transpose().iter().map(|&v| v as f32).collect(),
            b: b.iter().map(|&v| v as f32).collect(),
        }
    }
}

/// Kernel CCA regression with one CCA over all `d_out` output columns (FKY08 §4); see
/// [`fit_kcca_per_block`].
///
/// # Panics
/// As [`fit_kcca_per_block`].
pub fn fit_kcca(
    x: &[f32],
    d_in: usize,
    y: &[f32],
    kernel: Kernel,
    opts: &KccaOptions,
) -> LinearModel {
    let n = example_count(x, d_in);
    let d_out = y.len().checked_div(n).unwrap_or(0);
    fit_kcca_per_block(x, d_in, y, d_out.max(1), kernel, opts)
}

/// Kernel CCA regression, one CCA per `block` consecutive output columns (one bone's
/// quaternion: `block = 4`), all blocks stacked into one `M` (FKY08 §4.3 and §6.1: a distinct
/// basis set per bone, one matrix for all bones). The centred kernel matrix is decomposed once
/// and shared.
///
/// `x` is `n x d_in` and `y` is `n x d_out`, row-major, with `n = x.len() / d_in` and
/// `d_out = y.len() / n` a multiple of `block`.
///
/// Degenerate cases, by design: with `n = 1`, or when every example has the same input or a
/// block's outputs are constant, the block predicts the training mean (`M` rows zero). With
/// `n = 2` each block has one basis pair (the centred kernel matrix has rank 1).
///
/// # Panics
/// If `d_in` or `block` is 0, `x` is not a whole number of rows, there are no examples, `y` is
/// not `n` rows of a multiple of `block`, the kernel is invalid ([`Kernel::is_valid`]), or a value
/// is not finite.
pub fn fit_kcca_per_block(
    x: &[f32],
    d_in: usize,
    y: &[f32],
    block: usize,
    kernel: Kernel,
    opts: &KccaOptions,
) -> LinearModel {
    fit_kcca_per_block_centred(x, d_in, y, block, kernel, opts).fold()
}

/// [`fit_kcca_per_block`] before the centring is folded in.
///
/// # Panics
/// As [`fit_kcca_per_block`].
pub fn fit_kcca_per_block_centred(
    x: &[f32],
    d_in: usize,
    y: &[f32],
    block: usize,
    kernel: Kernel,
    opts: &KccaOptions,
) -> CentredModel {
    assert!(block > 0, "block must be > 0");
    let n = example_count(x, d_in);
    assert!(n > 0, "no examples");
    assert!(
        y.len().is_multiple_of(n) && (y.len() / n).is_multiple_of(block),
        "y must be {n} rows of a multiple of block = {block} values, got {} values",
        y.len()
    );
    let d_out = y.len() / n;
    let ck = CentredKernel::new(x, d_in, kernel);
    let (yc, mean_y) = centre_rows(y, n, d_out);
    let blocks = par::map_range(
        d_out / block,
        || (),
        |_, j| kcca_block(&ck, &yc.columns(j * block, block).into_owned(), opts),
    );
    let mut m = DMatrix::zeros(d_out, n);
    for (j, mb) in blocks.iter().enumerate() {
        m.rows_mut(j * block, block).copy_from(mb);
    }
    CentredModel {
        d_in,
        d_out,
        n,
        m,
        mean_y,
        kernel_row_means: ck.row_means,
    }
}

/// Direct RBF regression, the FKY08 Fig. 3 baseline: `y = sum_l alpha_l k(x, x_l) + b`, fitted
/// by kernel ridge regression with an unpenalised offset, `alpha = (K~ + ridge I)^+ Y~` on the
/// centred kernel matrix (the same solution as the bordered system `[K + ridge I, 1; 1^T, 0]`),
/// `ridge` a fraction of the largest eigenvalue of `K~`. `ridge = 0` interpolates
/// (minimum-norm where `K~` is singular). Same representation and degenerate behaviour as
/// [`fit_kcca_per_block`].
///
/// # Panics
/// If `d_in` is 0, `x` is not a whole number of rows, there are no examples,
/// `y.len() != n * d_out`, the kernel is invalid, `ridge` is negative or not finite, or a value is
/// not finite.
pub fn fit_rbf(
    x: &[f32],
    d_in: usize,
    y: &[f32],
    d_out: usize,
    kernel: Kernel,
    ridge: f64,
) -> LinearModel {
    assert!(
        ridge.is_finite() && ridge >= 0.0,
        "ridge must be finite and >= 0"
    );
    let n = example_count(x, d_in);
    assert!(n > 0, "no examples");
    assert_eq!(y.len(), n * d_out, "y must be n x d_out");
    let ck = CentredKernel::new(x, d_in, kernel);
    let (yc, mean_y) = centre_rows(y, n, d_out);
    let lambda = ridge * ck.l_max;
    // alpha = Q diag(1 / (l + lambda)) Q^T Y~, then M~ = alpha^T.
    let mut p = ck.q.transpose() * &yc;
    for (mut row, &l) in p.row_iter_mut().zip(&ck.l) {
        row /= l + lambda;
    }
    let alpha = &ck.q * p;
    CentredModel {
        d_in,
        d_out,
        n,
        m: alpha.transpose(),
        mean_y,
        kernel_row_means: ck.row_means,
    }
    .fold()
}

/// A default Gaussian width: the RMS distance of the examples to their mean,
/// `sqrt(1/n sum_l |x_l - mean|^2)`. FKY08 §7 sets `sigma` to "the standard deviation of control
/// point positions"; this is its multivariate form. Two typical examples are then about
/// `sqrt(2) sigma` apart, so kernel values between them sit near `exp(-1)`: neither all near 1
/// (the kernel cannot tell examples apart) nor all near 0 (the kernel matrix becomes the identity
/// and nothing generalises). Cross-validating a multiple of it may do better.
///
/// Returns 1 when it is undefined or zero (no examples, `d == 0`, all examples equal): every
/// width then gives the same kernel matrix.
///
/// # Panics
/// If `x.len()` is not a multiple of `d` (for `d > 0`).
pub fn default_sigma(x: &[f32], d: usize) -> f32 {
    if d == 0 || x.is_empty() {
        return 1.0;
    }
    assert_eq!(x.len() % d, 0, "x is not a whole number of rows");
    let n = x.len() / d;
    let mut mean = vec![0.0f64; d];
    for row in x.chunks_exact(d) {
        for (m, &v) in mean.iter_mut().zip(row) {
            *m += f64::from(v);
        }
    }
    mean.iter_mut().for_each(|m| *m /= n as f64);
    let ss: f64 = x
        .chunks_exact(d)
        .flat_map(|row| {
            row.iter()
                .zip(&mean)
                .map(|(&v, &m)| (f64::from(v) - m).powi(2))
        })
        .sum();
    let sigma = (ss / n as f64).sqrt() as f32;
    if sigma.is_finite() && sigma > 0.0 {
        sigma
    } else {
        1.0
    }
}

/// Number of rows of `x`, checking its shape and values.
fn example_count(x: &[f32], d_in: usize) -> usize {
    assert!(d_in > 0, "d_in must be > 0");
    assert_eq!(x.len() % d_in, 0, "x is not a whole number of rows");
    assert!(x.iter().all(|v| v.is_finite()), "x has a non-finite value");
    x.len() / d_in
}

/// `y` (`n x d`, row-major) minus its column means, and the means.
fn centre_rows(y: &[f32], n: usize, d: usize) -> (DMatrix<f64>, DVector<f64>) {
    assert!(y.iter().all(|v| v.is_finite()), "y has a non-finite value");
    let y = DMatrix::from_row_iterator(n, d, y.iter().map(|&v| f64::from(v)));
    let mean = DVector::from_iterator(d, y.column_iter().map(|c| c.mean()));
    let mut yc = y;
    for (mut col, &m) in yc.column_iter_mut().zip(&mean) {
        col.add_scalar_mut(-m);
    }
    (yc, mean)
}

/// The centred kernel matrix `K~ = J K J` of the training inputs, decomposed (step 1 of the
/// module docs): only the eigenpairs above [`EIGEN_RELATIVE_TOLERANCE`], largest first.
struct CentredKernel {
    /// `K 1 / n`.
    row_means: DVector<f64>,
    /// `n x r` eigenvectors.
    q: DMatrix<f64>,
    /// `r` eigenvalues, descending, all `> 0`.
    l: Vec<f64>,
    /// Largest eigenvalue (0 when `r = 0`): the scale of the relative ridges.
    l_max: f64,
}

impl CentredKernel {
    fn new(x: &[f32], d_in: usize, kernel: Kernel) -> Self {
        assert!(kernel.is_valid(), "invalid kernel {kernel:?}");
        let n = x.len() / d_in;
        let row = |i: usize| &x[i * d_in..(i + 1) * d_in];
        let mut k = DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            for j in i..n {
                let v = kernel.eval_f64(row(i), row(j));
                k[(i, j)] = v;
                k[(j, i)] = v;
            }
        }
        assert!(
            k.iter().all(|v| v.is_finite()),
            "kernel matrix overflowed (polynomial kernel on large inputs?)"
        );
        let row_means = DVector::from_iterator(n, k.row_iter().map(|r| r.mean()));
        let all_mean = row_means.mean();
        let mut kc = k;
        for i in 0..n {
            for j in 0..n {
                kc[(i, j)] += all_mean - row_means[i] - row_means[j];
            }
        }
        let (q, l) = top_eigen(kc);
        let l_max = l.first().copied().unwrap_or(0.0);
        CentredKernel {
            row_means,
            q,
            l,
            l_max,
        }
    }
}

/// Eigenpairs of a symmetric matrix with eigenvalue above [`EIGEN_RELATIVE_TOLERANCE`] times
/// the largest (and above 0), sorted descending: `(vectors as columns, values)`.
fn top_eigen(a: DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let n = a.nrows();
    if n == 0 {
        return (DMatrix::zeros(0, 0), Vec::new());
    }
    let eig = SymmetricEigen::new(a);
    let mut order: Vec<usize> = (0..n).collect();
    // Descending by value, ties by index: deterministic.
    order.sort_by(|&i, &j| {
        eig.eigenvalues[j]
            .total_cmp(&eig.eigenvalues[i])
            .then(i.cmp(&j))
    });
    let top = eig.eigenvalues[order[0]];
    let keep: Vec<usize> = order
        .into_iter()
        .take_while(|&i| top > 0.0 && eig.eigenvalues[i] > EIGEN_RELATIVE_TOLERANCE * top)
        .collect();
    let q = DMatrix::from_fn(n, keep.len(), |r, c| eig.eigenvectors[(r, keep[c])]);
    let l = keep.iter().map(|&i| eig.eigenvalues[i]).collect();
    (q, l)
}

/// `(S + ridge * mean eigenvalue * I)^power` of a symmetric positive semi-definite `s`, with
/// eigenvalues at or below [`EIGEN_RELATIVE_TOLERANCE`] of the largest (after the ridge) mapped
/// to 0: a regularised pseudo-power. An all-zero `s` gives zero.
fn sym_pseudo_power(s: &DMatrix<f64>, ridge: f64, power: f64) -> DMatrix<f64> {
    let p = s.nrows();
    if p == 0 {
        return DMatrix::zeros(0, 0);
    }
    let eig = SymmetricEigen::new(s.clone());
    let mean = eig.eigenvalues.iter().map(|&l| l.max(0.0)).sum::<f64>() / p as f64;
    let eps = ridge * mean;
    let top = eig.eigenvalues.max().max(0.0) + eps;
    let d = DVector::from_iterator(
        p,
        eig.eigenvalues.iter().map(|&l| {
            let l = l.max(0.0) + eps;
            if top > 0.0 && l > EIGEN_RELATIVE_TOLERANCE * top {
                l.powf(power)
            } else {
                0.0
            }
        }),
    );
    &eig.eigenvectors * DMatrix::from_diagonal(&d) * eig.eigenvectors.transpose()
}

/// Steps 2–5 of the module docs for one output block `yc` (`n x p`, centred): returns
/// `M~ = H_d B_c F_c^T` (`p x n`).
fn kcca_block(ck: &CentredKernel, yc: &DMatrix<f64>, opts: &KccaOptions) -> DMatrix<f64> {
    let (n, p) = yc.shape();
    let r = ck.l.len();
    let zero = DMatrix::zeros(p, n);
    if r == 0 || yc.iter().all(|&v| v == 0.0) {
        // Constant inputs or constant outputs: nothing to correlate, predict the mean.
        return zero;
    }
    let kappa = opts.kappa.max(0.0) * ck.l_max;
    // FKY08 eq. 3 in dual form, in the eigenbasis of K~ (module docs, step 2).
    let w: Vec<f64> = ck.l.iter().map(|&l| (l / (l + kappa)).sqrt()).collect();
    let a: Vec<f64> =
        ck.l.iter()
            .map(|&l| 1.0 / (l * l + kappa * l).sqrt())
            .collect();
    let by = sym_pseudo_power(&(yc.transpose() * yc), opts.output_ridge.max(0.0), -0.5);
    let mut g = ck.q.transpose() * yc * &by;
    for (mut row, &wi) in g.row_iter_mut().zip(&w) {
        row *= wi;
    }
    let svd = g.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        // nalgebra computes both when asked; keep the mean rather than panic if not.
        return zero;
    };
    let mut order: Vec<usize> = (0..svd.singular_values.len()).collect();
    order.sort_by(|&i, &j| {
        svd.singular_values[j]
            .total_cmp(&svd.singular_values[i])
            .then(i.cmp(&j))
    });
    let nf = opts.n_bases.min(p).min(r).min(n.saturating_sub(1));
    if nf == 0 {
        return zero;
    }
    let u = DMatrix::from_fn(r, nf, |i, c| u[(i, order[c])]);
    let v = DMatrix::from_fn(p, nf, |i, c| v_t[(order[c], i)]);
    // FKY08 eq. 4: F_c = Q diag(a) U.
    let mut au = u.clone();
    for (mut row, &ai) in au.row_iter_mut().zip(&a) {
        row *= ai;
    }
    let f_c = &ck.q * au;
    // C_r = F_c^T K~ = U^T diag(w) Q^T (eq. 7 on the training inputs).
    let mut wu = u;
    for (mut row, &wi) in wu.row_iter_mut().zip(&w) {
        row *= wi;
    }
    let c_r = wu.transpose() * ck.q.transpose();
    // FKY08 eq. 5: U_d = (Y~^T Y~ + eps I)^(-1/2) V; D_r = U_d^T Y~^T.
    let d_r = (by * v).transpose() * yc.transpose();
    let ridge = opts.regression_ridge.max(0.0);
    // FKY08 eq. 8 and eq. 9, ridge least squares.
    let b_c = &d_r * c_r.transpose() * sym_pseudo_power(&(&c_r * c_r.transpose()), ridge, -1.0);
    let h_d =
        yc.transpose() * d_r.transpose() * sym_pseudo_power(&(&d_r * d_r.transpose()), ridge, -1.0);
    h_d * b_c * f_c.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sym_pseudo_power_inverts_and_handles_zero() {
        let s = DMatrix::from_row_slice(2, 2, &[4.0, 0.0, 0.0, 9.0]);
        let inv_sqrt = sym_pseudo_power(&s, 0.0, -0.5);
        assert!((inv_sqrt[(0, 0)] - 0.5).abs() < 1e-12);
        assert!((inv_sqrt[(1, 1)] - 1.0 / 3.0).abs() < 1e-12);
        let z = sym_pseudo_power(&DMatrix::zeros(3, 3), 1e-8, -1.0);
        assert!(z.iter().all(|&v| v == 0.0));
        // Rank one: the null direction maps to zero, not to 1 / eps.
        let r1 = DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 1.0]);
        let p = sym_pseudo_power(&r1, 0.0, -1.0);
        assert!((p[(0, 0)] - 0.25).abs() < 1e-12 && (p[(0, 1)] - 0.25).abs() < 1e-12);
    }

    #[test]
    fn centred_kernel_drops_the_constant_direction() {
        let x = [0.0f32, 1.0, 3.0, 4.5];
        let ck = CentredKernel::new(&x, 1, Kernel::Gaussian { sigma: 1.0 });
        assert_eq!(ck.l.len(), 3, "rank n - 1");
        let ones = DVector::from_element(4, 1.0);
        assert!((ck.q.transpose() * ones).norm() < 1e-10);
        assert!(ck.l.windows(2).all(|w| w[0] >= w[1]));
    }

    #[test]
    fn default_sigma_is_rms_distance_to_mean() {
        // Points (0,0), (2,0), (0,2), (2,2): mean (1,1), every distance sqrt 2.
        let x = [0.0f32, 0.0, 2.0, 0.0, 0.0, 2.0, 2.0, 2.0];
        assert!((default_sigma(&x, 2) - 2f32.sqrt()).abs() < 1e-6);
        assert_eq!(default_sigma(&[3.0, 3.0], 1), 1.0);
        assert_eq!(default_sigma(&[], 3), 1.0);
    }

    #[test]
    fn predict_with_no_examples_returns_offset() {
        let m = LinearModel {
            d_in: 1,
            d_out: 2,
            n: 0,
            m: vec![],
            b: vec![1.0, 2.0],
        };
        let mut out = [0.0; 2];
        m.predict(&[], &mut out);
        assert_eq!(out, [1.0, 2.0]);
    }
}

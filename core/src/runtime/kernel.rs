//! Regression kernels (FKY08 §4.2, §7) and the run-time kernel vector `xi(c)` (FKY08 eq. 7).
//!
//! A trained predictor is `d = M xi(c) + b` where `xi_l(c) = k(c, c^l)` over the `n` training
//! control vectors `c^l` (FKY08 §4.3, §6.1). [`Kernel::kernel_vector`] fills `xi` into a
//! caller buffer without allocating; [`Kernel::kernel_vector_with_dist2`] also returns the
//! squared distances `|c - c^l|^2`, which the pose-space blending of HZY11 §6 (its eq. 2 heat
//! kernel) needs as well, at no extra cost for the Gaussian kernel.

use serde::{Deserialize, Serialize};

/// A positive-definite kernel `k(x, y)` on control vectors.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum Kernel {
    /// `exp(-|x - y|^2 / (2 sigma^2))` (FKY08 §7: used for all their non-facial data).
    Gaussian {
        /// Width, in the units of the control vectors; must be finite and `> 0`.
        sigma: f32,
    },
    /// `exp(-|x - y|^2 / (2 sigma^2)) + gamma (x . y) / sigma^2`: the Gaussian plus a linear
    /// part. A Gaussian interpolant sags toward the mean between and beyond its examples; the
    /// linear part carries the global trend of the map (how rotations follow the control points
    /// to first order), and the Gaussian the rest. Not in FKY08, which uses one kernel at a time.
    GaussianLinear {
        /// Width, finite and `> 0`.
        sigma: f32,
        /// Weight of the linear part, finite and `>= 0`.
        gamma: f32,
    },
    /// The inhomogeneous polynomial kernel `(x . y + c)^degree` (FKY08 §7: degree 5 for faces).
    Polynomial {
        /// Offset; FKY08 §7 sets it to 0.1 times the average control-vector norm. Must be finite.
        c: f32,
        /// Degree; 0 gives the constant kernel 1.
        degree: u32,
    },
}

impl Kernel {
    /// True when the parameters are usable: a finite, positive `sigma`; a finite `c`.
    pub fn is_valid(&self) -> bool {
        match *self {
            Kernel::Gaussian { sigma } => sigma.is_finite() && sigma > 0.0,
            Kernel::GaussianLinear { sigma, gamma } => {
                sigma.is_finite() && sigma > 0.0 && gamma.is_finite() && gamma >= 0.0
            }
            Kernel::Polynomial { c, .. } => c.is_finite(),
        }
    }

    /// `k(x, y)`.
    ///
    /// # Panics
    /// If `x` and `y` differ in length.
    #[inline]
    pub fn eval(&self, x: &[f32], y: &[f32]) -> f32 {
        assert_eq!(x.len(), y.len(), "kernel arguments differ in length");
        match *self {
            Kernel::Gaussian { sigma } => gaussian(dist2(x, y), sigma),
            Kernel::GaussianLinear { sigma, gamma } => {
                gaussian_linear(dist2(x, y), dot(x, y), sigma, gamma)
            }
            Kernel::Polynomial { c, degree } => polynomial(dot(x, y), c, degree),
        }
    }

    /// `k(x, y)` accumulated and evaluated in `f64`, for training: the kernel matrix is
    /// eigen-decomposed, and f32 rounding of its entries would blur its small eigenvalues.
    /// Agrees with [`Kernel::eval`] to f32 rounding.
    ///
    /// # Panics
    /// If `x` and `y` differ in length.
    pub fn eval_f64(&self, x: &[f32], y: &[f32]) -> f64 {
        assert_eq!(x.len(), y.len(), "kernel arguments differ in length");
        match *self {
            Kernel::Gaussian { sigma } => {
                let d2: f64 = x
                    .iter()
                    .zip(y)
                    .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
                    .sum();
                let s = f64::from(sigma);
                (-d2 / (2.0 * s * s)).exp()
            }
            Kernel::GaussianLinear { sigma, gamma } => {
                let (mut d2, mut d) = (0.0f64, 0.0f64);
                for (&a, &b) in x.iter().zip(y) {
                    let (a, b) = (f64::from(a), f64::from(b));
                    d2 += (a - b).powi(2);
                    d += a * b;
                }
                let s2 = f64::from(sigma).powi(2);
                (-d2 / (2.0 * s2)).exp() + f64::from(gamma) * d / s2
            }
            Kernel::Polynomial { c, degree } => {
                let d: f64 = x
                    .iter()
                    .zip(y)
                    .map(|(&a, &b)| f64::from(a) * f64::from(b))
                    .sum();
                (d + f64::from(c)).powi(degree_i32(degree))
            }
        }
    }

    /// The kernel vector `xi(x)` of FKY08 eq. 7: `out[l] = k(x, examples[l])`, where `examples`
    /// holds `out.len()` vectors of length `dim`, row-major. Allocates nothing.
    ///
    /// # Panics
    /// If `x.len() != dim` or `examples.len() != out.len() * dim`.
    pub fn kernel_vector(&self, x: &[f32], examples: &[f32], dim: usize, out: &mut [f32]) {
        check_shapes(x, examples, dim, out.len());
        // Match once outside the loop so each loop body is branch-free.
        match *self {
            Kernel::Gaussian { sigma } => {
                for (l, o) in out.iter_mut().enumerate() {
                    *o = gaussian(dist2(x, &examples[l * dim..(l + 1) * dim]), sigma);
                }
            }
            Kernel::GaussianLinear { sigma, gamma } => {
                for (l, o) in out.iter_mut().enumerate() {
                    let e = &examples[l * dim..(l + 1) * dim];
                    *o = gaussian_linear(dist2(x, e), dot(x, e), sigma, gamma);
                }
            }
            Kernel::Polynomial { c, degree } => {
                for (l, o) in out.iter_mut().enumerate() {
                    *o = polynomial(dot(x, &examples[l * dim..(l + 1) * dim]), c, degree);
                }
            }
        }
    }

    /// [`Kernel::kernel_vector`] that also writes the squared distances
    /// `out_d2[l] = |x - examples[l]|^2` (the HZY11 eq. 2 heat-kernel weights of pose-space
    /// blending need them). Allocates nothing.
    ///
    /// # Panics
    /// If `x.len() != dim`, `out_k.len() != out_d2.len()` or
    /// `examples.len() != out_k.len() * dim`.
    pub fn kernel_vector_with_dist2(
        &self,
        x: &[f32],
        examples: &[f32],
        dim: usize,
        out_k: &mut [f32],
        out_d2: &mut [f32],
    ) {
        assert_eq!(out_k.len(), out_d2.len(), "output buffers differ in length");
        check_shapes(x, examples, dim, out_k.len());
        for (l, (k, d2)) in out_k.iter_mut().zip(out_d2.iter_mut()).enumerate() {
            let e = &examples[l * dim..(l + 1) * dim];
            *d2 = dist2(x, e);
            *k = match *self {
                Kernel::Gaussian { sigma } => gaussian(*d2, sigma),
                Kernel::GaussianLinear { sigma, gamma } => {
                    gaussian_linear(*d2, dot(x, e), sigma, gamma)
                }
                Kernel::Polynomial { c, degree } => polynomial(dot(x, e), c, degree),
            };
        }
    }
}

/// Panics unless `x` is `dim` long and `examples` holds exactly `n` rows of `dim`.
fn check_shapes(x: &[f32], examples: &[f32], dim: usize, n: usize) {
    assert_eq!(x.len(), dim, "input vector length != dim");
    assert_eq!(
        examples.len(),
        n * dim,
        "examples must hold out.len() rows of dim values"
    );
}

#[inline]
fn dist2(x: &[f32], y: &[f32]) -> f32 {
    x.iter().zip(y).map(|(&a, &b)| (a - b) * (a - b)).sum()
}

#[inline]
fn dot(x: &[f32], y: &[f32]) -> f32 {
    x.iter().zip(y).map(|(&a, &b)| a * b).sum()
}

#[inline]
fn gaussian(d2: f32, sigma: f32) -> f32 {
    (-d2 / (2.0 * sigma * sigma)).exp()
}

#[inline]
fn gaussian_linear(d2: f32, dot: f32, sigma: f32, gamma: f32) -> f32 {
    gaussian(d2, sigma) + gamma * dot / (sigma * sigma)
}

#[inline]
fn polynomial(dot: f32, c: f32, degree: u32) -> f32 {
    (dot + c).powi(degree_i32(degree))
}

/// Degrees beyond `i32::MAX` overflow any float anyway; saturate rather than wrap.
#[inline]
fn degree_i32(degree: u32) -> i32 {
    i32::try_from(degree).unwrap_or(i32::MAX)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-6 * (1.0 + b.abs())
    }

    #[test]
    fn gaussian_matches_closed_form() {
        let k = Kernel::Gaussian { sigma: 2.0 };
        // |x - y|^2 = 1 + 4 + 4 = 9; exp(-9 / 8).
        let v = k.eval(&[1.0, 0.0, 2.0], &[0.0, 2.0, 0.0]);
        assert!(close(v, (-9.0f32 / 8.0).exp()), "{v}");
        assert_eq!(k.eval(&[3.0, -1.0], &[3.0, -1.0]), 1.0);
        assert!(
            (k.eval_f64(&[1.0, 0.0, 2.0], &[0.0, 2.0, 0.0]) - (-9.0f64 / 8.0).exp()).abs() < 1e-15
        );
    }

    #[test]
    fn gaussian_linear_matches_closed_form() {
        let k = Kernel::GaussianLinear {
            sigma: 2.0,
            gamma: 0.5,
        };
        // |x - y|^2 = 9, x . y = 0: exp(-9 / 8) + 0.
        let (x, y) = ([1.0f32, 0.0, 2.0], [0.0f32, 2.0, 0.0]);
        assert!(close(k.eval(&x, &y), (-9.0f32 / 8.0).exp()));
        // x = y = (1, 1): exp(0) + 0.5 * 2 / 4.
        assert!(close(k.eval(&[1.0, 1.0], &[1.0, 1.0]), 1.25));
        assert!((k.eval_f64(&[1.0, 1.0], &[1.0, 1.0]) - 1.25).abs() < 1e-15);
        assert!(
            !Kernel::GaussianLinear {
                sigma: 1.0,
                gamma: -1.0
            }
            .is_valid()
        );
    }

    #[test]
    fn polynomial_matches_closed_form() {
        let k = Kernel::Polynomial { c: 0.5, degree: 3 };
        // x . y = 2 - 3 = -1; (-1 + 0.5)^3 = -0.125.
        assert!(close(k.eval(&[1.0, 3.0], &[2.0, -1.0]), -0.125));
        assert_eq!(k.eval_f64(&[1.0, 3.0], &[2.0, -1.0]), -0.125);
        let k0 = Kernel::Polynomial { c: 7.0, degree: 0 };
        assert_eq!(k0.eval(&[1.0], &[5.0]), 1.0);
        // Degree 2, c = 1 on 2-D: the feature-space identity (1 + x.y)^2 spelled out.
        let k2 = Kernel::Polynomial { c: 1.0, degree: 2 };
        let (x, y) = ([0.3f32, -1.2], [2.0f32, 0.7]);
        let d = x[0] * y[0] + x[1] * y[1];
        assert!(close(k2.eval(&x, &y), 1.0 + 2.0 * d + d * d));
    }

    #[test]
    fn kernel_vector_matches_eval_and_reports_dist2() {
        let examples = [0.0f32, 0.0, 1.0, 0.0, 0.0, 2.0, -1.0, -1.0];
        let x = [0.5f32, 0.5];
        for kernel in [
            Kernel::Gaussian { sigma: 0.7 },
            Kernel::GaussianLinear {
                sigma: 0.7,
                gamma: 0.3,
            },
            Kernel::Polynomial { c: 1.0, degree: 5 },
        ] {
            let mut k = [f32::NAN; 4];
            let mut k2 = [f32::NAN; 4];
            let mut d2 = [f32::NAN; 4];
            kernel.kernel_vector(&x, &examples, 2, &mut k);
            kernel.kernel_vector_with_dist2(&x, &examples, 2, &mut k2, &mut d2);
            for l in 0..4 {
                let e = &examples[2 * l..2 * l + 2];
                assert_eq!(k[l], kernel.eval(&x, e));
                assert_eq!(k2[l], k[l]);
            }
            assert_eq!(d2, [0.5, 0.5, 2.5, 4.5]);
        }
    }

    #[test]
    fn empty_example_set_and_zero_dim_are_fine() {
        let k = Kernel::Gaussian { sigma: 1.0 };
        k.kernel_vector(&[1.0], &[], 1, &mut []);
        let mut out = [0.0f32; 3];
        k.kernel_vector(&[], &[], 0, &mut out);
        assert_eq!(out, [1.0; 3]);
    }

    #[test]
    #[should_panic(expected = "rows of dim")]
    fn kernel_vector_rejects_ragged_examples() {
        let mut out = [0.0f32; 2];
        Kernel::Gaussian { sigma: 1.0 }.kernel_vector(&[0.0, 0.0], &[1.0, 2.0, 3.0], 2, &mut out);
    }

    #[test]
    fn validity_and_serde_round_trip() {
        assert!(Kernel::Gaussian { sigma: 0.1 }.is_valid());
        assert!(!Kernel::Gaussian { sigma: 0.0 }.is_valid());
        assert!(!Kernel::Gaussian { sigma: f32::NAN }.is_valid());
        assert!(
            !Kernel::Polynomial {
                c: f32::INFINITY,
                degree: 2
            }
            .is_valid()
        );
        let k = Kernel::Polynomial { c: 0.25, degree: 5 };
        let json = serde_json::to_string(&k).unwrap();
        assert_eq!(json, r#"{"kind":"polynomial","c":0.25,"degree":5}"#);
        assert_eq!(serde_json::from_str::<Kernel>(&json).unwrap(), k);
    }
}

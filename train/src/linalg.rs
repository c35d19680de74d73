//! Small dense kernels shared by the per-vertex and per-edge fits (systems of at most a few
//! dozen unknowns, solved millions of times: no allocation, no library call overhead).

/// Cholesky `a = L L^T` of the `m x m` row-major symmetric `a` into `l` (lower triangle
/// written); false if `a` is not numerically positive definite.
pub(crate) fn cholesky(a: &[f64], m: usize, l: &mut [f64]) -> bool {
    for i in 0..m {
        for j in 0..=i {
            let mut s = a[i * m + j];
            for k in 0..j {
                s -= l[i * m + k] * l[j * m + k];
            }
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return false;
                }
                l[i * m + i] = s.sqrt();
            } else {
                l[i * m + j] = s / l[j * m + j];
            }
        }
    }
    true
}

/// Solves `L L^T x = b` in place for the factor of [`cholesky`].
pub(crate) fn cholesky_solve(l: &[f64], m: usize, b: &mut [f64]) {
    for i in 0..m {
        let mut s = b[i];
        for k in 0..i {
            s -= l[i * m + k] * b[k];
        }
        b[i] = s / l[i * m + i];
    }
    for i in (0..m).rev() {
        let mut s = b[i];
        for k in i + 1..m {
            s -= l[k * m + i] * b[k];
        }
        b[i] = s / l[i * m + i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solves_a_known_system() {
        // a = M M^T + I for a fixed M; x known, b = a x.
        let m = 4;
        let mm = [
            1.0, 2.0, 0.5, -1.0, 0.0, 1.5, 2.0, 0.3, -0.7, 0.2, 1.0, 0.9, 0.4, 0.0, -1.2, 2.0,
        ];
        let mut a = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                a[i * m + j] = (0..m).map(|k| mm[i * m + k] * mm[j * m + k]).sum::<f64>()
                    + if i == j { 1.0 } else { 0.0 };
            }
        }
        let x = [0.3, -1.0, 2.5, 0.7];
        let mut b: Vec<f64> = (0..m)
            .map(|i| (0..m).map(|j| a[i * m + j] * x[j]).sum())
            .collect();
        let mut l = vec![0.0; m * m];
        assert!(cholesky(&a, m, &mut l));
        cholesky_solve(&l, m, &mut b);
        for (got, want) in b.iter().zip(x) {
            assert!((got - want).abs() < 1e-12, "{got} vs {want}");
        }
        // Not positive definite.
        let mut neg = a.clone();
        neg[0] = -1.0;
        assert!(!cholesky(&neg, m, &mut l));
    }
}

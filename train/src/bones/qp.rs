//! The per-vertex weight problem: a small convex QP on the probability simplex.
//!
//! `min_w 1/2 w^T G w - g^T w  s.t.  w >= 0, sum(w) = 1`, solved with a primal active-set method
//! (Nocedal & Wright, "Numerical Optimization", Alg. 16.3) warm-started from the previous
//! weights. The equality-constrained sub-problem on the free set is solved in closed form with a
//! Cholesky factor: `w_F = x - mu y`, `x = G_FF^-1 g_F`, `y = G_FF^-1 1`,
//! `mu = (1^T x - 1) / 1^T y`. All buffers live in [`SimplexQp`] and are reused across vertices.

use crate::linalg::cholesky_solve;

/// Largest candidate set a vertex may have.
pub(crate) const MAX_CANDIDATES: usize = 40;

/// Reusable workspace of the simplex-constrained QP.
#[derive(Debug)]
pub(crate) struct SimplexQp {
    chol: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    wf: Vec<f64>,
    free: Vec<usize>,
    is_free: Vec<bool>,
    mu: f64,
}

impl Default for SimplexQp {
    fn default() -> Self {
        let n = MAX_CANDIDATES;
        Self {
            chol: vec![0.0; n * n],
            x: vec![0.0; n],
            y: vec![0.0; n],
            wf: vec![0.0; n],
            free: Vec::with_capacity(n),
            is_free: vec![false; n],
            mu: 0.0,
        }
    }
}

impl SimplexQp {
    /// Solves the QP over variables `0..n` where `allowed[j]` is true; the others stay 0.
    /// `g_mat` is `n x n` row-major, symmetric positive semi-definite. `w` holds a feasible start
    /// on entry (non-negative, sums to 1, zero where not allowed; if it is not, the start is
    /// the best single allowed variable) and the solution on exit.
    pub(crate) fn solve(
        &mut self,
        n: usize,
        g_mat: &[f64],
        g: &[f64],
        allowed: &[bool],
        w: &mut [f64],
    ) {
        debug_assert!(n <= MAX_CANDIDATES && g_mat.len() >= n * n);
        let sum: f64 = w[..n].iter().sum();
        let feasible = (sum - 1.0).abs() < 1e-6
            && (0..n).all(|j| w[j] >= 0.0 && (allowed[j] || w[j] == 0.0) && w[j].is_finite());
        if !feasible {
            // Best vertex of the simplex: minimise 1/2 G_jj - g_j.
            let best = (0..n).filter(|&j| allowed[j]).min_by(|&a, &b| {
                let fa = 0.5 * g_mat[a * n + a] - g[a];
                let fb = 0.5 * g_mat[b * n + b] - g[b];
                fa.total_cmp(&fb)
            });
            let Some(best) = best else { return };
            w[..n].fill(0.0);
            w[best] = 1.0;
        }
        let ridge = 1e-12 * (0..n).map(|j| g_mat[j * n + j]).fold(0.0f64, f64::max) + 1e-300;
        for (free, &wj) in self.is_free.iter_mut().zip(&w[..n]) {
            *free = wj > 0.0;
        }
        for _ in 0..(4 * n + 10) {
            self.free.clear();
            self.free.extend((0..n).filter(|&j| self.is_free[j]));
            let m = self.free.len();
            if !self.solve_equality(n, g_mat, g, ridge) {
                return; // numerically singular even with the ridge: keep the feasible iterate.
            }
            let blocked = (0..m).any(|a| self.wf[a] < 0.0);
            if !blocked {
                for a in 0..m {
                    w[self.free[a]] = self.wf[a];
                }
                // Multipliers of the bound constraints: lambda_j = (G w - g)_j + mu.
                let mu = self.mu;
                let mut worst = None;
                let mut worst_val =
                    -1e-12 * (1.0 + g.iter().take(n).fold(0.0f64, |a, b| a.max(b.abs())));
                for j in 0..n {
                    if self.is_free[j] || !allowed[j] {
                        continue;
                    }
                    let gw: f64 = self.free.iter().map(|&k| g_mat[j * n + k] * w[k]).sum();
                    let lambda = gw - g[j] + mu;
                    if lambda < worst_val {
                        worst_val = lambda;
                        worst = Some(j);
                    }
                }
                match worst {
                    Some(j) => self.is_free[j] = true,
                    None => return,
                }
            } else {
                // Step towards the sub-problem's optimum until the first weight hits zero.
                let mut alpha = 1.0;
                let mut block = usize::MAX;
                for a in 0..m {
                    let j = self.free[a];
                    if self.wf[a] < 0.0 {
                        let step = w[j] / (w[j] - self.wf[a]);
                        if step < alpha {
                            alpha = step;
                            block = j;
                        }
                    }
                }
                for a in 0..m {
                    let j = self.free[a];
                    w[j] += alpha * (self.wf[a] - w[j]);
                    if w[j] <= 0.0 || j == block {
                        w[j] = 0.0;
                        self.is_free[j] = false;
                    }
                }
                // Keep the iterate exactly on the simplex.
                let s: f64 = w[..n].iter().sum();
                if s > 0.0 {
                    w[..n].iter_mut().for_each(|x| *x /= s);
                }
            }
        }
    }
}

impl SimplexQp {
    /// Solves the equality-constrained problem on `self.free` into `self.wf` (and `self.mu`).
    fn solve_equality(&mut self, n: usize, g_mat: &[f64], g: &[f64], ridge: f64) -> bool {
        let m = self.free.len();
        if m == 0 {
            return false;
        }
        let l = &mut self.chol;
        // Cholesky G_FF + ridge I = L L^T, L stored row-major m x m.
        for a in 0..m {
            for b in 0..=a {
                let mut s = g_mat[self.free[a] * n + self.free[b]];
                if a == b {
                    s += ridge;
                }
                for k in 0..b {
                    s -= l[a * m + k] * l[b * m + k];
                }
                if a == b {
                    if s.is_nan() || s <= 0.0 {
                        return false;
                    }
                    l[a * m + a] = s.sqrt();
                } else {
                    l[a * m + b] = s / l[b * m + b];
                }
            }
        }
        for a in 0..m {
            self.x[a] = g[self.free[a]];
            self.y[a] = 1.0;
        }
        cholesky_solve(l, m, &mut self.x);
        cholesky_solve(l, m, &mut self.y);
        let sx: f64 = self.x[..m].iter().sum();
        let sy: f64 = self.y[..m].iter().sum();
        if sy.is_nan() || sy == 0.0 {
            return false;
        }
        self.mu = (sx - 1.0) / sy;
        for a in 0..m {
            self.wf[a] = self.x[a] - self.mu * self.y[a];
        }
        self.wf[..m].iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn objective(n: usize, gm: &[f64], g: &[f64], w: &[f64]) -> f64 {
        let mut f = 0.0;
        for a in 0..n {
            f -= g[a] * w[a];
            for b in 0..n {
                f += 0.5 * w[a] * gm[a * n + b] * w[b];
            }
        }
        f
    }

    /// Independent reference: the optimum lies on some face of the simplex, where it is the
    /// unconstrained-on-the-face minimiser; enumerate every face and keep the best feasible one.
    fn brute_force(n: usize, gm: &[f64], g: &[f64]) -> (Vec<f64>, f64) {
        let mut best = (vec![0.0; n], f64::INFINITY);
        for mask in 1u32..(1 << n) {
            let idx: Vec<usize> = (0..n).filter(|&j| mask & (1 << j) != 0).collect();
            let m = idx.len();
            // Solve [G_FF 1; 1^T 0] [w; mu] = [g_F; 1] with nalgebra's LU.
            let mut a = nalgebra::DMatrix::<f64>::zeros(m + 1, m + 1);
            let mut b = nalgebra::DVector::<f64>::zeros(m + 1);
            for (r, &i) in idx.iter().enumerate() {
                for (c, &j) in idx.iter().enumerate() {
                    a[(r, c)] = gm[i * n + j];
                }
                a[(r, m)] = 1.0;
                a[(m, r)] = 1.0;
                b[r] = g[i];
            }
            b[m] = 1.0;
            let Some(x) = a.lu().solve(&b) else { continue };
            if (0..m).any(|r| x[r] < -1e-12) {
                continue;
            }
            let mut w = vec![0.0; n];
            for (r, &i) in idx.iter().enumerate() {
                w[i] = x[r].max(0.0);
            }
            let f = objective(n, gm, g, &w);
            if f < best.1 {
                best = (w, f);
            }
        }
        best
    }

    #[test]
    fn matches_face_enumeration_on_random_problems() {
        let mut rng = StdRng::seed_from_u64(7);
        let mut qp = SimplexQp::default();
        for trial in 0..300 {
            let n = 1 + trial % 8;
            let rows = 3 + trial % 5;
            // G = A^T A (PSD, sometimes rank deficient), g = A^T b.
            let a: Vec<f64> = (0..rows * n).map(|_| rng.random_range(-1.0..1.0)).collect();
            let bv: Vec<f64> = (0..rows).map(|_| rng.random_range(-1.0..1.0)).collect();
            let mut gm = vec![0.0; n * n];
            let mut g = vec![0.0; n];
            for i in 0..n {
                for j in 0..n {
                    gm[i * n + j] = (0..rows).map(|r| a[r * n + i] * a[r * n + j]).sum::<f64>()
                        + if i == j { 1e-6 } else { 0.0 };
                }
                g[i] = (0..rows).map(|r| a[r * n + i] * bv[r]).sum();
            }
            let (_, f_ref) = brute_force(n, &gm, &g);
            let mut w = vec![1.0 / n as f64; n];
            qp.solve(n, &gm, &g, &vec![true; n], &mut w);
            assert!(w.iter().all(|&x| x >= 0.0), "negative weight {w:?}");
            assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-9, "sum {w:?}");
            let f = objective(n, &gm, &g, &w);
            assert!(
                f <= f_ref + 1e-7 * (1.0 + f_ref.abs()),
                "trial {trial}: {f} vs reference {f_ref}"
            );
        }
    }

    #[test]
    fn respects_the_allowed_mask_and_repairs_an_infeasible_start() {
        let n = 3;
        // Unconstrained optimum wants all weight on variable 2, which is not allowed.
        let gm = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let g = [0.2, 0.1, 5.0];
        let mut w = [f64::NAN, 0.0, 0.0];
        qp_solve_masked(n, &gm, &g, &[true, true, false], &mut w);
        assert_eq!(w[2], 0.0);
        assert!((w[0] + w[1] - 1.0).abs() < 1e-12);
        assert!((w[0] - 0.55).abs() < 1e-9, "{w:?}"); // minimiser of the 2-variable problem
    }

    fn qp_solve_masked(n: usize, gm: &[f64], g: &[f64], allowed: &[bool], w: &mut [f64]) {
        SimplexQp::default().solve(n, gm, g, allowed, w);
    }
}

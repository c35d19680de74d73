//! Weighted rigid alignment (Kabsch / orthogonal Procrustes) from accumulated sums.

use glam::{Mat3A, Vec3A};
use nalgebra::{Matrix3, Vector3};

/// A rigid transform in the fitter's working form: `x' = m * x + t`, `m` a rotation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Rigid {
    pub m: Mat3A,
    pub t: Vec3A,
}

impl Rigid {
    pub(super) const IDENTITY: Self = Self {
        m: Mat3A::IDENTITY,
        t: Vec3A::ZERO,
    };

    #[inline]
    pub(super) fn apply(&self, p: Vec3A) -> Vec3A {
        self.m * p + self.t
    }
}

/// Sums of a weighted point-pair set `{(w_i, p_i, q_i)}` for the problem
/// `min_{R,T} sum_i w_i |R p_i + T - q_i|^2`. Stored un-centred so sets can be accumulated in
/// one pass; [`PairSums::solve`] centres them.
///
/// The SSDR bone update (Le & Deng 2012, eq. 7) is this problem with weight `w^2`, target `q/w`;
/// callers push `(w^2, p, w*q_target)` through [`PairSums::add_scaled`] so no division is needed.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct PairSums {
    /// sum of weights
    pub sw: f64,
    /// sum w p
    pub sp: [f64; 3],
    /// sum w q
    pub sq: [f64; 3],
    /// sum w p q^T, row-major (a, b) = sum w p_a q_b
    pub h: [[f64; 3]; 3],
}

impl PairSums {
    /// Adds a pair with weight `w`.
    #[inline]
    pub(super) fn add(&mut self, w: f64, p: Vec3A, q: Vec3A) {
        self.add_scaled(w, w, p, q);
    }

    /// Adds a pair where the point weight is `wp` and the target is pre-multiplied: contributes
    /// `wp` to sw, `wp p` to sp, `wq q` to sq and `wq p q^T` to h.
    #[inline]
    pub(super) fn add_scaled(&mut self, wp: f64, wq: f64, p: Vec3A, q: Vec3A) {
        let p = [p.x as f64, p.y as f64, p.z as f64];
        let q = [q.x as f64, q.y as f64, q.z as f64];
        self.sw += wp;
        for a in 0..3 {
            self.sp[a] += wp * p[a];
            self.sq[a] += wq * q[a];
            let wpa = wq * p[a];
            for (h, qb) in self.h[a].iter_mut().zip(q) {
                *h += wpa * qb;
            }
        }
    }

    /// The optimal rigid transform, or `None` when the weights vanish. A rank-deficient set
    /// (one point, collinear points) still yields a proper rotation; `fallback` supplies the
    /// rotation when the covariance is numerically zero (a single point).
    pub(super) fn solve(&self, fallback: Mat3A) -> Option<Rigid> {
        if !self.sw.is_finite() || self.sw <= 1e-300 {
            return None;
        }
        let inv = 1.0 / self.sw;
        let pc = Vector3::new(self.sp[0] * inv, self.sp[1] * inv, self.sp[2] * inv);
        let qc = Vector3::new(self.sq[0] * inv, self.sq[1] * inv, self.sq[2] * inv);
        // Centred covariance: sum w (p - pc)(q - qc)^T = H - sw * pc qc^T.
        let mut h = Matrix3::zeros();
        let mut norm = 0.0;
        for a in 0..3 {
            for b in 0..3 {
                let v = self.h[a][b] - self.sw * pc[a] * qc[b];
                h[(a, b)] = v;
                norm += v * v;
            }
        }
        let r = if norm.sqrt() <= 1e-14 * self.sw.max(1e-300) || !norm.is_finite() {
            let c = fallback.to_cols_array();
            Matrix3::from_column_slice(&c.map(|x| x as f64))
        } else {
            rotation_from_covariance(&h)
        };
        let t = qc - r * pc;
        let m = Mat3A::from_cols(
            Vec3A::new(r[(0, 0)] as f32, r[(1, 0)] as f32, r[(2, 0)] as f32),
            Vec3A::new(r[(0, 1)] as f32, r[(1, 1)] as f32, r[(2, 1)] as f32),
            Vec3A::new(r[(0, 2)] as f32, r[(1, 2)] as f32, r[(2, 2)] as f32),
        );
        let t = Vec3A::new(t[0] as f32, t[1] as f32, t[2] as f32);
        (m.is_finite() && t.is_finite()).then_some(Rigid { m, t })
    }
}

/// R = V diag(1, 1, det(V U^T)) U^T for H = U S V^T (Kabsch 1976; Arun et al. 1987): the
/// proper rotation maximising trace(R H).
fn rotation_from_covariance(h: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = h.svd(true, true);
    let (Some(u), Some(v_t)) = (svd.u, svd.v_t) else {
        return Matrix3::identity();
    };
    let v = v_t.transpose();
    let d = (v * u.transpose()).determinant();
    let mut s = Matrix3::identity();
    if d < 0.0 {
        s[(2, 2)] = -1.0;
    }
    v * s * u.transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};

    #[test]
    fn recovers_a_known_rigid_motion() {
        let q = Quat::from_axis_angle(Vec3::new(1.0, 2.0, -0.5).normalize(), 1.3);
        let m = Mat3A::from_quat(q);
        let t = Vec3A::new(0.3, -2.0, 5.0);
        let pts = [
            Vec3A::new(0.0, 0.0, 0.0),
            Vec3A::new(1.0, 0.2, 0.0),
            Vec3A::new(0.1, 1.0, 0.3),
            Vec3A::new(-0.4, 0.5, 1.2),
        ];
        let mut s = PairSums::default();
        for (i, &p) in pts.iter().enumerate() {
            s.add(1.0 + i as f64, p, m * p + t);
        }
        let r = s.solve(Mat3A::IDENTITY).unwrap();
        for &p in &pts {
            assert!((r.apply(p) - (m * p + t)).length() < 1e-5);
        }
        assert!((r.m.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn never_returns_a_reflection() {
        // Mirror image of a planar set: the best *proper* rotation still has det +1.
        let pts = [
            Vec3A::X,
            Vec3A::Y,
            Vec3A::new(1.0, 1.0, 0.0),
            Vec3A::new(0.3, 0.2, 1.0),
        ];
        let mut s = PairSums::default();
        for &p in &pts {
            s.add(1.0, p, Vec3A::new(-p.x, p.y, p.z));
        }
        let r = s.solve(Mat3A::IDENTITY).unwrap();
        assert!((r.m.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn single_point_uses_fallback_rotation() {
        let mut s = PairSums::default();
        s.add(2.0, Vec3A::new(1.0, 2.0, 3.0), Vec3A::new(4.0, 5.0, 6.0));
        let r = s.solve(Mat3A::IDENTITY).unwrap();
        assert_eq!(r.m, Mat3A::IDENTITY);
        assert!((r.apply(Vec3A::new(1.0, 2.0, 3.0)) - Vec3A::new(4.0, 5.0, 6.0)).length() < 1e-6);
        assert!(PairSums::default().solve(Mat3A::IDENTITY).is_none());
    }
}

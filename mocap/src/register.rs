//! Registration: the recording's frame to the model's, from the back-of-hand markers.
//!
//! HZY11 §7 drives the hand from markers "expressed in the local frame of the hand", estimated
//! from four markers on the back of the hand. Here the model's frame *is* that hand frame: every
//! frame, the similarity `x -> s R x + t` that best puts the registration markers (hand_top,
//! hand_left, hand_right) onto the model's rest positions of the same control points is fitted,
//! and every marker of the frame goes through it. The wrist's motion through the room is
//! removed; what remains (finger markers relative to the back of the hand) is what the model's
//! regression was trained on.
//!
//! - Rotation: Horn's closed form (Horn 1987, "Closed-form solution of absolute orientation
//!   using unit quaternions", §4): the unit quaternion is the eigenvector of the largest
//!   eigenvalue of the symmetric 4×4 matrix built from the cross-covariance of the centred
//!   point sets. It needs at least three non-collinear points.
//! - Scale: fitted once, over the first `calibration_frames` registrable frames, as the
//!   least-squares scale in the model frame, `s = Σ b·(R a) / Σ |a|²` over all calibration
//!   frames' centred points (Horn 1987 §2.D's asymmetric form: the error is measured where the
//!   model lives). Until then the running estimate is used. A scale can also be given.
//! - Translation: `t = b̄ - s R ā` (the centroids coincide).
//! - Fewer than three valid registration markers: the last transform is held (and counted).

use glam::{DMat3, Quat, Vec3};

/// `x -> scale * rotation * x + translation`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Similarity {
    /// Uniform scale (model units per recording unit).
    pub scale: f32,
    /// Rotation.
    pub rotation: Quat,
    /// Translation (model units).
    pub translation: Vec3,
}

impl Similarity {
    /// The identity.
    pub const IDENTITY: Similarity = Similarity {
        scale: 1.0,
        rotation: Quat::IDENTITY,
        translation: Vec3::ZERO,
    };

    /// Maps a point.
    pub fn apply(&self, p: Vec3) -> Vec3 {
        self.scale * (self.rotation * p) + self.translation
    }

    /// The inverse map.
    pub fn inverse(&self) -> Similarity {
        let r = self.rotation.inverse();
        Similarity {
            scale: 1.0 / self.scale,
            rotation: r,
            translation: -(r * self.translation) / self.scale,
        }
    }
}

fn centroid(points: &[Vec3]) -> Vec3 {
    points.iter().copied().sum::<Vec3>() / points.len().max(1) as f32
}

/// The rotation `R` minimising `Σ |R a_i - b_i|²` over centred point sets (Horn 1987 §4),
/// computed in f64. `None` for fewer than three points or a degenerate (collinear) set.
pub fn fit_rotation(a: &[Vec3], b: &[Vec3]) -> Option<Quat> {
    assert_eq!(a.len(), b.len(), "one target per point");
    if a.len() < 3 {
        return None;
    }
    let (ca, cb) = (centroid(a), centroid(b));
    let mut m = [[0.0f64; 3]; 3];
    for (p, q) in a.iter().zip(b) {
        let (p, q) = ((*p - ca).as_dvec3(), (*q - cb).as_dvec3());
        let (p, q) = (p.to_array(), q.to_array());
        for r in 0..3 {
            for c in 0..3 {
                m[r][c] += p[r] * q[c];
            }
        }
    }
    // Degenerate when the source spans less than a plane: the cross-covariance then has rank
    // below two and the optimal rotation is not unique.
    let cov = DMat3::from_cols_array_2d(&m).transpose();
    let scale = m.iter().flatten().map(|v| v.abs()).fold(0.0, f64::max);
    if scale == 0.0 || !scale.is_finite() {
        return None;
    }
    let cross = cov.x_axis.cross(cov.y_axis).length()
        + cov.y_axis.cross(cov.z_axis).length()
        + cov.z_axis.cross(cov.x_axis).length();
    if cross < 1e-9 * scale * scale {
        return None;
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = m;
    // Horn 1987 eq. (§4.A): N's top eigenvector is the quaternion (w, x, y, z).
    #[rustfmt::skip]
    let n = nalgebra::Matrix4::new(
        sxx + syy + szz, syz - szy,       szx - sxz,        sxy - syx,
        syz - szy,       sxx - syy - szz, sxy + syx,        szx + sxz,
        szx - sxz,       sxy + syx,       -sxx + syy - szz, syz + szy,
        sxy - syx,       szx + sxz,       syz + szy,        -sxx - syy + szz,
    );
    let eig = nalgebra::SymmetricEigen::new(n);
    let best = eig.eigenvalues.imax();
    let v = eig.eigenvectors.column(best);
    let q = Quat::from_xyzw(v[1] as f32, v[2] as f32, v[3] as f32, v[0] as f32);
    q.is_finite().then(|| q.normalize())
}

/// The least-squares similarity `b ≈ s R a + t` with `s` free (Horn 1987 §2.D, asymmetric
/// form) or fixed.
pub fn fit_similarity(a: &[Vec3], b: &[Vec3], fixed_scale: Option<f32>) -> Option<Similarity> {
    let rotation = fit_rotation(a, b)?;
    let scale = fixed_scale.unwrap_or_else(|| {
        let (num, den) = scale_sums(a, b, rotation);
        (num / den) as f32
    });
    Some(with_rotation(a, b, rotation, scale))
}

/// The similarity with `rotation` and `scale` that puts the centroid of `a` on that of `b`.
fn with_rotation(a: &[Vec3], b: &[Vec3], rotation: Quat, scale: f32) -> Similarity {
    Similarity {
        scale,
        rotation,
        translation: centroid(b) - scale * (rotation * centroid(a)),
    }
}

/// `(Σ b'·R a', Σ |a'|²)` over the centred sets: the least-squares scale is their ratio.
fn scale_sums(a: &[Vec3], b: &[Vec3], rotation: Quat) -> (f64, f64) {
    let (ca, cb) = (centroid(a), centroid(b));
    a.iter().zip(b).fold((0.0, 0.0), |(n, d), (p, q)| {
        let ra = (rotation * (*p - ca)).as_dvec3();
        let qb = (*q - cb).as_dvec3();
        (n + ra.dot(qb), d + (*p - ca).as_dvec3().length_squared())
    })
}

/// What [`Registration::update`] did with a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Registered {
    /// A transform was fitted to this frame's markers.
    Fitted,
    /// Too few registration markers: the previous frame's transform was reused.
    Held,
    /// No transform yet (no registrable frame so far).
    None,
}

/// Per-frame registration with a scale fitted once (module docs).
#[derive(Clone, Debug)]
pub struct Registration {
    targets: Vec<Vec3>,
    calibration_frames: usize,
    scale: Option<f32>,
    sums: (f64, f64, usize),
    current: Option<Similarity>,
    // Scratch: the valid markers and their targets of one frame.
    a: Vec<Vec3>,
    b: Vec<Vec3>,
}

impl Registration {
    /// Registration onto `targets` (model-frame positions of the registration markers, in the
    /// order [`update`](Self::update) receives them), fitting the scale over the first
    /// `calibration_frames` registrable frames, unless `fixed_scale` is given.
    pub fn new(
        targets: Vec<Vec3>,
        calibration_frames: usize,
        fixed_scale: Option<f32>,
    ) -> Registration {
        let n = targets.len();
        Registration {
            targets,
            calibration_frames: calibration_frames.max(1),
            scale: fixed_scale,
            sums: (0.0, 0.0, 0),
            current: None,
            a: Vec::with_capacity(n),
            b: Vec::with_capacity(n),
        }
    }

    /// The scale once fixed (given, or after the calibration frames).
    pub fn scale(&self) -> Option<f32> {
        self.scale
    }

    /// The current transform, if any frame has been registered.
    pub fn transform(&self) -> Option<Similarity> {
        self.current
    }

    fn collect(&mut self, markers: &[Vec3], valid: &[bool]) -> bool {
        assert_eq!(markers.len(), self.targets.len(), "one marker per target");
        self.a.clear();
        self.b.clear();
        for ((p, ok), t) in markers.iter().zip(valid).zip(&self.targets) {
            if *ok && p.is_finite() {
                self.a.push(*p);
                self.b.push(*t);
            }
        }
        self.a.len() >= 3
    }

    /// Feeds one calibration frame without registering it; returns whether it counted.
    /// Calling this over the first frames of a file before playing it fixes the scale for
    /// every frame, the first ones included.
    pub fn calibrate(&mut self, markers: &[Vec3], valid: &[bool]) -> bool {
        if self.scale.is_some() || !self.collect(markers, valid) {
            return false;
        }
        let Some(rotation) = fit_rotation(&self.a, &self.b) else {
            return false;
        };
        self.accumulate(rotation);
        true
    }

    /// Adds the collected frame, aligned by `rotation`, to the scale fit, and fixes the scale
    /// once `calibration_frames` frames are in.
    fn accumulate(&mut self, rotation: Quat) {
        let (n, d) = scale_sums(&self.a, &self.b, rotation);
        self.sums = (self.sums.0 + n, self.sums.1 + d, self.sums.2 + 1);
        if self.sums.2 >= self.calibration_frames && self.sums.1 > 0.0 {
            self.scale = Some((self.sums.0 / self.sums.1) as f32);
        }
    }

    /// Registers one frame: `markers` and `valid` in target order. While the scale is not
    /// fixed, the frame also counts towards it, and the running estimate is used.
    pub fn update(&mut self, markers: &[Vec3], valid: &[bool]) -> Registered {
        if !self.collect(markers, valid) {
            return self.held();
        }
        let Some(rotation) = fit_rotation(&self.a, &self.b) else {
            return self.held();
        };
        if self.scale.is_none() {
            self.accumulate(rotation);
        }
        let scale = self
            .scale
            .unwrap_or_else(|| (self.sums.0 / self.sums.1) as f32);
        if !(scale.is_finite() && scale > 0.0) {
            return self.held();
        }
        self.current = Some(with_rotation(&self.a, &self.b, rotation, scale));
        Registered::Fitted
    }

    fn held(&self) -> Registered {
        if self.current.is_some() {
            Registered::Held
        } else {
            Registered::None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng, rngs::StdRng};

    fn random_similarity(rng: &mut StdRng) -> Similarity {
        let axis = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize();
        Similarity {
            scale: rng.random_range(0.0005..0.01),
            rotation: Quat::from_axis_angle(axis, rng.random_range(-3.1..3.1)),
            translation: Vec3::new(
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
                rng.random_range(-2.0..2.0),
            ),
        }
    }

    #[test]
    fn recovers_a_known_similarity_from_three_points() {
        let mut rng = StdRng::seed_from_u64(3);
        for _ in 0..50 {
            let truth = random_similarity(&mut rng);
            let a: Vec<Vec3> = (0..3)
                .map(|_| {
                    Vec3::new(
                        rng.random_range(-100.0..100.0),
                        rng.random_range(-100.0..100.0),
                        rng.random_range(-100.0..100.0),
                    )
                })
                .collect();
            let b: Vec<Vec3> = a.iter().map(|p| truth.apply(*p)).collect();
            let fit = fit_similarity(&a, &b, None).expect("three points");
            assert!(
                (fit.scale / truth.scale - 1.0).abs() < 1e-4,
                "{fit:?} {truth:?}"
            );
            assert!(
                fit.rotation.dot(truth.rotation).abs() > 1.0 - 1e-6,
                "{fit:?} {truth:?}"
            );
            // An unrelated point maps where the true transform maps it.
            let p = Vec3::new(37.0, -12.0, 55.0);
            assert!(
                fit.apply(p).distance(truth.apply(p)) < 1e-4 * truth.scale * 100.0 + 1e-5,
                "{} vs {}",
                fit.apply(p),
                truth.apply(p)
            );
            // And the inverse undoes it.
            assert!(fit.inverse().apply(fit.apply(p)).distance(p) < 1e-2);
        }
    }

    #[test]
    fn rejects_collinear_and_too_few_points() {
        let a = [Vec3::ZERO, Vec3::X, 2.0 * Vec3::X];
        assert!(fit_rotation(&a, &a).is_none());
        assert!(fit_rotation(&a[..2], &a[..2]).is_none());
    }

    #[test]
    fn scale_is_fitted_once_then_fixed_and_gaps_hold_the_transform() {
        let mut rng = StdRng::seed_from_u64(9);
        let targets = vec![
            Vec3::new(0.0, 0.06, 0.02),
            Vec3::new(-0.015, 0.0, 0.02),
            Vec3::new(0.015, 0.0, 0.02),
        ];
        let true_scale = 0.00093;
        let mut reg = Registration::new(targets.clone(), 4, None);
        let valid = [true; 3];
        for f in 0..10 {
            // The recording: the targets mapped by the inverse of a moving similarity of one
            // scale (the fitted scale averages over the first four frames, then stays).
            let mut t = random_similarity(&mut rng);
            t.scale = true_scale;
            let inv = t.inverse();
            let markers: Vec<Vec3> = targets.iter().map(|p| inv.apply(*p)).collect();
            assert_eq!(reg.update(&markers, &valid), Registered::Fitted);
            let fit = reg.transform().unwrap();
            if f >= 4 {
                assert_eq!(reg.scale(), Some(fit.scale));
            }
            assert!((fit.scale / true_scale - 1.0).abs() < 1e-4, "{fit:?}");
            for (m, target) in markers.iter().zip(&targets) {
                assert!(fit.apply(*m).distance(*target) < 1e-5);
            }
        }
        let before = reg.transform();
        let markers = [Vec3::ZERO; 3];
        assert_eq!(reg.update(&markers, &[true, false, true]), Registered::Held);
        assert_eq!(reg.transform(), before);
        let mut fresh = Registration::new(targets, 4, None);
        assert_eq!(
            fresh.update(&markers, &[false, false, false]),
            Registered::None
        );
    }
}

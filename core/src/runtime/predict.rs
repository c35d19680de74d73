//! Bone rotations from control points: the run-time half of the regression (FKY08 §4, §6.1;
//! HZY11 §5.1, §6).
//!
//! Bones are grouped by the control points they see: one group holding every control point for
//! the global models (FKY08), one group per distinct set of `k_c` geodesically nearest control
//! points for the geometry-local models (HZY11 §5.1.1). Per frame and group, the kernel vector
//! `xi_l = k(c_g, c_g^l)` over the training examples is computed once (FKY08 eq. 7) and serves
//! every bone of the group:
//!
//! - **global in pose space** (FKY08): one matrix for all the group's bones, `q = M xi + b`
//!   (FKY08 §4.3: `M_b = H_d B_c F_c` collapsed, all bones stacked, §6.1);
//! - **local in pose space** (HZY11 §5.1.2, §6): one model per example pose `i`, trained on the
//!   rotations relative to pose `i` of its `k_p` nearest poses. At run time the `k_p` example
//!   poses nearest to `c_g` each predict a relative rotation `r_i`, brought to the reference
//!   frame as `r_i * q^i`, and the results are blended with heat-kernel weights
//!   `w_i = exp(-|c_g - c_g^i|^2 / 2 sigma^2)` normalised to sum to one (HZY11 eqs. 2–3).
//!
//! Quaternions are blended linearly after sign alignment and normalised. Nothing here allocates
//! per frame: [`RotationScratch`] holds every buffer.

use glam::{Quat, Vec3, Vec4};

use super::kernel::Kernel;

/// Bones that share one control-point subset, and their regression.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ControlGroup {
    /// Indices into the model's control points, ascending.
    pub controls: Vec<u32>,
    /// The bones of this group, in the row order of the matrices (4 rows per bone).
    pub bones: Vec<u32>,
    /// Regression kernel.
    pub kernel: Kernel,
    /// Width of the heat kernel of the pose-space blend (HZY11 eq. 2).
    pub heat_sigma: f32,
    /// Training inputs: `examples x (3 * controls.len())`, row-major.
    pub inputs: Vec<f32>,
    /// The regression of this group.
    pub regression: GroupRegression,
}

/// A linear operator on a kernel vector: `y = m * xi + b`, `m` row-major `rows x cols`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LinearOperator {
    /// Output rows (4 per bone).
    pub rows: usize,
    /// Kernel-vector length (training examples it was fitted on).
    pub cols: usize,
    /// Row-major matrix.
    pub m: Vec<f32>,
    /// Offset, one per row.
    pub b: Vec<f32>,
}

impl LinearOperator {
    /// `out = m * xi + b`: with AVX2 + FMA where the CPU has them and a row has at least 8
    /// columns (`runtime::simd`), else a row at a time.
    #[inline]
    pub fn apply(&self, xi: &[f32], out: &mut [f32]) {
        self.apply_rows(xi, 0, out);
    }

    /// [`LinearOperator::apply`] for the rows `first .. first + out.len()` only (a task's share
    /// of a large operator, e.g. the detail regressor's). An operator of no columns writes `b`.
    ///
    /// # Panics
    /// If the rows run past [`LinearOperator::rows`].
    #[inline]
    pub fn apply_rows(&self, xi: &[f32], first: usize, out: &mut [f32]) {
        debug_assert_eq!(xi.len(), self.cols);
        let b = &self.b[first..first + out.len()];
        if self.cols == 0 {
            out.copy_from_slice(b);
            return;
        }
        let m = &self.m[first * self.cols..(first + out.len()) * self.cols];
        if let Some(simd) = super::simd::fma()
            && super::simd::dot_rows(simd, m, xi, b, out)
        {
            return;
        }
        for ((row, o), b) in m.chunks_exact(self.cols).zip(out.iter_mut()).zip(b) {
            *o = row.iter().zip(xi).map(|(a, x)| a * x).sum::<f32>() + b;
        }
    }

    /// Checks that the sizes agree.
    pub fn validate(&self) -> Result<(), String> {
        if self.m.len() != self.rows * self.cols || self.b.len() != self.rows {
            return Err(format!(
                "operator {}x{}: matrix has {} entries (expected {}), offset {} (expected {})",
                self.rows,
                self.cols,
                self.m.len(),
                self.rows * self.cols,
                self.b.len(),
                self.rows
            ));
        }
        if !self.m.iter().chain(&self.b).all(|x| x.is_finite()) {
            return Err(format!(
                "operator {}x{} has non-finite entries",
                self.rows, self.cols
            ));
        }
        Ok(())
    }
}

/// How a group maps its kernel vector to rotations.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum GroupRegression {
    /// One operator over all training examples (FKY08).
    Global(LinearOperator),
    /// One operator per example pose over its neighbours (HZY11 §5.1.2).
    PoseLocal(Vec<PoseModel>),
}

/// The local model of one example pose.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseModel {
    /// The example poses it was trained on (its `k_p` nearest, itself included).
    pub neighbours: Vec<u32>,
    /// Relative rotations from the neighbours' kernel values: rows = 4 per group bone,
    /// cols = `neighbours.len()`.
    pub operator: LinearOperator,
    /// This pose's rotation of each group bone: relative predictions are composed with it.
    pub base: Vec<Quat>,
}

/// The rotation regression of a whole model.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RotationModel {
    /// Number of control points the model expects.
    pub control_count: usize,
    /// Number of bones.
    pub bone_count: usize,
    /// Training examples (rows of every group's `inputs`).
    pub example_count: usize,
    /// Example poses blended per frame in pose-local groups (`k_p`).
    pub blend_poses: usize,
    /// The bone groups; every bone belongs to exactly one.
    pub groups: Vec<ControlGroup>,
}

/// Reusable per-frame buffers of [`RotationModel::predict`].
#[derive(Clone, Debug, Default)]
pub struct RotationScratch {
    input: Vec<f32>,
    xi: Vec<f32>,
    dist2: Vec<f32>,
    sub_xi: Vec<f32>,
    rows: Vec<f32>,
    order: Vec<u32>,
    weights: Vec<f32>,
    blend: Vec<Vec4>,
}

/// What is wrong with a rotation model.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("rotation model: {0}")]
pub struct RotationModelError(pub String);

impl RotationModel {
    /// Checks every size and index; a model that passes cannot make `predict` panic.
    pub fn validate(&self) -> Result<(), RotationModelError> {
        let err = |s: String| Err(RotationModelError(s));
        let mut seen = vec![false; self.bone_count];
        for (g, group) in self.groups.iter().enumerate() {
            if group.controls.is_empty() {
                return err(format!("group {g} has no control points"));
            }
            if let Some(&c) = group
                .controls
                .iter()
                .find(|&&c| c as usize >= self.control_count)
            {
                return err(format!(
                    "group {g}: control {c} out of range (model has {})",
                    self.control_count
                ));
            }
            let dim = 3 * group.controls.len();
            if group.inputs.len() != self.example_count * dim {
                return err(format!(
                    "group {g}: inputs have {} values, expected {} examples x {dim}",
                    group.inputs.len(),
                    self.example_count
                ));
            }
            for &b in &group.bones {
                let Some(s) = seen.get_mut(b as usize) else {
                    return err(format!(
                        "group {g}: bone {b} out of range (model has {})",
                        self.bone_count
                    ));
                };
                if *s {
                    return err(format!("bone {b} belongs to two groups"));
                }
                *s = true;
            }
            let rows = 4 * group.bones.len();
            match &group.regression {
                GroupRegression::Global(op) => {
                    op.validate()
                        .map_err(|e| RotationModelError(format!("group {g}: {e}")))?;
                    if op.rows != rows || op.cols != self.example_count {
                        return err(format!(
                            "group {g}: operator is {}x{}, expected {rows}x{}",
                            op.rows, op.cols, self.example_count
                        ));
                    }
                }
                GroupRegression::PoseLocal(poses) => {
                    if poses.len() != self.example_count {
                        return err(format!(
                            "group {g}: {} pose models, expected {}",
                            poses.len(),
                            self.example_count
                        ));
                    }
                    for (i, p) in poses.iter().enumerate() {
                        p.operator
                            .validate()
                            .map_err(|e| RotationModelError(format!("group {g} pose {i}: {e}")))?;
                        if p.operator.rows != rows
                            || p.operator.cols != p.neighbours.len()
                            || p.base.len() != group.bones.len()
                        {
                            return err(format!("group {g} pose {i}: sizes disagree"));
                        }
                        if p.neighbours
                            .iter()
                            .any(|&n| n as usize >= self.example_count)
                        {
                            return err(format!("group {g} pose {i}: neighbour out of range"));
                        }
                    }
                }
            }
        }
        if let Some(b) = seen.iter().position(|s| !s) {
            return err(format!("bone {b} belongs to no group"));
        }
        if self.blend_poses == 0 {
            return err("blend_poses must be at least 1".into());
        }
        Ok(())
    }

    /// Predicts every bone's rotation (relative to the rest pose) from the control positions.
    /// `controls` has `control_count` entries (the caller substitutes occluded ones); `out` has
    /// `bone_count`. Non-finite results (only possible from non-finite input) come out as the
    /// identity.
    pub fn predict(&self, controls: &[Vec3], scratch: &mut RotationScratch, out: &mut [Quat]) {
        assert_eq!(controls.len(), self.control_count, "control count");
        assert_eq!(out.len(), self.bone_count, "bone count");
        let n = self.example_count;
        scratch.xi.resize(n, 0.0);
        scratch.dist2.resize(n, 0.0);
        for group in &self.groups {
            scratch.input.clear();
            for &c in &group.controls {
                let p = controls[c as usize];
                scratch.input.extend_from_slice(&[p.x, p.y, p.z]);
            }
            group.kernel.kernel_vector_with_dist2(
                &scratch.input,
                &group.inputs,
                scratch.input.len(),
                &mut scratch.xi,
                &mut scratch.dist2,
            );
            let rows = 4 * group.bones.len();
            scratch.rows.resize(rows, 0.0);
            match &group.regression {
                GroupRegression::Global(op) => {
                    op.apply(&scratch.xi, &mut scratch.rows);
                    for (k, &b) in group.bones.iter().enumerate() {
                        let r = &scratch.rows[4 * k..4 * k + 4];
                        out[b as usize] = to_unit_quat(Vec4::new(r[0], r[1], r[2], r[3]));
                    }
                }
                GroupRegression::PoseLocal(poses) => {
                    self.predict_pose_local(group, poses, scratch, out);
                }
            }
        }
    }

    fn predict_pose_local(
        &self,
        group: &ControlGroup,
        poses: &[PoseModel],
        s: &mut RotationScratch,
        out: &mut [Quat],
    ) {
        // The k_p example poses nearest to the input and their heat-kernel weights (HZY11 §6).
        heat_weights(
            &s.dist2,
            self.blend_poses,
            group.heat_sigma,
            &mut s.order,
            &mut s.weights,
        );
        let nb = group.bones.len();
        s.blend.clear();
        s.blend.resize(nb, Vec4::ZERO);
        for (&i, &w) in s.order.iter().zip(&s.weights) {
            let pose = &poses[i as usize];
            s.sub_xi.clear();
            s.sub_xi
                .extend(pose.neighbours.iter().map(|&l| s.xi[l as usize]));
            pose.operator.apply(&s.sub_xi, &mut s.rows);
            for k in 0..nb {
                let r = &s.rows[4 * k..4 * k + 4];
                // Relative rotation to this pose, brought to the reference frame (HZY11 §6).
                let q = to_unit_quat(Vec4::new(r[0], r[1], r[2], r[3])) * pose.base[k];
                let mut v = Vec4::from(q);
                if s.blend[k].dot(v) < 0.0 {
                    v = -v;
                }
                s.blend[k] += w * v;
            }
        }
        for (k, &b) in group.bones.iter().enumerate() {
            out[b as usize] = to_unit_quat(s.blend[k]);
        }
    }
}

/// Heat-kernel blend of HZY11 eqs. 2–3: `order` receives the `k` examples with the smallest
/// squared distances `dist2` (nearest first) and `weights` their weights
/// `exp(-d^2 / 2 sigma^2)` normalised to sum to one. The exponent is shifted by the smallest
/// distance so the weights cannot all underflow (normalisation cancels the shift); non-finite
/// distances get weight 0, and if every distance is non-finite the first example gets weight 1.
pub fn heat_weights(
    dist2: &[f32],
    k: usize,
    sigma: f32,
    order: &mut Vec<u32>,
    weights: &mut Vec<f32>,
) {
    order.clear();
    weights.clear();
    if dist2.is_empty() {
        return;
    }
    let key = |i: u32| {
        let d = dist2[i as usize];
        if d.is_finite() { d } else { f32::INFINITY }
    };
    order.extend(0..dist2.len() as u32);
    order.sort_unstable_by(|&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    order.truncate(k.clamp(1, dist2.len()));
    let d_min = key(order[0]);
    let two_s2 = 2.0 * sigma * sigma;
    let mut total = 0.0;
    for &i in order.iter() {
        let w = if d_min.is_finite() {
            (-(key(i) - d_min) / two_s2).exp()
        } else {
            0.0
        };
        let w = if w.is_finite() { w } else { 0.0 };
        weights.push(w);
        total += w;
    }
    if total > 0.0 {
        weights.iter_mut().for_each(|w| *w /= total);
    } else {
        weights.iter_mut().for_each(|w| *w = 0.0);
        weights[0] = 1.0;
    }
}

/// Normalises a regressed 4-vector `(x, y, z, w)` to a unit quaternion; the identity when it is
/// zero or not finite.
#[inline]
pub fn to_unit_quat(v: Vec4) -> Quat {
    let len2 = v.length_squared();
    if len2 > 1e-20 && len2.is_finite() {
        Quat::from_vec4(v / len2.sqrt())
    } else {
        Quat::IDENTITY
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heat_weights_sum_to_one_and_pick_the_nearest_pose() {
        let (mut order, mut w) = (Vec::new(), Vec::new());
        // Controls equal example 2 (distance 0): it must come first with the largest weight.
        let d2 = [4.0, 1.0, 0.0, 9.0, 2.5];
        heat_weights(&d2, 3, 1.0, &mut order, &mut w);
        assert_eq!(order, vec![2, 1, 4]);
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        assert!(w[0] > w[1] && w[1] > w[2]);
        // Independent value: exp(-d/2) normalised.
        let e: Vec<f32> = [0.0f32, 1.0, 2.5]
            .iter()
            .map(|d| (-d / 2.0).exp())
            .collect();
        let total: f32 = e.iter().sum();
        for (a, b) in w.iter().zip(&e) {
            assert!((a - b / total).abs() < 1e-6);
        }
        // Far away from everything: no underflow to all-zero, still sums to one.
        heat_weights(&[1e6, 2e6], 2, 0.01, &mut order, &mut w);
        assert_eq!(order[0], 0);
        assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        // NaN distances never win and never produce NaN weights.
        heat_weights(&[f32::NAN, 3.0], 2, 1.0, &mut order, &mut w);
        assert_eq!(order[0], 1);
        assert!(w.iter().all(|x| x.is_finite()));
    }
}

//! How far a frame lies from what the model knows (issue 20): the distance of its control
//! vector to the nearest training example in the regression kernel's own metric,
//! `d(x, y)^2 = k(x, x) + k(y, y) - 2 k(x, y)` (the distance of the two points in the kernel's
//! feature space, FKY08 §4's), scaled so that 1 means "as far as the training example farthest
//! from its nearest neighbour is from that neighbour". 0 at every example; beyond 1 the frame
//! is further out than the training set is spread, and the regression extrapolates.
//!
//! The kernel and examples are those of the model's control group with the most control
//! points (the global models have one group with all of them). A per-frame value costs one
//! kernel vector over the examples.

use glam::Vec3;

use super::predict::RotationModel;

/// The precomputed scale of one model (module docs).
#[derive(Clone, Debug)]
pub struct Confidence {
    /// The control group whose kernel and examples measure the distance.
    group: usize,
    /// `k(x_i, x_i)` per example.
    k_self: Vec<f64>,
    /// The largest nearest-neighbour distance among the examples.
    scale: f64,
}

/// Per-stream buffers of [`Confidence::of`].
#[derive(Clone, Debug, Default)]
pub struct ConfidenceScratch {
    input: Vec<f32>,
    xi: Vec<f32>,
}

impl Confidence {
    /// The confidence scale of `model`; `None` without two examples (nothing to scale by).
    pub fn new(model: &RotationModel) -> Option<Confidence> {
        let (index, group) = model
            .groups
            .iter()
            .enumerate()
            .max_by_key(|(_, g)| g.controls.len())?;
        let dim = 3 * group.controls.len();
        let n = model.example_count;
        if n < 2 || dim == 0 || group.inputs.len() != n * dim {
            return None;
        }
        let row = |i: usize| &group.inputs[i * dim..(i + 1) * dim];
        let k_self: Vec<f64> = (0..n)
            .map(|i| f64::from(group.kernel.eval(row(i), row(i))))
            .collect();
        let mut scale = 0.0f64;
        for i in 0..n {
            let nearest = (0..n)
                .filter(|&j| j != i)
                .map(|j| {
                    let k = f64::from(group.kernel.eval(row(i), row(j)));
                    (k_self[i] + k_self[j] - 2.0 * k).max(0.0)
                })
                .fold(f64::INFINITY, f64::min);
            scale = scale.max(nearest.sqrt());
        }
        (scale > 0.0 && scale.is_finite()).then_some(Confidence {
            group: index,
            k_self,
            scale,
        })
    }

    /// The distance of `controls` (the model's control points, model order) to the nearest
    /// example, in units of the scale (module docs); `model` is the one this was built from.
    /// Allocation-free after the first call on a scratch.
    pub fn of(
        &self,
        model: &RotationModel,
        controls: &[Vec3],
        scratch: &mut ConfidenceScratch,
    ) -> f32 {
        let group = &model.groups[self.group];
        scratch.input.clear();
        for &c in &group.controls {
            scratch
                .input
                .extend_from_slice(&controls[c as usize].to_array());
        }
        scratch.xi.resize(self.k_self.len(), 0.0);
        let dim = scratch.input.len();
        group
            .kernel
            .kernel_vector(&scratch.input, &group.inputs, dim, &mut scratch.xi);
        let x = &scratch.input;
        let kxx = f64::from(group.kernel.eval(x, x));
        let nearest = scratch
            .xi
            .iter()
            .zip(&self.k_self)
            .map(|(&k, &kii)| (kxx + kii - 2.0 * f64::from(k)).max(0.0))
            .fold(f64::INFINITY, f64::min);
        (nearest.sqrt() / self.scale) as f32
    }
}

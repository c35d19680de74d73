//! The detail regressor at run time: HZY11 §5.2's per-vertex displacement `h(c)`, collapsed
//! into one dense matrix so a frame costs one kernel vector and one matrix-vector product for
//! all detailed vertices:
//!
//! ```text
//! h(x) = D xi(x) + b,    xi_l(x) = k(x, x_l),    D: vertices x examples       (HZY11 eq. 4)
//! ```
//!
//! The input `x` is the full control vector (HZY11 §5.2, [`DetailInput::Controls`]) or, for the
//! cascaded baseline of HZY11 Fig. 5c, the bone rotations the base layer predicts
//! ([`DetailInput::Rotations`]). A regressor with no examples is the static baseline of HZY11
//! Fig. 8a: `h = b` in every pose ([`DetailRegressor::fixed`]).
//!
//! Training (one 1-D kernel CCA per vertex) lives in `crease-train`'s `detail::regress`; the
//! per-frame synthesis `S · base + h n` in [`super::detail`].

use glam::Quat;
use serde::{Deserialize, Serialize};

use super::fill_rows;
use super::kernel::Kernel;
use super::predict::LinearOperator;

/// Rows of `D` per rayon task: 4096 rows of ~14 multiply-adds (~20 µs) dwarf the task overhead.
const ROWS_PER_TASK: usize = 4096;

/// What the detail regressor reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DetailInput {
    /// The full control vector, `3 x controls` values (HZY11 §5.2).
    Controls,
    /// The predicted bone rotations, `4 x bones` values: unit quaternions with `w >= 0`,
    /// concatenated (HZY11 Fig. 5c, "cascaded"; see [`rotations_input`]).
    Rotations,
}

impl DetailInput {
    /// The name used in model files and tables.
    pub fn name(self) -> &'static str {
        match self {
            DetailInput::Controls => "controls",
            DetailInput::Rotations => "rotations",
        }
    }
}

/// `h = D xi(x) + b` (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DetailRegressor {
    /// What `x` is.
    pub input: DetailInput,
    /// The kernel of `xi`.
    pub kernel: Kernel,
    /// Input dimension.
    pub d_in: usize,
    /// Training inputs, `examples x d_in` row-major (the `x_l` of `xi`).
    pub examples: Vec<f32>,
    /// `D` (`rows` = detailed vertices, `cols` = examples) and `b`.
    pub operator: LinearOperator,
}

impl DetailRegressor {
    /// The static-detail baseline (HZY11 Fig. 8a): `h` is `rest` in every pose.
    pub fn fixed(input: DetailInput, d_in: usize, rest: Vec<f32>) -> DetailRegressor {
        DetailRegressor {
            input,
            kernel: Kernel::Gaussian { sigma: 1.0 },
            d_in,
            examples: Vec::new(),
            operator: LinearOperator {
                rows: rest.len(),
                cols: 0,
                m: Vec::new(),
                b: rest,
            },
        }
    }

    /// Number of detailed vertices (the length of `h`).
    pub fn vertex_count(&self) -> usize {
        self.operator.rows
    }

    /// Number of training examples (the length of `xi`; 0 for the static baseline).
    pub fn example_count(&self) -> usize {
        self.operator.cols
    }

    /// Whether `h` depends on the pose.
    pub fn is_static(&self) -> bool {
        self.operator.cols == 0
    }

    /// Checks that the sizes agree and every value is finite.
    pub fn validate(&self) -> Result<(), String> {
        self.operator.validate()?;
        if self.d_in == 0 {
            return Err("detail regressor: input dimension is 0".into());
        }
        let expected = self.operator.cols.checked_mul(self.d_in);
        if expected != Some(self.examples.len()) {
            return Err(format!(
                "detail regressor: {} example values for {} examples of dimension {}",
                self.examples.len(),
                self.operator.cols,
                self.d_in
            ));
        }
        if let Some(i) = self.examples.iter().position(|v| !v.is_finite()) {
            return Err(format!("detail regressor: example value {i} is not finite"));
        }
        if !self.kernel.is_valid() {
            return Err(format!(
                "detail regressor: invalid kernel {:?}",
                self.kernel
            ));
        }
        Ok(())
    }

    /// `h = D xi(x) + b` into `out`; `xi` is scratch of at least
    /// [`DetailRegressor::example_count`] values. Rows split over the rayon pool with the
    /// `parallel` feature. Allocates nothing.
    ///
    /// # Panics
    /// If `x` is not `d_in` values, `xi` is too short or `out` is not one value per vertex.
    pub fn predict(&self, x: &[f32], xi: &mut [f32], out: &mut [f32]) {
        assert_eq!(out.len(), self.vertex_count(), "h length != vertices");
        let n = self.example_count();
        self.kernel_vector(x, &mut xi[..n]);
        self.apply(&xi[..n], out);
    }

    /// The kernel vector `xi(x)` (HZY11 eq. 4) into `xi` ([`DetailRegressor::example_count`]
    /// values): all a palette stream's detail frame carries. Allocates nothing.
    ///
    /// # Panics
    /// If `x` is not `d_in` values or `xi` not one per example.
    pub fn kernel_vector(&self, x: &[f32], xi: &mut [f32]) {
        assert_eq!(x.len(), self.d_in, "detail input length != d_in");
        assert_eq!(xi.len(), self.example_count(), "xi length != examples");
        if !xi.is_empty() {
            self.kernel.kernel_vector(x, &self.examples, self.d_in, xi);
        }
    }

    /// `h = D xi + b` for a kernel vector `xi` into `out` ([`LinearOperator::apply_rows`]:
    /// AVX2 with FMA where the CPU has them, else a row at a time).
    /// Rows split over the rayon pool with the `parallel` feature. Allocates nothing.
    ///
    /// # Panics
    /// If `xi` is not one value per example or `out` not one per vertex.
    pub fn apply(&self, xi: &[f32], out: &mut [f32]) {
        assert_eq!(out.len(), self.vertex_count(), "h length != vertices");
        let n = self.example_count();
        assert_eq!(xi.len(), n, "xi length != examples");
        fill_rows(out, ROWS_PER_TASK, |first, rows| {
            self.operator.apply_rows(xi, first, rows)
        });
    }

    /// The rows `first .. first + out.len()` of `h = D xi + b` for a kernel vector `xi` into
    /// `out`, on the calling thread: [`DetailRegressor::apply`] a block at a time, for a detail
    /// synthesis that regresses each block of vertices just before it displaces them
    /// (`DetailSynth::synthesize_regressed`) with a regressor other than the model's own (which
    /// runs from its [`BlockedRows`]). Allocates nothing.
    ///
    /// # Panics
    /// If `xi` is not one value per example or the rows run past the vertices.
    #[inline]
    pub fn apply_rows(&self, xi: &[f32], first: usize, out: &mut [f32]) {
        assert_eq!(xi.len(), self.example_count(), "xi length != examples");
        self.operator.apply_rows(xi, first, out);
    }
}

/// Rows of `D` in one block of a [`BlockedRows`]: one 8-wide register.
pub const ROW_BLOCK: usize = 8;

/// A [`DetailRegressor`]'s `D` and `b` rearranged for the per-frame product (issue 23): blocks
/// of [`ROW_BLOCK`] consecutive rows, each stored column by column (`[block][column][row]`,
/// the last block padded with zero rows). `h` of a block is then `b + sum_l D[.., l] xi_l`: one
/// broadcast and one 8-wide multiply-add a column for eight rows, where a row at a time needs
/// a horizontal sum per row (33 instructions a row with AVX2, ~4 so). The same bytes; built
/// once per model by the predictor, never stored.
#[derive(Clone, Debug, PartialEq)]
pub struct BlockedRows {
    cols: usize,
    blocks: Vec<[f32; ROW_BLOCK]>,
    b: Vec<f32>,
}

impl BlockedRows {
    /// `regressor`'s operator in blocks.
    pub fn new(regressor: &DetailRegressor) -> BlockedRows {
        let op = &regressor.operator;
        let cols = op.cols;
        let mut blocks = vec![[0.0; ROW_BLOCK]; op.rows.div_ceil(ROW_BLOCK) * cols];
        // `m` is `rows x cols` row-major (a validated operator; empty when `cols` is 0).
        for (r, row) in op.m.chunks_exact(cols.max(1)).enumerate() {
            for (l, &v) in row.iter().enumerate() {
                blocks[(r / ROW_BLOCK) * cols + l][r % ROW_BLOCK] = v;
            }
        }
        BlockedRows {
            cols,
            blocks,
            b: op.b.clone(),
        }
    }

    /// Number of rows (vertices).
    pub fn rows(&self) -> usize {
        self.b.len()
    }

    /// Rows `first .. first + out.len()` of `h = D xi + b` into `out` on the calling thread:
    /// whole blocks eight rows at a time (AVX2 + FMA where the CPU has them), rows before the
    /// first block boundary and after the last whole block one at a time. Allocates nothing.
    ///
    /// # Panics
    /// If `xi` is not one value per column or the rows run past the end.
    pub fn apply_rows(&self, xi: &[f32], first: usize, out: &mut [f32]) {
        assert_eq!(xi.len(), self.cols, "xi length != examples");
        assert!(first + out.len() <= self.rows(), "rows past the end");
        let lead = (first.next_multiple_of(ROW_BLOCK) - first).min(out.len());
        let (head, rest) = out.split_at_mut(lead);
        for (k, o) in head.iter_mut().enumerate() {
            *o = self.row(xi, first + k);
        }
        let start = first + lead;
        let whole = rest.len() / ROW_BLOCK * ROW_BLOCK;
        let (body, tail) = rest.split_at_mut(whole);
        if !body.is_empty() {
            let b0 = start / ROW_BLOCK;
            let blocks = &self.blocks[b0 * self.cols..(b0 + whole / ROW_BLOCK) * self.cols];
            let b = &self.b[start..start + whole];
            self.apply_blocks(blocks, xi, b, body);
        }
        for (k, o) in tail.iter_mut().enumerate() {
            *o = self.row(xi, start + whole + k);
        }
    }

    /// Whole blocks: `out` and `b` are `blocks.len() / cols` blocks of rows.
    fn apply_blocks(&self, blocks: &[[f32; ROW_BLOCK]], xi: &[f32], b: &[f32], out: &mut [f32]) {
        if self.cols == 0 {
            out.copy_from_slice(b);
            return;
        }
        if let Some(simd) = super::simd::fma() {
            super::simd::block_rows8(simd, blocks, xi, b, out);
            return;
        }
        blocks_portable(blocks, xi, b, out);
    }

    /// Row `r` alone.
    fn row(&self, xi: &[f32], r: usize) -> f32 {
        let block = &self.blocks[(r / ROW_BLOCK) * self.cols..][..self.cols];
        let lane = r % ROW_BLOCK;
        block.iter().zip(xi).map(|(c, &x)| c[lane] * x).sum::<f32>() + self.b[r]
    }
}

/// [`BlockedRows::apply_blocks`] without SIMD intrinsics (fixed-width arrays the compiler
/// vectorises); `xi` not empty.
fn blocks_portable(blocks: &[[f32; ROW_BLOCK]], xi: &[f32], b: &[f32], out: &mut [f32]) {
    let outs = out
        .chunks_exact_mut(ROW_BLOCK)
        .zip(b.chunks_exact(ROW_BLOCK));
    for ((o, b), block) in outs.zip(blocks.chunks_exact(xi.len())) {
        let mut acc = [0.0f32; ROW_BLOCK];
        acc.copy_from_slice(b);
        for (column, &x) in block.iter().zip(xi) {
            for (a, &d) in acc.iter_mut().zip(column) {
                *a += d * x;
            }
        }
        o.copy_from_slice(&acc);
    }
}

/// The cascaded input of [`DetailInput::Rotations`]: each rotation as a unit quaternion with
/// `w >= 0` (a rotation has two quaternions; the sign is fixed so that nearby rotations give
/// nearby inputs), `[x, y, z, w]` per bone, into `out` (`4 x rotations` values).
///
/// # Panics
/// If `out` is not four values per rotation.
pub fn rotations_input(rotations: &[Quat], out: &mut [f32]) {
    assert_eq!(out.len(), 4 * rotations.len(), "4 values per rotation");
    for (q, o) in rotations.iter().zip(out.chunks_exact_mut(4)) {
        let q = q.normalize();
        let q = if q.w < 0.0 { -q } else { q };
        o.copy_from_slice(&q.to_array());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn static_regressor_returns_b() {
        let r = DetailRegressor::fixed(DetailInput::Controls, 3, vec![0.5, -1.0]);
        r.validate().unwrap();
        let mut out = [9.0; 2];
        r.predict(&[1.0, 2.0, 3.0], &mut [], &mut out);
        assert_eq!(out, [0.5, -1.0]);
    }

    #[test]
    fn predict_is_matrix_times_kernel_vector() {
        // Two examples in 1-D, Gaussian kernel: compare with the sum written out by hand.
        let r = DetailRegressor {
            input: DetailInput::Controls,
            kernel: Kernel::Gaussian { sigma: 2.0 },
            d_in: 1,
            examples: vec![0.0, 1.0],
            operator: LinearOperator {
                rows: 3,
                cols: 2,
                m: vec![1.0, 0.0, 0.0, 1.0, 2.0, -1.0],
                b: vec![0.0, 0.1, 0.2],
            },
        };
        r.validate().unwrap();
        let x = 0.25f32;
        let k = |a: f32| (-(x - a).powi(2) / (2.0 * 2.0 * 2.0)).exp();
        let (k0, k1) = (k(0.0), k(1.0));
        let mut xi = [0.0; 2];
        let mut out = [0.0; 3];
        r.predict(&[x], &mut xi, &mut out);
        let want = [k0, k1 + 0.1, 2.0 * k0 - k1 + 0.2];
        for (g, w) in out.iter().zip(want) {
            assert!((g - w).abs() < 1e-6, "{g} vs {w}");
        }
    }

    #[test]
    fn validate_names_bad_sizes() {
        let mut r = DetailRegressor::fixed(DetailInput::Controls, 3, vec![0.0; 4]);
        r.operator.cols = 1;
        assert!(r.validate().unwrap_err().contains("matrix has 0 entries"));
        let mut r = DetailRegressor::fixed(DetailInput::Controls, 3, vec![0.0; 4]);
        r.examples = vec![1.0];
        assert!(r.validate().unwrap_err().contains("1 example values"));
    }

    /// The blocked product against the rows summed in f64, from every start (inside a block,
    /// on a boundary) and length (partial blocks at both ends), 19 rows of 14 columns.
    #[test]
    fn blocked_rows_equal_f64_sums() {
        let (rows, cols) = (19, 14);
        let m: Vec<f32> = (0..rows * cols)
            .map(|i| ((i * 37 % 101) as f32 - 50.0) * 0.013)
            .collect();
        let b: Vec<f32> = (0..rows).map(|i| i as f32 * 0.1 - 0.7).collect();
        let r = DetailRegressor {
            input: DetailInput::Controls,
            kernel: Kernel::Gaussian { sigma: 1.0 },
            d_in: 1,
            examples: vec![0.0; cols],
            operator: LinearOperator {
                rows,
                cols,
                m: m.clone(),
                b: b.clone(),
            },
        };
        let xi: Vec<f32> = (0..cols).map(|l| (l as f32 * 0.7).cos()).collect();
        let blocked = BlockedRows::new(&r);
        assert_eq!(blocked.rows(), rows);
        for first in 0..rows {
            for len in 0..=rows - first {
                let mut out = vec![f32::NAN; len];
                blocked.apply_rows(&xi, first, &mut out);
                for (k, &got) in out.iter().enumerate() {
                    let row = first + k;
                    let mut want = f64::from(b[row]);
                    let mut scale = f64::from(b[row].abs());
                    for l in 0..cols {
                        let t = f64::from(m[row * cols + l]) * f64::from(xi[l]);
                        want += t;
                        scale += t.abs();
                    }
                    assert!(
                        (f64::from(got) - want).abs() <= 4.0 * f64::from(f32::EPSILON) * scale,
                        "row {row} (first {first}, len {len}): {got} vs {want}"
                    );
                }
            }
        }
        // The portable loop (the kernel above where the CPU has AVX2 + FMA), whole blocks.
        let mut out = vec![f32::NAN; 16];
        blocks_portable(&blocked.blocks[..2 * cols], &xi, &b[..16], &mut out);
        let mut want = vec![f32::NAN; 16];
        blocked.apply_rows(&xi, 0, &mut want);
        for (row, (g, w)) in out.iter().zip(&want).enumerate() {
            assert!(
                (g - w).abs() <= 1e-5 * w.abs().max(1.0),
                "row {row}: {g} vs {w}"
            );
        }
        // No examples: h = b.
        let fixed = BlockedRows::new(&DetailRegressor::fixed(DetailInput::Controls, 3, b.clone()));
        let mut out = vec![0.0; rows];
        fixed.apply_rows(&[], 0, &mut out);
        assert_eq!(out, b);
    }

    #[test]
    fn rotation_inputs_have_positive_w() {
        let q = Quat::from_rotation_x(1.0);
        let mut out = [0.0; 8];
        rotations_input(&[q, -q], &mut out);
        assert_eq!(out[..4], out[4..]);
        assert!(out[3] > 0.0);
    }
}

//! Poisson translation solver (FKY08 §5): given per-bone rotations `R_b` (from the predictor)
//! and the control point positions `c_l`, new bone translations `t_b` that make neighbouring
//! bones agree on the mesh's edges and pull the control vertices onto the control points:
//!
//! ```text
//! min_t  sum_k | (v_k0^s - v_k1^s) - e_k^s |^2  +  beta sum_l | v_{i_l}^s - c_l |^2   (FKY08 eq. 11)
//!   v_i^s = sum_b w_ib (R_b v_i^0 + t_b)          vertex LBS
//!   e_k^s = sum_b R_b a_kb                        edge skin (super::edge_skin)
//! ```
//!
//! FKY08's edge skin is `a_kb = w^_kb e_k^0` with scalar weights from eq. 10; crease fits free
//! vectors `a_kb` instead (see [`super::edge_skin`] for why), which changes nothing below.
//!
//! # Structure used
//!
//! The unknowns enter only through `sum_b w_ib t_b`, so the least-squares matrix `A` is the same
//! for x, y and z: one row per edge with entries `w_k0,b - w_k1,b`, one row per control with
//! entries `sqrt(beta) w_{i_l},b`. The normal matrix
//! `N = A_e^T A_e + beta A_c^T A_c` is `n_b x n_b`, sparse (bones sharing an edge) and fixed:
//! it is factored once with faer's sparse Cholesky (AMD fill-reducing ordering, sequential,
//! simplicial) when the solver is built and again, numerically only, in
//! [`TranslationSolver::set_beta`]. The per-frame substitutions are crease's own
//! (`lower_factor`): the three coordinates share the factor, so each stored entry updates an
//! `[x, y, z, 0]` row with one 4-wide multiply-add instead of three passes of faer's solve.
//!
//! The right-hand side is linear in the rotations: with
//! `q_kb = a_kb - w_k0,b v_k0^0 + w_k1,b v_k1^0`,
//!
//! ```text
//! (A^T T)_a = sum_b R_b K_ab + beta sum_l w_{i_l},a c_l
//! K_ab = sum_k (w_k0,a - w_k1,a) q_kb  -  beta sum_l w_{i_l},a w_{i_l},b v_{i_l}^0
//! ```
//!
//! `K` (3-vectors, non-zero only for bone pairs that share an edge or a control vertex) is
//! precomputed, so a frame costs `nnz(K)` 3x3 mat-vecs, `n_c k` multiply-adds for the controls
//! and one forward/backward substitution pair with three right-hand sides, independent of the
//! vertex and edge counts. FKY08 precompute the dense pseudo-inverse `(A^T A)^-1 A^T` for the GPU;
//! the sparse factor gives the same solution without the dense `n_b x 3 n_b` operator.
//!
//! # Decisions
//!
//! - **Singular systems.** With `beta = 0` or no control points a common translation of all
//!   bones is free; bones that influence no vertex (or the same weight on a whole connected
//!   component) are free too. A ridge of [`RIDGE`] times the largest diagonal entry of `N` is
//!   always added, so `N` is positive definite: free directions solve to (nearly) their
//!   minimum-norm value (an unused bone gets `t = 0`; with `beta = 0` the translations come out
//!   with the global offset that has minimal norm, so the caller must place the result). Its
//!   effect on a well-posed system is a relative change of the order of `RIDGE`.
//! - **Occlusion.** The solver has no notion of a missing control point: the caller substitutes
//!   the last valid position of an occluded marker. A non-finite control (or rotation) is
//!   rejected with [`TranslationError::NonFinite`] and the output is left untouched, so the
//!   previous frame's translations survive.
//! - **Precision.** Everything is assembled and solved in f64 (the rest positions, weights and
//!   rotations arrive in f32); weights are renormalised to sum to one in f64 so that the
//!   global-translation direction is an exact null vector of `A_e`.
//! - **Allocation.** Per-frame buffers live in a [`TranslationScratch`] owned by the caller (one
//!   per stream, from [`TranslationSolver::scratch`]), so one solver can be shared by many
//!   streams; a solve then allocates nothing.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, SymbolicCholesky, SymmetricOrdering, factorize_symbolic_cholesky,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Par, Side};
use glam::{DVec3, Quat, Vec3};

use super::edge_skin::{EdgeSkin, EdgeSkinError};
use super::lower_factor::{LowerFactor, Row4};
use super::simd;
use super::skin::{RigidTransform, SkinError, SkinWeights};

/// Ridge added to the diagonal of the normal matrix, relative to its largest diagonal entry.
/// It makes the singular cases (`beta = 0`, no controls, bones without influence) positive
/// definite. Round-off leaves a component of about `1e-16 |N| |t|` in a null direction, which the
/// ridge turns into a drift of about `1e-16 / RIDGE ~ 1e-7` of the translation scale; on a
/// well-posed system it perturbs the solution by a relative `RIDGE / lambda_min(N) * |N|`, below
/// f32 resolution for the control weights FKY08 use (`beta` of order 1).
pub const RIDGE: f64 = 1e-9;

/// Errors from building or running a [`TranslationSolver`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TranslationError {
    /// A buffer or array has the wrong length.
    #[error("{what}: expected {expected}, got {got}")]
    Size {
        /// Which input ("rest positions", "rotations", "controls", "output", ...).
        what: &'static str,
        /// Length required.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// An index (edge endpoint, control vertex) is out of range.
    #[error("{what} {item}: index {index} out of range, there are {limit}")]
    IndexOutOfRange {
        /// What holds the index ("edge", "control point").
        what: &'static str,
        /// Which edge / control point.
        item: usize,
        /// The offending index.
        index: u32,
        /// How many there are (indices must be below this).
        limit: usize,
    },
    /// The vertex skin names a bone at or beyond `bone_count`.
    #[error("vertex skin: {0}")]
    Skin(#[source] SkinError),
    /// The edge skin names a bone at or beyond `bone_count`.
    #[error("edge skin: {0}")]
    EdgeSkin(#[source] EdgeSkinError),
    /// `beta` is negative or not finite.
    #[error("beta = {beta}: must be finite and >= 0")]
    BadBeta {
        /// The rejected value.
        beta: f32,
    },
    /// Zero bones.
    #[error("the translation solver needs at least one bone")]
    NoBones,
    /// A NaN or infinite input value; on a per-frame call the output is left untouched.
    #[error("{what} {index}: not finite")]
    NonFinite {
        /// Which input ("rest position", "rotation", "control").
        what: &'static str,
        /// Its index.
        index: usize,
    },
    /// The sparse Cholesky factorisation failed (out of memory, or a non-positive pivot, which
    /// the ridge should rule out).
    #[error("sparse Cholesky factorisation failed: {reason}")]
    Factorization {
        /// faer's description.
        reason: String,
    },
}

/// Sparse rows: row `r` owns `idx[ptr[r]..ptr[r + 1]]` and the same range of `val`.
#[derive(Clone, Debug, Default)]
struct Rows<T> {
    ptr: Vec<usize>,
    idx: Vec<u32>,
    val: Vec<T>,
}

impl<T: Copy> Rows<T> {
    fn new() -> Self {
        Self {
            ptr: vec![0],
            idx: Vec::new(),
            val: Vec::new(),
        }
    }

    fn len(&self) -> usize {
        self.ptr.len() - 1
    }

    fn row(&self, r: usize) -> impl Iterator<Item = (usize, T)> + '_ {
        let s = self.ptr[r]..self.ptr[r + 1];
        self.idx[s.clone()]
            .iter()
            .map(|&i| i as usize)
            .zip(self.val[s].iter().copied())
    }

    fn end_row(&mut self) {
        self.ptr.push(self.idx.len());
    }

    /// The transpose, with `cols` rows.
    fn transpose(&self, cols: usize) -> Rows<T> {
        let mut ptr = vec![0usize; cols + 1];
        for &c in &self.idx {
            ptr[c as usize + 1] += 1;
        }
        for c in 0..cols {
            ptr[c + 1] += ptr[c];
        }
        let mut fill = ptr.clone();
        let mut idx = vec![0u32; self.idx.len()];
        let mut val = self.val.clone();
        for r in 0..self.len() {
            for p in self.ptr[r]..self.ptr[r + 1] {
                let c = self.idx[p] as usize;
                idx[fill[c]] = r as u32;
                val[fill[c]] = self.val[p];
                fill[c] += 1;
            }
        }
        Rows { ptr, idx, val }
    }
}

/// Values that can be accumulated as `acc += x * s`.
trait Acc: Copy + Default {
    fn add_scaled(&mut self, x: Self, s: f64);
}

impl Acc for f64 {
    fn add_scaled(&mut self, x: Self, s: f64) {
        *self += x * s;
    }
}

impl Acc for DVec3 {
    fn add_scaled(&mut self, x: Self, s: f64) {
        *self += x * s;
    }
}

impl<T: Acc> Acc for (T, T) {
    fn add_scaled(&mut self, x: Self, s: f64) {
        self.0.add_scaled(x.0, s);
        self.1.add_scaled(x.1, s);
    }
}

/// `L^T R` for row-sparse `L` (scalar) and `R` (same rows), as `cols` sorted sparse rows
/// (Gustavson's row-by-row product over the transpose of `L`). `diagonal` forces entry `(a, a)`
/// into every row.
fn transpose_times<T: Acc>(
    left: &Rows<f64>,
    right: &Rows<T>,
    cols: usize,
    diagonal: bool,
) -> Rows<T> {
    let lt = left.transpose(cols);
    let mut acc = vec![T::default(); cols];
    let mut mark = vec![usize::MAX; cols];
    let mut touched: Vec<usize> = Vec::new();
    let mut out = Rows::new();
    for a in 0..cols {
        touched.clear();
        if diagonal {
            mark[a] = a;
            acc[a] = T::default();
            touched.push(a);
        }
        for (r, la) in lt.row(a) {
            for (b, rb) in right.row(r) {
                if mark[b] != a {
                    mark[b] = a;
                    acc[b] = T::default();
                    touched.push(b);
                }
                acc[b].add_scaled(rb, la);
            }
        }
        touched.sort_unstable();
        for &b in &touched {
            out.idx.push(b as u32);
            out.val.push(acc[b]);
        }
        out.end_row();
    }
    out
}

/// A vertex's influences in f64, renormalised to sum to one, zero weights dropped.
pub(super) fn influences(skin: &SkinWeights, v: usize) -> impl Iterator<Item = (u32, f64)> + '_ {
    let (idx, w) = skin.vertex(v);
    let sum: f64 = w.iter().map(|&x| x as f64).sum();
    idx.iter()
        .zip(w)
        .filter(|(_, w)| **w > 0.0)
        .map(move |(&b, &w)| (b, w as f64 / sum))
}

/// Adds `(bone, value)` into a short unsorted list, merging repeated bones.
fn add_entry<T: Acc>(list: &mut Vec<(u32, T)>, bone: u32, x: T, s: f64) {
    match list.iter_mut().find(|(b, _)| *b == bone) {
        Some((_, v)) => v.add_scaled(x, s),
        None => {
            let mut v = T::default();
            v.add_scaled(x, s);
            list.push((bone, v));
        }
    }
}

/// The Poisson translation solver of FKY08 §5 (eq. 11), factored for one mesh, rig and `beta`.
///
/// Build once per model with [`TranslationSolver::new`]; per frame call
/// [`TranslationSolver::solve`] (or [`apply`](TranslationSolver::apply)) with a
/// [`TranslationScratch`] kept by the caller.
#[derive(Debug)]
pub struct TranslationSolver {
    bones: usize,
    edges: usize,
    beta: f64,
    /// Control points: their vertices' influences (renormalised), one row per control.
    control_w: Rows<f64>,
    /// Normal matrix, upper triangle in compressed columns: column `j` holds rows `i <= j`.
    n_ptr: Vec<usize>,
    n_idx: Vec<usize>,
    /// `A_e^T A_e` and `A_c^T A_c` (without `beta`) on that pattern.
    n_edge: Vec<f64>,
    n_ctrl: Vec<f64>,
    /// `n_edge + beta n_ctrl + ridge` on the diagonal: what was factored.
    n_val: Vec<f64>,
    /// Rotation operator `K_ab` by rows `a`, split into its edge and control parts.
    k_ptr: Vec<usize>,
    k_idx: Vec<u32>,
    k_edge: Vec<DVec3>,
    k_ctrl: Vec<DVec3>,
    /// `k_edge - beta k_ctrl`.
    k_val: Vec<DVec3>,
    symbolic: SymbolicCholesky<usize>,
    /// The numeric factor of `n_val` (simplicial: faer is asked for it), as the per-frame
    /// substitutions read it.
    factor: LowerFactor,
}

/// Per-stream buffers of [`TranslationSolver`]'s per-frame calls. Get one sized for a solver
/// from [`TranslationSolver::scratch`]; a `Default` one is sized by its first solve (the only
/// allocation). Cloning gives a fresh buffer of the same size.
#[derive(Default)]
pub struct TranslationScratch {
    /// Each bone's rotation matrix as its three columns padded to four lanes
    /// (`simd::padded_rotation`), the form the FMA kernel reads; the portable loop rebuilds the
    /// matrix from it (exactly).
    rot: Vec<[f64; 12]>,
    acc: Vec<DVec3>,
    /// Right-hand side and solution, a `[x, y, z, 0]` row per bone in the factor's order.
    y: Vec<Row4>,
}

impl Clone for TranslationScratch {
    /// A scratch of the same size (contents are per-call temporaries and are not copied).
    fn clone(&self) -> Self {
        let mut s = Self::default();
        s.prepare(self.rot.len());
        s
    }
}

impl std::fmt::Debug for TranslationScratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TranslationScratch")
            .field("bones", &self.rot.len())
            .finish()
    }
}

impl TranslationScratch {
    /// Sizes the buffers for `bones` bones.
    fn prepare(&mut self, bones: usize) {
        if self.rot.len() != bones {
            self.rot
                .resize(bones, simd::padded_rotation(Quat::IDENTITY));
            self.acc.resize(bones, DVec3::ZERO);
            self.y.resize(bones, [0.0; 4]);
        }
    }
}

impl TranslationSolver {
    /// Builds and factors the solver.
    ///
    /// - `rest`: rest positions `v_i^0`;
    /// - `edges`: the mesh edges `e_k = v_k0 - v_k1` (e.g. [`crate::mesh::Mesh::edges`]);
    /// - `vertex_skin`: vertex weights `w_ib`, one row per rest vertex;
    /// - `edge_skin`: the edge skin `a_kb` ([`EdgeSkin`]), one row per edge, same order;
    /// - `control_vertices`: the vertex `i_l` of each control point, in the order the controls
    ///   will be passed to [`solve`](Self::solve);
    /// - `bone_count`: number of bones (every skin slot must name a bone below it);
    /// - `beta`: weight of the control term, finite and `>= 0` (see the module docs for
    ///   `beta = 0`).
    pub fn new(
        rest: &[Vec3],
        edges: &[[u32; 2]],
        vertex_skin: &SkinWeights,
        edge_skin: &EdgeSkin,
        control_vertices: &[u32],
        bone_count: usize,
        beta: f32,
    ) -> Result<Self, TranslationError> {
        let n_v = rest.len();
        if bone_count == 0 {
            return Err(TranslationError::NoBones);
        }
        check_beta(beta)?;
        if vertex_skin.vertex_count() != n_v {
            return Err(TranslationError::Size {
                what: "vertex skin rows (one per rest vertex)",
                expected: n_v,
                got: vertex_skin.vertex_count(),
            });
        }
        if edge_skin.edge_count() != edges.len() {
            return Err(TranslationError::Size {
                what: "edge skin rows (one per edge)",
                expected: edges.len(),
                got: edge_skin.edge_count(),
            });
        }
        vertex_skin
            .validate_bones(bone_count)
            .map_err(TranslationError::Skin)?;
        edge_skin
            .validate_bones(bone_count)
            .map_err(TranslationError::EdgeSkin)?;
        if let Some(index) = rest.iter().position(|p| !p.is_finite()) {
            return Err(TranslationError::NonFinite {
                what: "rest position",
                index,
            });
        }
        for (item, e) in edges.iter().enumerate() {
            if let Some(&index) = e.iter().find(|&&v| v as usize >= n_v) {
                return Err(TranslationError::IndexOutOfRange {
                    what: "edge",
                    item,
                    index,
                    limit: n_v,
                });
            }
        }
        if let Some((item, &index)) = control_vertices
            .iter()
            .enumerate()
            .find(|&(_, &v)| v as usize >= n_v)
        {
            return Err(TranslationError::IndexOutOfRange {
                what: "control point",
                item,
                index,
                limit: n_v,
            });
        }

        // Rows of A (left factor) and of the two right factors, edges first, then controls:
        // N = A^T [A_e; 0 | 0; A_c] and K = A^T [Q_e; 0 | 0; Q_c] computed together.
        let mut a_rows = Rows::<f64>::new();
        let mut n_rhs = Rows::<(f64, f64)>::new();
        let mut k_rhs = Rows::<(DVec3, DVec3)>::new();
        let mut d: Vec<(u32, f64)> = Vec::new();
        let mut q: Vec<(u32, DVec3)> = Vec::new();
        for (k, &[i0, i1]) in edges.iter().enumerate() {
            let (i0, i1) = (i0 as usize, i1 as usize);
            let v0 = rest[i0].as_dvec3();
            let v1 = rest[i1].as_dvec3();
            d.clear();
            q.clear();
            for (b, w) in influences(vertex_skin, i0) {
                add_entry(&mut d, b, w, 1.0);
                add_entry(&mut q, b, v0, -w);
            }
            for (b, w) in influences(vertex_skin, i1) {
                add_entry(&mut d, b, w, -1.0);
                add_entry(&mut q, b, v1, w);
            }
            let (bones, vectors) = edge_skin.edge(k);
            for (&b, a) in bones.iter().zip(vectors) {
                if *a != Vec3::ZERO {
                    add_entry(&mut q, b, a.as_dvec3(), 1.0);
                }
            }
            for &(b, x) in d.iter().filter(|(_, x)| *x != 0.0) {
                a_rows.idx.push(b);
                a_rows.val.push(x);
                n_rhs.idx.push(b);
                n_rhs.val.push((x, 0.0));
            }
            for &(b, x) in q.iter().filter(|(_, x)| *x != DVec3::ZERO) {
                k_rhs.idx.push(b);
                k_rhs.val.push((x, DVec3::ZERO));
            }
            a_rows.end_row();
            n_rhs.end_row();
            k_rhs.end_row();
        }
        let mut control_w = Rows::<f64>::new();
        for &i in control_vertices {
            let v = rest[i as usize].as_dvec3();
            d.clear();
            for (b, w) in influences(vertex_skin, i as usize) {
                add_entry(&mut d, b, w, 1.0);
            }
            for &(b, w) in &d {
                a_rows.idx.push(b);
                a_rows.val.push(w);
                n_rhs.idx.push(b);
                n_rhs.val.push((0.0, w));
                k_rhs.idx.push(b);
                k_rhs.val.push((DVec3::ZERO, w * v));
                control_w.idx.push(b);
                control_w.val.push(w);
            }
            a_rows.end_row();
            n_rhs.end_row();
            k_rhs.end_row();
            control_w.end_row();
        }

        let n_full = transpose_times(&a_rows, &n_rhs, bone_count, true);
        let k_op = transpose_times(&a_rows, &k_rhs, bone_count, false);

        // Upper triangle in columns: symmetric, so row j of N is column j; keep rows i <= j.
        let mut n_ptr = vec![0usize];
        let mut n_idx = Vec::new();
        let mut n_edge = Vec::new();
        let mut n_ctrl = Vec::new();
        for j in 0..bone_count {
            for (i, (e, c)) in n_full.row(j).filter(|&(i, _)| i <= j) {
                n_idx.push(i);
                n_edge.push(e);
                n_ctrl.push(c);
            }
            n_ptr.push(n_idx.len());
        }
        let pattern =
            SymbolicSparseColMatRef::new_checked(bone_count, bone_count, &n_ptr, None, &n_idx);
        let symbolic = factorize_symbolic_cholesky(
            pattern,
            Side::Upper,
            SymmetricOrdering::Amd,
            // Simplicial: the per-frame substitutions read its compressed columns
            // (`lower_factor`); at these sizes (bones x bones, a few thousand entries) the
            // supernodal blocks would not pay.
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SIMPLICIAL,
                ..Default::default()
            },
        )
        .map_err(|e| TranslationError::Factorization {
            reason: format!("{e:?}"),
        })?;
        let n_val = vec![0.0; n_idx.len()];
        let k_val = vec![DVec3::ZERO; k_op.idx.len()];
        let (k_edge, k_ctrl) = k_op.val.iter().copied().unzip();
        let mut solver = Self {
            bones: bone_count,
            edges: edges.len(),
            beta: 0.0,
            control_w,
            n_ptr,
            n_idx,
            n_edge,
            n_ctrl,
            n_val,
            k_ptr: k_op.ptr,
            k_idx: k_op.idx,
            k_edge,
            k_ctrl,
            k_val,
            symbolic,
            factor: LowerFactor::default(),
        };
        solver.set_beta(beta)?;
        Ok(solver)
    }

    /// Changes `beta` and refactors (numerically only: the sparsity pattern is unchanged). On
    /// error the solver keeps its previous `beta` and factor.
    pub fn set_beta(&mut self, beta: f32) -> Result<(), TranslationError> {
        check_beta(beta)?;
        let beta = beta as f64;
        let mut n_val = std::mem::take(&mut self.n_val);
        for ((v, &e), &c) in n_val.iter_mut().zip(&self.n_edge).zip(&self.n_ctrl) {
            *v = e + beta * c; // FKY08 eq. 11: N = A_e^T A_e + beta A_c^T A_c
        }
        // The diagonal is the last entry of each upper column (rows sorted, diagonal present).
        let diag = |j: usize| self.n_ptr[j + 1] - 1;
        let max_diag = (0..self.bones)
            .map(|j| n_val[diag(j)])
            .fold(0.0f64, f64::max);
        let ridge = if max_diag > 0.0 {
            RIDGE * max_diag
        } else {
            1.0
        };
        for j in 0..self.bones {
            n_val[diag(j)] += ridge;
        }
        let mut l_values = vec![0.0; self.symbolic.len_val()];
        let result = {
            let symbolic = SymbolicSparseColMatRef::new_checked(
                self.bones,
                self.bones,
                &self.n_ptr,
                None,
                &self.n_idx,
            );
            let mat = SparseColMatRef::new(symbolic, &n_val);
            let mut mem = MemBuffer::new(
                self.symbolic
                    .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            );
            self.symbolic
                .factorize_numeric_llt(
                    &mut l_values,
                    mat,
                    Side::Upper,
                    LltRegularization::default(),
                    Par::Seq,
                    MemStack::new(&mut mem),
                    Default::default(),
                )
                .map(|_| ())
        };
        if let Err(e) = result {
            self.n_val = n_val;
            return Err(TranslationError::Factorization {
                reason: format!("{e:?}"),
            });
        }
        self.n_val = n_val;
        self.factor =
            LowerFactor::new(&self.symbolic, l_values).ok_or(TranslationError::Factorization {
                reason: "faer returned a supernodal factor where a simplicial one was asked for"
                    .into(),
            })?;
        self.beta = beta;
        for ((v, &e), &c) in self.k_val.iter_mut().zip(&self.k_edge).zip(&self.k_ctrl) {
            *v = e - beta * c;
        }
        Ok(())
    }

    /// Solves FKY08 eq. 11 for unit-quaternion rotations (normalised here) and control
    /// positions, writing one translation per bone into `out`. On error `out` is untouched.
    pub fn solve(
        &self,
        rotations: &[Quat],
        controls: &[Vec3],
        scratch: &mut TranslationScratch,
        out: &mut [Vec3],
    ) -> Result<(), TranslationError> {
        self.check_sizes(rotations.len(), controls.len(), out.len())?;
        self.solve_rotations(rotations.iter().copied(), controls, scratch)?;
        self.write(scratch, |a, t| out[a] = t);
        Ok(())
    }

    /// Replaces the translations of `bones` (predicted transforms) by the solution for their
    /// rotations and the controls. On error `bones` is untouched.
    pub fn apply(
        &self,
        bones: &mut [RigidTransform],
        controls: &[Vec3],
        scratch: &mut TranslationScratch,
    ) -> Result<(), TranslationError> {
        self.check_sizes(bones.len(), controls.len(), bones.len())?;
        self.solve_rotations(bones.iter().map(|b| b.rotation), controls, scratch)?;
        self.write(scratch, |a, t| bones[a].translation = t);
        Ok(())
    }

    /// The shared body of the public solves: sizes are checked by the caller; fills the
    /// scratch's rotation matrices and solves into the scratch.
    fn solve_rotations(
        &self,
        rotations: impl Iterator<Item = Quat>,
        controls: &[Vec3],
        scratch: &mut TranslationScratch,
    ) -> Result<(), TranslationError> {
        scratch.prepare(self.bones);
        for (m, q) in scratch.rot.iter_mut().zip(rotations) {
            *m = simd::padded_rotation(q);
        }
        self.solve_prepared(scratch, controls)
    }

    /// A scratch sized for this solver, so that even the first solve allocates nothing.
    pub fn scratch(&self) -> TranslationScratch {
        let mut s = TranslationScratch::default();
        s.prepare(self.bones);
        s
    }

    /// Number of bones (length of the rotation and output slices).
    pub fn bone_count(&self) -> usize {
        self.bones
    }

    /// Number of control points (length of the control slice).
    pub fn control_count(&self) -> usize {
        self.control_w.len()
    }

    /// Number of mesh edges in the edge term.
    pub fn edge_count(&self) -> usize {
        self.edges
    }

    /// Current control weight `beta`.
    pub fn beta(&self) -> f32 {
        self.beta as f32
    }

    /// Stored entries of the rotation operator `K` (3x3 mat-vecs per frame).
    pub fn rotation_operator_len(&self) -> usize {
        self.k_idx.len()
    }

    /// Stored entries of the Cholesky factor.
    pub fn factor_len(&self) -> usize {
        self.factor.stored()
    }

    fn check_sizes(
        &self,
        rotations: usize,
        controls: usize,
        out: usize,
    ) -> Result<(), TranslationError> {
        let checks = [
            ("rotations (one per bone)", self.bones, rotations),
            (
                "controls (one per control point)",
                self.control_count(),
                controls,
            ),
            ("output translations (one per bone)", self.bones, out),
        ];
        for (what, expected, got) in checks {
            if expected != got {
                return Err(TranslationError::Size {
                    what,
                    expected,
                    got,
                });
            }
        }
        Ok(())
    }

    /// With `scratch.rot` filled: builds the right-hand side and solves in place into
    /// `scratch.rhs`.
    fn solve_prepared(
        &self,
        scratch: &mut TranslationScratch,
        controls: &[Vec3],
    ) -> Result<(), TranslationError> {
        if let Some(index) = scratch
            .rot
            .iter()
            .position(|m| !m.iter().all(|x| x.is_finite()))
        {
            return Err(TranslationError::NonFinite {
                what: "rotation",
                index,
            });
        }
        if let Some(index) = controls.iter().position(|c| !c.is_finite()) {
            return Err(TranslationError::NonFinite {
                what: "control",
                index,
            });
        }
        let n = self.bones;
        // A^T T = sum_b R_b K_ab + beta sum_l w_la c_l (FKY08 eq. 11, right-hand side).
        if let Some(simd) = simd::fma() {
            simd::rotate_sum(
                simd,
                &self.k_ptr,
                &self.k_idx,
                &self.k_val,
                &scratch.rot,
                &mut scratch.acc,
            );
        } else {
            for a in 0..n {
                let mut s = DVec3::ZERO;
                for p in self.k_ptr[a]..self.k_ptr[a + 1] {
                    s += simd::unpad_columns(&scratch.rot[self.k_idx[p] as usize]) * self.k_val[p];
                }
                scratch.acc[a] = s;
            }
        }
        for (l, c) in controls.iter().enumerate() {
            let c = self.beta * c.as_dvec3();
            for (b, w) in self.control_w.row(l) {
                scratch.acc[b] += w * c;
            }
        }
        let acc = &scratch.acc;
        self.factor
            .solve(|a| [acc[a].x, acc[a].y, acc[a].z, 0.0], &mut scratch.y);
        Ok(())
    }

    /// Hands each bone's solved translation to `set(bone, t)`.
    fn write(&self, scratch: &TranslationScratch, mut set: impl FnMut(usize, Vec3)) {
        for (a, r) in self.factor.solution(&scratch.y) {
            set(a, Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32));
        }
    }
}

fn check_beta(beta: f32) -> Result<(), TranslationError> {
    if beta.is_finite() && beta >= 0.0 {
        Ok(())
    } else {
        Err(TranslationError::BadBeta { beta })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)] // dense matrix indices read clearer than iterators
    fn transpose_times_matches_dense() {
        // L: 3 rows x 4 cols, R: 3 rows x 4 cols (scalar).
        let mut l = Rows::<f64>::new();
        let mut r = Rows::<f64>::new();
        let dense_l = [
            [1.0, 0.0, 2.0, 0.0],
            [0.0, 3.0, 0.0, 0.0],
            [4.0, 0.0, 0.0, 5.0],
        ];
        let dense_r = [
            [0.0, 1.0, 0.0, 2.0],
            [6.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 7.0, 1.0],
        ];
        for row in 0..3 {
            for c in 0..4 {
                if dense_l[row][c] != 0.0 {
                    l.idx.push(c as u32);
                    l.val.push(dense_l[row][c]);
                }
                if dense_r[row][c] != 0.0 {
                    r.idx.push(c as u32);
                    r.val.push(dense_r[row][c]);
                }
            }
            l.end_row();
            r.end_row();
        }
        let p = transpose_times(&l, &r, 4, true);
        for a in 0..4 {
            let mut dense_row = [0.0; 4];
            for (b, v) in p.row(a) {
                dense_row[b] = v;
            }
            for (b, &got) in dense_row.iter().enumerate() {
                let want: f64 = (0..3).map(|k| dense_l[k][a] * dense_r[k][b]).sum();
                assert_eq!(got, want, "({a}, {b})");
            }
            assert!(p.row(a).any(|(b, _)| b == a), "diagonal present in row {a}");
            let cols: Vec<usize> = p.row(a).map(|(b, _)| b).collect();
            assert!(cols.windows(2).all(|w| w[0] < w[1]), "sorted row {a}");
        }
    }
}

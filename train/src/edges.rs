//! Edge skinning weights (FKY08 §5, eq. 10) for the Poisson translation solver
//! ([`crease_core::runtime::translations`]).
//!
//! Each mesh edge `e_k = v_k0 - v_k1` is skinned like a vertex, but as a direction: rotations
//! only, translations cancel. Its weights minimise the fit over the example frames `j`
//!
//! ```text
//! min_w  sum_j | e_k^j - sum_b w_b R_b^j e_k^0 |^2   s.t.  w >= 0, sum w = 1, |w|_0 <= K   (eq. 10)
//! ```
//!
//! With `a_b` the stacked `R_b^j e_k^0` over frames this is the simplex QP of
//! `bones::qp` with `G = A^T A`, `g = A^T e`, the same problem the vertex weights solve
//! (see `bones::weights`). Candidates are the bones influencing either endpoint; the QP starts
//! from the endpoints' averaged weights; the sparsity bound is met by keeping the `K` largest
//! weights and solving again on them, and if that loses to the averaged weights (when those are
//! `K`-sparse themselves) the averaged weights are kept, so an edge never fits worse than the
//! blend of its endpoints.
//!
//! A zero-length rest edge has no direction to fit: it gets its endpoints' averaged weights
//! (the `K` largest, renormalised). So does every edge when there are no frames.

use crease_core::glam::{Mat3A, Quat, Vec3, Vec3A};
use crease_core::mesh::Mesh;
use crease_core::runtime::edge_skin::{EdgeSkin, EdgeSkinError};
use crease_core::runtime::skin::{MAX_INFLUENCES, SkinError, SkinWeights};

use crate::bones::qp::{MAX_CANDIDATES, SimplexQp};
use crate::linalg::{cholesky, cholesky_solve};
use crate::par;

/// Edges per parallel work item: one edge costs a few µs (Gram matrix over the frames plus a
/// QP of at most `2K` variables), so 256 edges make a task of about a millisecond.
const CHUNK: usize = 256;

/// Why edge weights could not be fitted.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EdgeWeightError {
    /// `k` outside `1..=MAX_INFLUENCES`.
    #[error("edge influences k = {k}, must be in 1..={MAX_INFLUENCES}")]
    BadK {
        /// The rejected value.
        k: usize,
    },
    /// A length does not match.
    #[error("{what}: expected {expected}, got {got}")]
    Size {
        /// Which input ("frame 3 vertices", "rotation sets (one per frame)", ...).
        what: String,
        /// Length required.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// An edge names a vertex that does not exist.
    #[error("edge {edge}: vertex {vertex} out of range, the mesh has {vertex_count}")]
    EdgeOutOfRange {
        /// Edge index.
        edge: usize,
        /// The offending vertex index.
        vertex: u32,
        /// Number of vertices.
        vertex_count: usize,
    },
    /// The vertex skin names a bone that has no rotation.
    #[error("vertex skin: {0}")]
    Skin(#[source] SkinError),
    /// The fitted edge skin was rejected (a non-finite vector).
    #[error("edge skin: {0}")]
    EdgeSkin(#[from] EdgeSkinError),
    /// A non-finite coordinate or rotation.
    #[error("{what}: not finite")]
    NonFinite {
        /// Where ("frame 2 vertex 17", "rotation of bone 4 in frame 0", "rest vertex 3").
        what: String,
    },
}

/// Fits `k` weights per edge (FKY08 eq. 10); one [`SkinWeights`] row per entry of `edges`.
///
/// - `rest`: the rest mesh (only its positions are used);
/// - `edges`: the edges to fit, usually `rest.edges()`; row `k` of the result is edge `k`;
/// - `frames`: example poses sharing the rest pose's vertex order;
/// - `rotations`: per frame, per bone, the bone rotation `R_b^j` (from the bone fit);
/// - `vertex_skin`: the vertex weights, whose bones are the candidates;
/// - `k`: most bones per edge (`1..=8`), usually the vertex `K`.
///
/// # Panics
/// On inconsistent inputs (see [`try_fit_edge_weights`] for the checked version): sizes that do
/// not match, out-of-range indices, non-finite values, `k` out of range.
pub fn fit_edge_weights(
    rest: &Mesh,
    edges: &[[u32; 2]],
    frames: &[&[Vec3]],
    rotations: &[Vec<Quat>],
    vertex_skin: &SkinWeights,
    k: usize,
) -> SkinWeights {
    try_fit_edge_weights(&rest.positions, edges, frames, rotations, vertex_skin, k)
        .unwrap_or_else(|e| panic!("fit_edge_weights: {e}"))
}

/// [`fit_edge_weights`] with the inputs checked: an error names the first inconsistency.
/// `rotations` holds one slice of per-bone rotations per frame (`Vec<Quat>` or `&[Quat]`).
pub fn try_fit_edge_weights<R: AsRef<[Quat]> + Sync>(
    rest: &[Vec3],
    edges: &[[u32; 2]],
    frames: &[&[Vec3]],
    rotations: &[R],
    vertex_skin: &SkinWeights,
    k: usize,
) -> Result<SkinWeights, EdgeWeightError> {
    let input = Input::new(rest, edges, frames, rotations, vertex_skin, k)?;
    let f = frames.len();
    let mut out: Vec<(u32, f32)> = vec![(0, 0.0); edges.len() * k];
    par::map_chunks_mut(
        &mut out,
        CHUNK * k,
        || Scratch::new(f),
        |s, c, chunk| {
            for (j, slots) in chunk.chunks_mut(k).enumerate() {
                fit_edge(&input, c * CHUNK + j, s, slots);
            }
        },
    );
    let (indices, weights) = out.into_iter().unzip();
    SkinWeights::new(k, indices, weights).map_err(EdgeWeightError::Skin)
}

fn check<R: AsRef<[Quat]>>(
    rest: &[Vec3],
    edges: &[[u32; 2]],
    frames: &[&[Vec3]],
    rotations: &[R],
    vertex_skin: &SkinWeights,
    k: usize,
) -> Result<(), EdgeWeightError> {
    if !(1..=MAX_INFLUENCES).contains(&k) {
        return Err(EdgeWeightError::BadK { k });
    }
    if vertex_skin.vertex_count() != rest.len() {
        return Err(EdgeWeightError::Size {
            what: "vertex skin rows (one per rest vertex)".into(),
            expected: rest.len(),
            got: vertex_skin.vertex_count(),
        });
    }
    check_frames(rest, edges, frames, rotations)?;
    check_weighted_bones(vertex_skin, frames, rotations)
}

/// Every weighted slot of `skin` names a bone that has a rotation (padding slots name bone 0
/// by convention and are not checked). Nothing to check without frames.
fn check_weighted_bones<R: AsRef<[Quat]>>(
    skin: &SkinWeights,
    frames: &[&[Vec3]],
    rotations: &[R],
) -> Result<(), EdgeWeightError> {
    if frames.is_empty() {
        return Ok(());
    }
    let bones = rotations.first().map_or(0, |r| r.as_ref().len());
    for (row, (idx, w)) in skin.iter().enumerate() {
        if let Some(slot) = (0..idx.len()).find(|&s| w[s] > 0.0 && idx[s] as usize >= bones) {
            return Err(EdgeWeightError::Skin(SkinError::BoneOutOfRange {
                vertex: row,
                slot,
                bone: idx[slot],
                bone_count: bones,
            }));
        }
    }
    Ok(())
}

/// Checked inputs, in the layout the per-edge loops want (the vertex weights give the
/// candidate bones of an edge's endpoints).
struct Input<'a> {
    rest: &'a [Vec3],
    edges: &'a [[u32; 2]],
    frames: &'a [&'a [Vec3]],
    /// Rotations as matrices, frame-major `[j * bones + b]`.
    rot: Vec<Mat3A>,
    bones: usize,
    skin: &'a SkinWeights,
    k: usize,
}

impl<'a> Input<'a> {
    /// Checks the inputs ([`check`]) and lays them out for the per-edge loops.
    fn new<R: AsRef<[Quat]>>(
        rest: &'a [Vec3],
        edges: &'a [[u32; 2]],
        frames: &'a [&'a [Vec3]],
        rotations: &[R],
        skin: &'a SkinWeights,
        k: usize,
    ) -> Result<Self, EdgeWeightError> {
        check(rest, edges, frames, rotations, skin, k)?;
        Ok(Self {
            rest,
            edges,
            frames,
            rot: rotations
                .iter()
                .flat_map(|r| r.as_ref().iter().map(|&q| Mat3A::from_quat(q)))
                .collect(),
            bones: rotations.first().map_or(0, |r| r.as_ref().len()),
            skin,
            k,
        })
    }
}

/// Per-worker buffers, reused across edges.
struct Scratch {
    qp: SimplexQp,
    cands: Vec<u32>,
    /// Columns `R_b^j e^0`, candidate-major `[a * frames + j]`.
    cols: Vec<Vec3A>,
    /// The edge in each frame.
    target: Vec<Vec3A>,
    gram: Vec<f64>,
    rhs: Vec<f64>,
    w: Vec<f64>,
    avg: Vec<f64>,
    allowed: Vec<bool>,
    order: Vec<usize>,
}

impl Scratch {
    fn new(frames: usize) -> Self {
        Self {
            qp: SimplexQp::default(),
            cands: Vec::with_capacity(MAX_CANDIDATES),
            cols: vec![Vec3A::ZERO; MAX_CANDIDATES * frames],
            target: vec![Vec3A::ZERO; frames],
            gram: vec![0.0; MAX_CANDIDATES * MAX_CANDIDATES],
            rhs: vec![0.0; MAX_CANDIDATES],
            w: vec![0.0; MAX_CANDIDATES],
            avg: vec![0.0; MAX_CANDIDATES],
            allowed: vec![false; MAX_CANDIDATES],
            order: Vec::with_capacity(MAX_CANDIDATES),
        }
    }
}

/// Fits edge `e` into its `k` output slots (unused slots stay `(0, 0.0)`).
fn fit_edge(input: &Input<'_>, e: usize, s: &mut Scratch, out: &mut [(u32, f32)]) {
    let k = input.k;
    let f = input.frames.len();
    let [i0, i1] = input.edges[e].map(|v| v as usize);

    // Candidates: the weighted bones of both endpoints (at most 2 * 8 <= MAX_CANDIDATES), with
    // the endpoints' averaged weights.
    s.cands.clear();
    s.avg[..MAX_CANDIDATES].fill(0.0);
    for v in [i0, i1] {
        let (idx, w) = input.skin.vertex(v);
        for (&b, &w) in idx.iter().zip(w) {
            if w <= 0.0 {
                continue;
            }
            let a = match s.cands.iter().position(|&c| c == b) {
                Some(a) => a,
                None => {
                    s.cands.push(b);
                    s.cands.len() - 1
                }
            };
            s.avg[a] += 0.5 * w as f64;
        }
    }
    let n = s.cands.len();
    let sum: f64 = s.avg[..n].iter().sum();
    s.avg[..n].iter_mut().for_each(|w| *w /= sum);

    let e0 = Vec3A::from(input.rest[i0] - input.rest[i1]);
    if n == 1 || f == 0 || e0.length_squared() == 0.0 {
        s.w[..n].copy_from_slice(&s.avg[..n]);
        keep_largest(s, n, k);
        write(s, n, k, out);
        return;
    }

    // FKY08 eq. 10 as a QP: columns a_b = (R_b^j e^0)_j, G = A^T A, g = A^T (e^j)_j.
    for (j, t) in s.target.iter_mut().enumerate() {
        let frame = input.frames[j];
        *t = Vec3A::from(frame[i0] - frame[i1]);
    }
    for (a, &b) in s.cands.iter().enumerate() {
        for j in 0..f {
            s.cols[a * f + j] = input.rot[j * input.bones + b as usize] * e0;
        }
    }
    for a in 0..n {
        let ca = &s.cols[a * f..(a + 1) * f];
        s.rhs[a] = ca
            .iter()
            .zip(&s.target)
            .map(|(c, t)| c.dot(*t) as f64)
            .sum();
        for b in 0..=a {
            let cb = &s.cols[b * f..(b + 1) * f];
            let g: f64 = ca.iter().zip(cb).map(|(x, y)| x.dot(*y) as f64).sum();
            s.gram[a * n + b] = g;
            s.gram[b * n + a] = g;
        }
    }
    let f_avg = objective(n, &s.gram, &s.rhs, &s.avg);
    let avg_nnz = s.avg[..n].iter().filter(|&&w| w > 0.0).count();

    s.w[..n].copy_from_slice(&s.avg[..n]);
    s.allowed[..n].fill(true);
    s.qp.solve(n, &s.gram, &s.rhs, &s.allowed, &mut s.w);
    // Sparsity: keep the K largest and re-solve on them.
    if s.w[..n].iter().filter(|&&w| w > 0.0).count() > k {
        keep_largest(s, n, k);
        s.qp.solve(n, &s.gram, &s.rhs, &s.allowed, &mut s.w);
    }
    // Never fit worse than the endpoints' blend when that blend is itself admissible.
    let f_w = objective(n, &s.gram, &s.rhs, &s.w);
    if avg_nnz <= k && (f_w.is_nan() || f_w > f_avg) {
        s.w[..n].copy_from_slice(&s.avg[..n]);
    }
    write(s, n, k, out);
}

/// Zeroes all but the `k` largest of `s.w[..n]`, renormalises, and marks the kept ones in
/// `s.allowed`.
fn keep_largest(s: &mut Scratch, n: usize, k: usize) {
    s.allowed[..n].fill(true);
    if s.w[..n].iter().filter(|&&w| w > 0.0).count() <= k {
        return;
    }
    s.order.clear();
    s.order.extend(0..n);
    let w = &s.w;
    s.order.sort_by(|&a, &b| w[b].total_cmp(&w[a]));
    s.allowed[..n].fill(false);
    for &a in &s.order[..k] {
        s.allowed[a] = true;
    }
    for a in 0..n {
        if !s.allowed[a] {
            s.w[a] = 0.0;
        }
    }
    let kept: f64 = s.w[..n].iter().sum();
    s.w[..n].iter_mut().for_each(|w| *w /= kept);
}

/// The non-zero weights of `s.w[..n]` (at most `k`) into the output slots, summing to one in f32.
fn write(s: &Scratch, n: usize, k: usize, out: &mut [(u32, f32)]) {
    out.fill((0, 0.0));
    let mut slot = 0;
    for a in 0..n {
        if s.w[a] > 0.0 && slot < k {
            out[slot] = (s.cands[a], s.w[a] as f32);
            slot += 1;
        }
    }
    let sum: f32 = out.iter().map(|x| x.1).sum();
    if slot == 0 || sum.is_nan() || sum <= 0.0 {
        // Unreachable with a non-empty candidate set; keep the row valid regardless.
        out.fill((0, 0.0));
        out[0] = (s.cands.first().copied().unwrap_or(0), 1.0);
    } else {
        out.iter_mut().for_each(|x| x.1 /= sum);
    }
}

/// `1/2 w^T G w - g^T w` (eq. 10 up to the constant `sum_j |e^j|^2 / 2`).
fn objective(n: usize, gram: &[f64], rhs: &[f64], w: &[f64]) -> f64 {
    let mut f = 0.0;
    for a in 0..n {
        if w[a] == 0.0 {
            continue;
        }
        let gw: f64 = (0..n).map(|b| gram[a * n + b] * w[b]).sum();
        f += w[a] * (0.5 * gw - rhs[a]);
    }
    f
}

// ---------------------------------------------------------------------------------------------
// Vector edge skin: e_k^j ~ sum_b R_b^j a_kb with free rest-frame vectors a_kb.

/// Ridge candidates of the vector edge fit, relative (`lambda = ridge * frames`; a rotation
/// block `R^T R` is the identity, so `frames` is the scale of the normal matrix's diagonal).
/// `f64::INFINITY` stands for FKY08's scalar eq. 10 weights (the ridge's prior), so the
/// cross-validation can also decide that the vectors do not generalise.
pub const EDGE_RIDGES: [f64; 6] = [1e-6, 1e-5, 1e-4, 1e-3, 1e-2, f64::INFINITY];

/// Folds of the cross-validation that picks the ridge.
pub const EDGE_CV_FOLDS: usize = 5;

/// Every `EDGE_CV_STRIDE`-th edge enters the cross-validation (the choice is global, and a
/// quarter of the horse's 25,000 edges pins it down as well as all of them).
pub const EDGE_CV_STRIDE: usize = 4;

/// How the ridge of [`fit_edge_vectors`] is chosen, and what the cross-validation saw.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EdgeVectorReport {
    /// The ridge used (`inf`: scalar eq. 10 weights).
    pub ridge: f64,
    /// Per candidate ridge, the held-out relative edge error `sqrt(sum |r|^2 / sum |e|^2)`
    /// over the cross-validation folds (empty when the ridge was given).
    pub cv: Vec<(f64, f64)>,
}

/// Fits the vector edge skin ([`EdgeSkin`], see `crease_core::runtime::edge_skin`): per edge,
/// on the `k` bones that weigh most in its endpoints' averaged vertex weights `w^_kb`, free
/// rest-frame vectors `a_kb` minimising
///
/// ```text
/// sum_j | e_k^j - sum_b R_b^j a_kb |^2  +  lambda sum_b | a_kb - w^_kb e_k^0 |^2
/// ```
///
/// FKY08 eq. 10's residual with the scalar form lifted, regularised toward the endpoints'
/// blend (`lambda = ridge * frames`). With the endpoints' bones each vector can absorb what
/// the bone's rotation does to both ends of the edge, so the edge follows the vertex skin's
/// own stretch. `ridge = None` picks it from [`EDGE_RIDGES`] by [`EDGE_CV_FOLDS`]-fold
/// cross-validation over the frames (held-out relative edge error; every
/// [`EDGE_CV_STRIDE`]-th edge), then fits all frames with it.
///
/// Inputs as for [`try_fit_edge_weights`].
pub fn fit_edge_vectors<R: AsRef<[Quat]> + Sync>(
    rest: &[Vec3],
    edges: &[[u32; 2]],
    frames: &[&[Vec3]],
    rotations: &[R],
    vertex_skin: &SkinWeights,
    k: usize,
    ridge: Option<f64>,
) -> Result<(EdgeSkin, EdgeVectorReport), EdgeWeightError> {
    if let Some(r) = ridge.filter(|r| r.is_nan() || *r < 0.0) {
        return Err(EdgeWeightError::NonFinite {
            what: format!("edge ridge {r} (must be >= 0)"),
        });
    }
    let sys = Input::new(rest, edges, frames, rotations, vertex_skin, k)?;

    let (ridge, cv) = match ridge {
        Some(r) => (r, Vec::new()),
        None if frames.len() < 2 => (f64::INFINITY, Vec::new()),
        None => {
            let folds = EDGE_CV_FOLDS.min(frames.len());
            let picked: Vec<usize> = (0..edges.len()).step_by(EDGE_CV_STRIDE).collect();
            let sums = par::map_range(
                picked.len().div_ceil(CHUNK),
                || EdgeSystem::new(frames.len()),
                |s, c| {
                    let mut acc = [[0.0f64; 2]; EDGE_RIDGES.len()];
                    for &e in &picked[c * CHUNK..((c + 1) * CHUNK).min(picked.len())] {
                        s.build(&sys, e);
                        s.cross_validate(folds, &mut acc);
                    }
                    acc
                },
            );
            let mut total = [[0.0f64; 2]; EDGE_RIDGES.len()];
            for acc in sums {
                for (t, a) in total.iter_mut().zip(acc) {
                    t[0] += a[0];
                    t[1] += a[1];
                }
            }
            let cv: Vec<(f64, f64)> = EDGE_RIDGES
                .iter()
                .zip(total)
                .map(|(&r, [num, den])| (r, (num / den.max(f64::MIN_POSITIVE)).sqrt()))
                .collect();
            let best = cv
                .iter()
                .filter(|c| c.1.is_finite())
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map_or(f64::INFINITY, |c| c.0);
            (best, cv)
        }
    };

    let mut out = vec![(0u32, Vec3::ZERO); edges.len() * k];
    par::map_chunks_mut(
        &mut out,
        CHUNK * k,
        || EdgeSystem::new(frames.len()),
        |s, c, chunk| {
            for (j, slots) in chunk.chunks_mut(k).enumerate() {
                let e = c * CHUNK + j;
                s.build(&sys, e);
                s.solve_all(ridge);
                slots.fill((0, Vec3::ZERO));
                for (a, slot) in slots.iter_mut().take(s.bones.len()).enumerate() {
                    *slot = (
                        s.bones[a],
                        Vec3::new(
                            s.x[3 * a] as f32,
                            s.x[3 * a + 1] as f32,
                            s.x[3 * a + 2] as f32,
                        ),
                    );
                }
            }
        },
    );
    let (indices, vectors) = out.into_iter().unzip();
    let skin = EdgeSkin::new(k, indices, vectors)?;
    Ok((skin, EdgeVectorReport { ridge, cv }))
}

/// Sizes, ranges and finiteness of the frame data shared by both edge fits.
fn check_frames<R: AsRef<[Quat]>>(
    rest: &[Vec3],
    edges: &[[u32; 2]],
    frames: &[&[Vec3]],
    rotations: &[R],
) -> Result<(), EdgeWeightError> {
    let n = rest.len();
    let size = |what: String, expected: usize, got: usize| {
        if expected == got {
            Ok(())
        } else {
            Err(EdgeWeightError::Size {
                what,
                expected,
                got,
            })
        }
    };
    size(
        "rotation sets (one per frame)".into(),
        frames.len(),
        rotations.len(),
    )?;
    if let Some(i) = rest.iter().position(|p| !p.is_finite()) {
        return Err(EdgeWeightError::NonFinite {
            what: format!("rest vertex {i}"),
        });
    }
    let bones = rotations.first().map_or(0, |r| r.as_ref().len());
    for (j, (frame, rot)) in frames.iter().zip(rotations).enumerate() {
        size(format!("frame {j} vertices"), n, frame.len())?;
        size(
            format!("frame {j} bone rotations"),
            bones,
            rot.as_ref().len(),
        )?;
        if let Some(i) = frame.iter().position(|p| !p.is_finite()) {
            return Err(EdgeWeightError::NonFinite {
                what: format!("frame {j} vertex {i}"),
            });
        }
        if let Some(b) = rot.as_ref().iter().position(|q| !q.is_finite()) {
            return Err(EdgeWeightError::NonFinite {
                what: format!("rotation of bone {b} in frame {j}"),
            });
        }
    }
    for (edge, e) in edges.iter().enumerate() {
        if let Some(&vertex) = e.iter().find(|&&v| v as usize >= n) {
            return Err(EdgeWeightError::EdgeOutOfRange {
                edge,
                vertex,
                vertex_count: n,
            });
        }
    }
    Ok(())
}

/// One edge's least-squares system, per frame and summed, in a per-worker buffer.
///
/// Unknowns `x = (a_1, .., a_n)` (3 per support bone). Frame `j` contributes
/// `G_j = B_j^T B_j` (blocks `R_a^T R_b`), `h_j = B_j^T e^j` and `|e^j|^2`, where
/// `B_j = [R_1^j .. R_n^j]`.
struct EdgeSystem {
    /// Support bones and their averaged endpoint weights.
    bones: Vec<u32>,
    weights: Vec<f64>,
    order: Vec<usize>,
    /// Prior `w^_kb e_k^0`, 3 per bone.
    prior: Vec<f64>,
    /// Per frame `G_j` (m x m, m = 3n), `h_j` (m) and `|e^j|^2`.
    g: Vec<f64>,
    h: Vec<f64>,
    ee: Vec<f64>,
    /// Work: summed system, its Cholesky factor, the solution.
    gs: Vec<f64>,
    hs: Vec<f64>,
    l: Vec<f64>,
    x: Vec<f64>,
    frames: usize,
}

const MAX_M: usize = 3 * MAX_INFLUENCES;

impl EdgeSystem {
    fn new(frames: usize) -> Self {
        Self {
            bones: Vec::with_capacity(2 * MAX_INFLUENCES),
            weights: Vec::with_capacity(2 * MAX_INFLUENCES),
            order: Vec::with_capacity(2 * MAX_INFLUENCES),
            prior: vec![0.0; MAX_M],
            g: vec![0.0; frames * MAX_M * MAX_M],
            h: vec![0.0; frames * MAX_M],
            ee: vec![0.0; frames],
            gs: vec![0.0; MAX_M * MAX_M],
            hs: vec![0.0; MAX_M],
            l: vec![0.0; MAX_M * MAX_M],
            x: vec![0.0; MAX_M],
            frames,
        }
    }

    fn m(&self) -> usize {
        3 * self.bones.len()
    }

    /// Per-frame systems of edge `e`.
    fn build(&mut self, input: &Input<'_>, e: usize) {
        let [i0, i1] = input.edges[e].map(|v| v as usize);
        let e0 = input.rest[i0] - input.rest[i1];
        // Support: the endpoints' averaged vertex weights, the `k` largest, renormalised.
        self.bones.clear();
        self.weights.clear();
        for v in [i0, i1] {
            let (idx, w) = input.skin.vertex(v);
            for (&b, &x) in idx.iter().zip(w).filter(|(_, x)| **x > 0.0) {
                match self.bones.iter().position(|&c| c == b) {
                    Some(a) => self.weights[a] += 0.5 * x as f64,
                    None => {
                        self.bones.push(b);
                        self.weights.push(0.5 * x as f64);
                    }
                }
            }
        }
        if self.bones.len() > input.k {
            self.order.clear();
            self.order.extend(0..self.bones.len());
            let w = &self.weights;
            self.order
                .sort_by(|&a, &b| w[b].total_cmp(&w[a]).then(a.cmp(&b)));
            self.order.truncate(input.k);
            self.order.sort_unstable();
            for (i, &a) in self.order.iter().enumerate() {
                self.bones[i] = self.bones[a];
                self.weights[i] = self.weights[a];
            }
            self.bones.truncate(input.k);
            self.weights.truncate(input.k);
        }
        let sum: f64 = self.weights.iter().sum();
        for (a, &x) in self.weights.iter().enumerate() {
            for c in 0..3 {
                self.prior[3 * a + c] = e0[c] as f64 * x / sum;
            }
        }
        let m = self.m();
        let n = self.bones.len();
        for j in 0..self.frames {
            let frame = input.frames[j];
            let t = Vec3A::from(frame[i0] - frame[i1]);
            let rot = &input.rot[j * input.bones..(j + 1) * input.bones];
            let g = &mut self.g[j * m * m..(j + 1) * m * m];
            let h = &mut self.h[j * m..(j + 1) * m];
            self.ee[j] = t.length_squared() as f64;
            for a in 0..n {
                let ra = rot[self.bones[a] as usize];
                // h_a = R_a^T e
                let ha = ra.transpose() * t;
                for c in 0..3 {
                    h[3 * a + c] = ha[c] as f64;
                }
                for b in 0..=a {
                    // block (a, b) = R_a^T R_b (identity on the diagonal)
                    let blk = ra.transpose() * rot[self.bones[b] as usize];
                    for r in 0..3 {
                        for c in 0..3 {
                            let v = blk.col(c)[r] as f64;
                            g[(3 * a + r) * m + 3 * b + c] = v;
                            g[(3 * b + c) * m + 3 * a + r] = v;
                        }
                    }
                }
            }
        }
    }

    /// Solves with frames `j` where `held(j)` is false, ridge `ridge`; the result is in `x`.
    /// `ridge = inf` gives the prior.
    fn solve(&mut self, ridge: f64, held: impl Fn(usize) -> bool) {
        let m = self.m();
        if !ridge.is_finite() {
            self.x[..m].copy_from_slice(&self.prior[..m]);
            return;
        }
        self.gs[..m * m].fill(0.0);
        self.hs[..m].fill(0.0);
        let mut used = 0usize;
        for j in (0..self.frames).filter(|&j| !held(j)) {
            used += 1;
            for (s, g) in self.gs[..m * m]
                .iter_mut()
                .zip(&self.g[j * m * m..(j + 1) * m * m])
            {
                *s += g;
            }
            for (s, h) in self.hs[..m].iter_mut().zip(&self.h[j * m..(j + 1) * m]) {
                *s += h;
            }
        }
        // A tiny floor keeps bones whose rotation never changes (rank-deficient blocks)
        // solvable at ridge 0.
        let lambda = (ridge * used as f64).max(1e-9 * used.max(1) as f64);
        for a in 0..m {
            self.gs[a * m + a] += lambda;
            self.hs[a] += lambda * self.prior[a];
        }
        if !cholesky(&self.gs[..m * m], m, &mut self.l) {
            self.x[..m].copy_from_slice(&self.prior[..m]);
            return;
        }
        self.x[..m].copy_from_slice(&self.hs[..m]);
        cholesky_solve(&self.l, m, &mut self.x);
        if self.x[..m].iter().any(|v| !v.is_finite()) {
            self.x[..m].copy_from_slice(&self.prior[..m]);
        }
    }

    fn solve_all(&mut self, ridge: f64) {
        self.solve(ridge, |_| false);
    }

    /// Adds, per candidate ridge, the held-out residual and edge energy over `folds` folds
    /// (frame `j` is in fold `j % folds`).
    fn cross_validate(&mut self, folds: usize, acc: &mut [[f64; 2]; EDGE_RIDGES.len()]) {
        let m = self.m();
        for fold in 0..folds {
            for (r, &ridge) in EDGE_RIDGES.iter().enumerate() {
                self.solve(ridge, |j| j % folds == fold);
                for j in (fold..self.frames).step_by(folds) {
                    // |B x - e|^2 = x^T G x - 2 x^T h + |e|^2
                    let g = &self.g[j * m * m..(j + 1) * m * m];
                    let h = &self.h[j * m..(j + 1) * m];
                    let mut q = self.ee[j];
                    for a in 0..m {
                        let gx: f64 = (0..m).map(|b| g[a * m + b] * self.x[b]).sum();
                        q += self.x[a] * (gx - 2.0 * h[a]);
                    }
                    acc[r][0] += q.max(0.0);
                    acc[r][1] += self.ee[j];
                }
            }
        }
    }
}

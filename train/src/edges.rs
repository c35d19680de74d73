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
use crease_core::runtime::skin::{MAX_INFLUENCES, SkinError, SkinWeights};

use crate::bones::qp::{MAX_CANDIDATES, SimplexQp};
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
    check(rest, edges, frames, rotations, vertex_skin, k)?;
    let f = frames.len();
    let bones = rotations.first().map_or(0, |r| r.as_ref().len());
    // Frame-major rotations as matrices: [j * bones + b].
    let rot: Vec<Mat3A> = rotations
        .iter()
        .flat_map(|r| r.as_ref().iter().map(|&q| Mat3A::from_quat(q)))
        .collect();
    let input = Input {
        rest,
        edges,
        frames,
        rot: &rot,
        bones,
        skin: vertex_skin,
        k,
    };
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
        "vertex skin rows (one per rest vertex)".into(),
        n,
        vertex_skin.vertex_count(),
    )?;
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
    if !frames.is_empty() {
        // Only weighted slots need a rotation: padding slots name bone 0 by convention.
        for v in 0..n {
            let (idx, w) = vertex_skin.vertex(v);
            if let Some(slot) = (0..idx.len()).find(|&s| w[s] > 0.0 && idx[s] as usize >= bones) {
                return Err(EdgeWeightError::Skin(SkinError::BoneOutOfRange {
                    vertex: v,
                    slot,
                    bone: idx[slot],
                    bone_count: bones,
                }));
            }
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

/// Checked inputs, in the layout the per-edge loop wants.
struct Input<'a> {
    rest: &'a [Vec3],
    edges: &'a [[u32; 2]],
    frames: &'a [&'a [Vec3]],
    /// Rotations as matrices, frame-major `[j * bones + b]`.
    rot: &'a [Mat3A],
    bones: usize,
    skin: &'a SkinWeights,
    k: usize,
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

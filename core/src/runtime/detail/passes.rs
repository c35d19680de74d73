//! The passes of [`super::DetailSynth`]'s frame (issue 23): `S · base` on 4-lane rows (compressed
//! rows and Loop's edge-point stencils), the grouped normal scatter, and the normalisation with
//! the displacement, with `h` given or regressed a block at a time. Plain Rust, each pass
//! compiled a second time for AVX2 + FMA where the CPU has it (`runtime::simd`'s
//! `compiled_twice!`: three-operand instructions instead of SSE2's copies, 8-wide square roots
//! and divisions).

use glam::{Vec3, Vec3A};

#[cfg(feature = "parallel")]
use super::PARALLEL_CHUNK;
use super::{H_BLOCK, RegressRows};
use crate::mesh::subdivision::SparseMatrix;
#[cfg(test)]
use crate::mesh::topology::accumulate_face_normals;
use crate::runtime::simd::compiled_twice;

/// The rows `first..` of one level's matrix that are Loop edge points (`3/8 (a + b) + 1/8 (c +
/// d)` inside, `1/2 (a + b)` on the boundary), as their four vertices `[a, b, c, d]` (`[a, b,
/// a, b]` on the boundary): 16 bytes a row instead of 36 in compressed rows, and no weights to
/// load (issue 23: the detail frame's matrices, `D` among them, overflow the last-level cache,
/// so its bytes are its time). Loop's documented order puts the edge points last; rows of any
/// other form before them stay compressed rows.
#[derive(Debug)]
pub(super) struct EdgeStencils {
    first: usize,
    quads: Vec<[u32; 4]>,
}

impl EdgeStencils {
    /// The longest run of edge-point rows at the end of `s`.
    pub(super) fn new(s: &SparseMatrix) -> EdgeStencils {
        let mut quads = Vec::new();
        let mut first = s.rows();
        while first > 0 {
            let Some(q) = edge_stencil(s.row(first - 1)) else {
                break;
            };
            quads.push(q);
            first -= 1;
        }
        quads.reverse();
        EdgeStencils { first, quads }
    }
}

/// A row `(cols, vals)` as `[a, b, c, d]` with weights `3/8, 3/8, 1/8, 1/8` (exact in f32), or
/// a `1/2, 1/2` row as `[a, b, a, b]` (`3/8 + 1/8 = 1/2`); `None` for any other row.
fn edge_stencil((cols, vals): (&[u32], &[f32])) -> Option<[u32; 4]> {
    match (cols, vals) {
        (&[a, b], &[0.5, 0.5]) => Some([a, b, a, b]),
        (&[_, _, _, _], &[_, _, _, _]) => {
            let mut q = [0u32; 4];
            let (mut wide, mut narrow) = (0, 2);
            for (&c, &w) in cols.iter().zip(vals) {
                if w == 0.375 && wide < 2 {
                    q[wide] = c;
                    wide += 1;
                } else if w == 0.125 && narrow < 4 {
                    q[narrow] = c;
                    narrow += 1;
                } else {
                    return None;
                }
            }
            Some(q)
        }
        _ => None,
    }
}

compiled_twice! {
    /// `out[k] = 3/8 (x[a] + x[b]) + 1/8 (x[c] + x[d])` for `quads[k] = [a, b, c, d]`.
    fn edge_rows(quads: &'a [[u32; 4]], x: &'a [Vec3A], out: &'a mut [Vec3A]) => edge_rows_body
}

#[inline(always)]
fn edge_rows_body(quads: &[[u32; 4]], x: &[Vec3A], out: &mut [Vec3A]) {
    for (o, q) in out.iter_mut().zip(quads) {
        let [a, b, c, d] = q.map(|i| x[i as usize]);
        *o = (a + b) * 0.375 + (c + d) * 0.125;
    }
}

/// Rows `first .. first + out.len()` of `s · x` on 4-lane rows: compressed rows before
/// `edges.first` ([`apply_rows_padded`]), stencils from there ([`edge_rows`]).
pub(super) fn apply_step(
    s: &SparseMatrix,
    edges: &EdgeStencils,
    x: &[Vec3A],
    first: usize,
    out: &mut [Vec3A],
) {
    let split = edges.first.saturating_sub(first).min(out.len());
    let (rows, stencils) = out.split_at_mut(split);
    if !rows.is_empty() {
        apply_rows_padded(s, x, first, rows);
    }
    if !stencils.is_empty() {
        let quads = &edges.quads[first + split - edges.first..][..stencils.len()];
        edge_rows(quads, &x[..s.columns()], stencils);
    }
}

/// The six vertices `[a, b, c, ab, bc, ca]` of each group of four triangles in
/// [`LoopSubdivision::triangles`]' order (`[a, ab, ca]`, `[ab, b, bc]`, `[ca, bc, c]`,
/// `[ab, bc, ca]` per coarser triangle: the module's documented order, checked by its tests).
pub(super) fn loop_groups(triangles: &[[u32; 3]]) -> Vec<[u32; 6]> {
    triangles
        .chunks_exact(4)
        .map(|g| [g[0][0], g[1][1], g[2][2], g[0][1], g[1][2], g[0][2]])
        .collect()
}

/// [`accumulate_face_normals`] a group of four Loop children at a time (issue 23, groups from
/// [`loop_groups`]): the corners `a`, `b`, `c` get one child's face normal, the edge points
/// `ab`, `bc`, `ca` the sum of three, so six read-modify-writes a group instead of twelve, and
/// six index loads instead of twelve. The same face normals, summed in another order (within
/// rounding of the plain scatter).
pub(super) fn scatter_groups(positions: &[Vec3A], groups: &[[u32; 6]], acc: &mut [Vec3A]) {
    acc.fill(Vec3A::ZERO);
    scatter_into(positions, groups, acc);
}

compiled_twice! {
    /// [`scatter_groups`] after the zeroing.
    fn scatter_into(
        positions: &'a [Vec3A],
        groups: &'a [[u32; 6]],
        acc: &'a mut [Vec3A],
    ) => scatter_groups_body
}

#[inline(always)]
fn scatter_groups_body(positions: &[Vec3A], groups: &[[u32; 6]], acc: &mut [Vec3A]) {
    // One length for both, so one bounds check an index serves the load and the update.
    let acc = &mut acc[..positions.len()];
    for g in groups {
        let [a, b, c, ab, bc, ca] = g.map(|i| i as usize);
        let (pa, pb, pc) = (positions[a], positions[b], positions[c]);
        let (pab, pbc, pca) = (positions[ab], positions[bc], positions[ca]);
        let n0 = (pab - pa).cross(pca - pa);
        let n1 = (pb - pab).cross(pbc - pab);
        let n2 = (pbc - pca).cross(pc - pca);
        let n3 = (pbc - pab).cross(pca - pab);
        acc[a] += n0;
        acc[b] += n1;
        acc[c] += n2;
        acc[ab] += n0 + n1 + n3;
        acc[bc] += n1 + n2 + n3;
        acc[ca] += n0 + n2 + n3;
    }
}

/// Normalises the accumulated normals in place and writes `out = high + h ⊙ n`, all slices of
/// equal length (checked by the caller); split over the pool when `pooled`.
pub(super) fn normalize_and_displace(
    high: &[Vec3A],
    h: &[f32],
    normals: &mut [Vec3A],
    out: &mut [Vec3],
    pooled: bool,
) {
    #[cfg(feature = "parallel")]
    if pooled {
        use rayon::prelude::*;
        out.par_chunks_mut(PARALLEL_CHUNK)
            .zip(normals.par_chunks_mut(PARALLEL_CHUNK))
            .zip(high.par_chunks(PARALLEL_CHUNK))
            .zip(h.par_chunks(PARALLEL_CHUNK))
            .for_each(|(((o, n), p), h)| normalize_and_displace_kernel(p, h, n, o));
        return;
    }
    let _ = pooled;
    normalize_and_displace_here(high, h, normals, out);
}

compiled_twice! {
    /// The single-threaded last pass with `h` regressed a block of [`H_BLOCK`] at a time.
    pub(super) fn regress_and_displace(
        rows: RegressRows<'a>,
        high: &'a [Vec3A],
        h: &'a mut [f32],
        normals: &'a mut [Vec3A],
        out: &'a mut [Vec3],
    ) => regress_and_displace_body
}

compiled_twice! {
    /// [`normalize_and_displace`] on the calling thread.
    fn normalize_and_displace_here(
        high: &'a [Vec3A],
        h: &'a [f32],
        normals: &'a mut [Vec3A],
        out: &'a mut [Vec3],
    ) => normalize_and_displace_kernel
}

#[inline(always)]
fn regress_and_displace_body(
    rows: RegressRows<'_>,
    high: &[Vec3A],
    h: &mut [f32],
    normals: &mut [Vec3A],
    out: &mut [Vec3],
) {
    let blocks = h
        .chunks_mut(H_BLOCK)
        .zip(out.chunks_mut(H_BLOCK))
        .zip(normals.chunks_mut(H_BLOCK))
        .zip(high.chunks(H_BLOCK));
    for (k, (((h, o), nm), p)) in blocks.enumerate() {
        rows(k * H_BLOCK, h);
        normalize_and_displace_kernel(p, h, nm, o);
    }
}

/// Vertices whose reciprocal lengths [`normalize_and_displace_kernel`] takes together.
const NORMALIZE_BATCH: usize = 8;

/// [`normalize_and_displace`] on the calling thread. `Vec3A::normalize_or_zero` bit for bit,
/// but the square roots and divisions of [`NORMALIZE_BATCH`] vertices are taken as one array
/// (vector `sqrt` and `div`, issue 23): one per vertex, they occupied the divider ~8 cycles a
/// vertex, about a tenth of the synthesis.
#[inline(always)]
fn normalize_and_displace_kernel(
    high: &[Vec3A],
    h: &[f32],
    normals: &mut [Vec3A],
    out: &mut [Vec3],
) {
    let batches = out
        .chunks_mut(NORMALIZE_BATCH)
        .zip(normals.chunks_mut(NORMALIZE_BATCH))
        .zip(high.chunks(NORMALIZE_BATCH))
        .zip(h.chunks(NORMALIZE_BATCH));
    for (((o, n), p), h) in batches {
        // 1 / |n| as `normalize_or_zero` computes it: the same dot product, IEEE sqrt and
        // division (lanes past a short last batch hold 1 / 0, unused).
        let mut rcp = [0.0f32; NORMALIZE_BATCH];
        for (r, v) in rcp.iter_mut().zip(n.iter()) {
            *r = v.length_squared();
        }
        for r in &mut rcp {
            *r = 1.0 / r.sqrt();
        }
        for ((((o, n), &p), &h), &r) in o.iter_mut().zip(n).zip(p).zip(h).zip(&rcp) {
            *n = if r.is_finite() && r > 0.0 {
                *n * r
            } else {
                Vec3A::ZERO
            };
            *o = (p + h * *n).into();
        }
    }
}

/// [`SparseMatrix::apply_rows`] on 4-lane rows (at least [`SparseMatrix::columns`] of them):
/// one load a stored entry instead of three lanes' worth, and with AVX2 + FMA where the CPU has
/// them (`runtime::simd::sparse_rows4`) one broadcast and one fused multiply-add (issue 23: 19
/// instructions an entry before). The FMA rounds once per entry, so the sums differ from
/// [`SparseMatrix::apply_rows`]'s in the last bits. The fourth lane is summed like the others
/// and means nothing.
///
/// # Panics
/// As [`SparseMatrix::apply_rows`].
fn apply_rows_padded(s: &SparseMatrix, x: &[Vec3A], first_row: usize, out: &mut [Vec3A]) {
    let (row_ptr, cols, vals) = s.parts();
    let ptr = &row_ptr[first_row..=first_row + out.len()];
    let x = &x[..s.columns()];
    if let Some(simd) = crate::runtime::simd::fma() {
        crate::runtime::simd::sparse_rows4(simd, ptr, cols, vals, x, out);
        return;
    }
    let mut start = ptr[0] as usize;
    for (o, &end) in out.iter_mut().zip(&ptr[1..]) {
        let end = end as usize;
        let mut acc = Vec3A::ZERO;
        for (&c, &w) in cols[start..end].iter().zip(&vals[start..end]) {
            acc += x[c as usize] * w;
        }
        *o = acc;
        start = end;
    }
}

#[cfg(test)]
mod tests {
    use super::super::DetailSynth;
    use super::*;
    use crate::mesh::subdivision::LoopSubdivision;
    use crate::mesh::test_meshes::grid;

    #[test]
    fn grouped_scatter_sums_the_same_face_normals() {
        // A bumpy grid, subdivided twice: its final triangles are Loop's groups of four.
        let m = grid(6, 5, |i, j| {
            Vec3::new(i as f32, j as f32 * 1.3, ((i * 7 + j * 3) % 5) as f32 * 0.1)
        });
        let synth = DetailSynth::from_mesh(&m, 2).unwrap();
        let tris = synth.topology.subdivision.triangles();
        let mut high = vec![Vec3::ZERO; synth.vertex_count()];
        synth.subdivide(&m.positions, &mut high).unwrap();
        let high4: Vec<Vec3A> = high.iter().map(|&p| p.into()).collect();
        let mut grouped = vec![Vec3A::NAN; high.len()];
        let mut plain = vec![Vec3::NAN; high.len()];
        scatter_groups(&high4, &loop_groups(tris), &mut grouped);
        accumulate_face_normals(&high, tris, &mut plain);
        for (g, p) in grouped.iter().map(|&g| Vec3::from(g)).zip(&plain) {
            assert!(
                (g - *p).length() <= 1e-5 * p.length().max(1e-3),
                "{g} vs {p}"
            );
        }
    }

    /// The padded (FMA where the CPU has it) product against the matrix's rows summed in
    /// f64, on a subdivided grid with boundary and interior rows, every row split point.
    #[test]
    fn padded_rows_equal_f64_sums() {
        let m = grid(5, 4, |i, j| {
            Vec3::new(
                i as f32 * 1.1,
                j as f32 * 0.9,
                ((i * 3 + j * 5) % 7) as f32 * 0.3 - 1.0,
            )
        });
        let s = LoopSubdivision::new(&m, 1).unwrap();
        let mat = s.matrix();
        let padded: Vec<Vec3A> = m.positions.iter().map(|&p| p.into()).collect();
        for first in [0, 1, 7, mat.rows() - 1] {
            let mut out = vec![Vec3A::NAN; mat.rows() - first];
            apply_rows_padded(mat, &padded, first, &mut out);
            for (k, o) in out.iter().enumerate() {
                let (cols, vals) = mat.row(first + k);
                let mut want = [0.0f64; 3];
                let mut scale = 0.0f64;
                for (&c, &w) in cols.iter().zip(vals) {
                    let p = m.positions[c as usize];
                    for (a, x) in want.iter_mut().zip([p.x, p.y, p.z]) {
                        *a += f64::from(w) * f64::from(x);
                    }
                    scale += f64::from(w.abs()) * f64::from(p.abs().max_element());
                }
                for (got, w) in [o.x, o.y, o.z].into_iter().zip(want) {
                    assert!(
                        (f64::from(got) - w).abs() <= 4.0 * f64::from(f32::EPSILON) * scale,
                        "row {}: {got} vs {w}",
                        first + k
                    );
                }
            }
        }
    }

    /// The batched normalisation is `normalize_or_zero` bit for bit, zero and subnormal
    /// lengths included, with a partial last batch.
    #[test]
    fn batched_normalize_equals_normalize_or_zero() {
        let mut normals: Vec<Vec3A> = (0..29)
            .map(|i| {
                let t = i as f32 * 0.731;
                Vec3A::new(t.sin() * 3.0, t.cos() * 0.01, (t * 1.7).sin() * 1e-3)
            })
            .collect();
        normals[3] = Vec3A::ZERO;
        normals[11] = Vec3A::new(1e-30, 0.0, 0.0);
        normals[20] = Vec3A::new(3e38, 3e38, 0.0);
        let high: Vec<Vec3A> = (0..29).map(|i| Vec3A::splat(i as f32 * 0.1)).collect();
        let h: Vec<f32> = (0..29).map(|i| (i as f32 - 14.0) * 1e-3).collect();
        let want_n: Vec<Vec3A> = normals.iter().map(|n| n.normalize_or_zero()).collect();
        let mut got_n = normals.clone();
        let mut out = vec![Vec3::NAN; 29];
        normalize_and_displace_kernel(&high, &h, &mut got_n, &mut out);
        for v in 0..29 {
            assert_eq!(Vec3::from(got_n[v]), Vec3::from(want_n[v]), "normal {v}");
            assert_eq!(out[v], Vec3::from(high[v] + h[v] * want_n[v]), "vertex {v}");
        }
        assert_eq!(Vec3::from(got_n[3]), Vec3::ZERO);
    }

    /// The edge-point stencils cover Loop's edge rows (interior and boundary) and give the
    /// matrix's sums (in f64) on every split of the rows.
    #[test]
    fn edge_stencils_equal_the_matrix_rows() {
        let m = grid(6, 5, |i, j| {
            Vec3::new(
                i as f32 * 1.1,
                j as f32 * 0.9,
                ((i * 3 + j * 5) % 7) as f32 * 0.3,
            )
        });
        let s = LoopSubdivision::new(&m, 1).unwrap();
        let mat = s.matrix();
        let edges = EdgeStencils::new(mat);
        // Every edge row is a stencil: the run starts at the first edge point.
        assert_eq!(edges.first, m.vertex_count());
        assert_eq!(edges.quads.len(), mat.rows() - m.vertex_count());
        assert!(edges.quads.iter().any(|q| q[0] == q[2]), "a boundary edge");
        assert!(edges.quads.iter().any(|q| q[0] != q[2]), "an interior edge");
        let x: Vec<Vec3A> = m.positions.iter().map(|&p| p.into()).collect();
        for first in [0, 5, m.vertex_count(), mat.rows() - 3] {
            let mut out = vec![Vec3A::NAN; mat.rows() - first];
            apply_step(mat, &edges, &x, first, &mut out);
            for (k, o) in out.iter().enumerate() {
                let (cols, vals) = mat.row(first + k);
                let mut scale = 0.0f64;
                for (axis, got) in [o.x, o.y, o.z].into_iter().enumerate() {
                    let mut want = 0.0f64;
                    for (&c, &w) in cols.iter().zip(vals) {
                        let p = f64::from(m.positions[c as usize][axis]);
                        want += f64::from(w) * p;
                        scale = scale.max(f64::from(w.abs()) * p.abs());
                    }
                    assert!(
                        (f64::from(got) - want).abs()
                            <= 8.0 * f64::from(f32::EPSILON) * scale.max(1.0),
                        "row {} axis {axis}: {got} vs {want}",
                        first + k
                    );
                }
            }
        }
        // Rows of another form end the run.
        let q = edge_stencil((&[1, 2, 3, 4], &[0.375, 0.375, 0.125, 0.126]));
        assert_eq!(q, None);
        assert_eq!(edge_stencil((&[1, 2], &[0.5, 0.5])), Some([1, 2, 1, 2]));
        assert_eq!(
            edge_stencil((&[1, 2, 3, 4], &[0.125, 0.375, 0.125, 0.375])),
            Some([2, 4, 1, 3])
        );
    }
}

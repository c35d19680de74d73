//! Loop subdivision as a sparse matrix: the `S` of HZY11 §4 and eq. 4 (`high = S · base`).
//!
//! HZY11 §4 extracts the detail of each example by subdividing its smooth low-resolution mesh and
//! measuring displacements along the normals of the subdivided vertices; at run time (eq. 4) the
//! skinned base mesh is subdivided "in the same way" and the predicted displacements are added.
//! Since the base topology never changes, one subdivision step is a fixed linear map from base
//! positions to subdivided positions; [`LoopSubdivision`] builds it once, for 1 to
//! [`MAX_LEVELS`] levels composed into one CSR matrix ([`SparseMatrix`], `S = S_L · … · S_1`),
//! together with the subdivided triangle list. Per frame only [`SparseMatrix::apply`] runs.
//!
//! The rules (Loop, "Smooth subdivision surfaces based on triangles", MS thesis, University of
//! Utah, 1987, with Warren's simpler β; boundary rules of Hoppe et al., "Piecewise smooth surface
//! reconstruction", SIGGRAPH 1994, without their crease and corner rules):
//! - even (old) vertex of valence `n`, interior: `(1 - n β) v + β Σ neighbours`, with
//!   `β = 3 / (8 n)` for `n > 3` and `β = 3 / 16` for `n ≤ 3` (Warren);
//! - even vertex on the boundary: `3/4 v + 1/8 (b₀ + b₁)`, `b₀`, `b₁` its two boundary
//!   neighbours;
//! - odd (new) vertex on an interior edge `(a, b)` with opposite vertices `c`, `d`:
//!   `3/8 (a + b) + 1/8 (c + d)`;
//! - odd vertex on a boundary edge: `1/2 (a + b)`.
//!
//! An isolated vertex (in no triangle) keeps its position.
//!
//! Vertex order of each level: the vertices of the coarser mesh first, same indices, then one
//! new vertex per edge, in the order the edges are first met walking the triangles in order and
//! each triangle `[a, b, c]` along `ab`, `bc`, `ca`. With two levels this applies twice: base
//! vertices, then level-1 edge vertices, then level-2 edge vertices. First-appearance order,
//! rather than edges sorted by index, keeps the vertices of neighbouring triangles near each
//! other in memory (the triangles of a level come in patches of 4 per coarser triangle). On the
//! 2-level hand the per-frame passes are bound by arithmetic and measured the same with it, with
//! sorted order, and with an ideal renumbering; it costs nothing and helps larger meshes.
//!
//! Triangle order: each triangle `[a, b, c]` of the coarser mesh, with edge vertices `ab`, `bc`,
//! `ca`, becomes four triangles in place, `[a, ab, ca]`, `[ab, b, bc]`, `[ca, bc, c]`,
//! `[ab, bc, ca]`, keeping its winding.
//!
//! The input must be an edge- and vertex-manifold mesh, closed or with boundary, without
//! degenerate triangles; anything else is a [`SubdivisionError`] naming the edge, vertex or
//! triangle. Triangle orientation need not be consistent for the rules, but normals computed
//! on an inconsistently oriented result are meaningless.

use glam::{Vec3, Vec3A};

use super::Mesh;

/// Most subdivision levels accepted. Each level multiplies the triangle count by 4: the ~9.5K
/// vertex base hand gives ~151K vertices at 2 levels (DESIGN step 2 asks for 1–2) and ~600K at
/// 3; more would be far beyond what a frame can stream, and the composed matrix's rows grow with
/// the support of the levels (on the hand 4.8 entries per row at 1 level, 8.0 at 2).
pub const MAX_LEVELS: u32 = 3;

/// An error building a [`LoopSubdivision`] or applying its matrix.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum SubdivisionError {
    /// `levels` outside `1..=MAX_LEVELS`.
    #[error("Loop subdivision: {levels} levels requested, expected 1..={MAX_LEVELS}")]
    BadLevels {
        /// The rejected level count.
        levels: u32,
    },
    /// A triangle names a vertex that does not exist.
    #[error(
        "Loop subdivision: triangle {triangle} refers to vertex {index}, but there are only \
         {vertex_count} vertices"
    )]
    IndexOutOfRange {
        /// 0-based triangle index.
        triangle: usize,
        /// The vertex index found.
        index: u32,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },
    /// A triangle repeats a vertex: it has no edges to split consistently.
    #[error("Loop subdivision: triangle {triangle} {indices:?} is degenerate (repeats a vertex)")]
    DegenerateTriangle {
        /// 0-based triangle index.
        triangle: usize,
        /// Its vertices.
        indices: [u32; 3],
    },
    /// An edge is shared by more than two triangles.
    #[error(
        "Loop subdivision: edge ({a}, {b}) is shared by {triangles} triangles (non-manifold \
         edge; at most 2 allowed)"
    )]
    NonManifoldEdge {
        /// Smaller vertex index of the edge.
        a: u32,
        /// Larger vertex index of the edge.
        b: u32,
        /// How many triangles use it.
        triangles: usize,
    },
    /// A vertex has a number of boundary edges other than 0 (interior) or 2 (boundary): two
    /// boundary fans meet at it (a "bowtie"), so its boundary neighbours are not defined.
    #[error(
        "Loop subdivision: vertex {vertex} has {boundary_edges} boundary edges (non-manifold \
         vertex; expected 0 or 2)"
    )]
    NonManifoldVertex {
        /// The vertex.
        vertex: u32,
        /// Edges at the vertex used by only one triangle.
        boundary_edges: usize,
    },
    /// The triangles around a vertex form several fans (e.g. two cones touching at their tips):
    /// its valence, and so its Loop weights, are not defined.
    #[error(
        "Loop subdivision: the triangles around vertex {vertex} form {fans} separate fans \
         (non-manifold vertex; expected 1)"
    )]
    SeveralFans {
        /// The vertex.
        vertex: u32,
        /// Separate fans of triangles around it.
        fans: usize,
    },
    /// The subdivided mesh would have more vertices than `u32` indices can name.
    #[error("Loop subdivision: {vertices} vertices after subdivision exceed u32 indices")]
    TooLarge {
        /// The vertex count that would result.
        vertices: u64,
    },
    /// A buffer passed to [`SparseMatrix::apply`] or [`LoopSubdivision::mesh`] has the wrong
    /// length.
    #[error("{what}: {got} vertices, expected {expected}")]
    Length {
        /// Which buffer ("base positions", "output").
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length found.
        got: usize,
    },
}

/// Vertex count of `mesh` Loop-subdivided `levels` times, without building `S`: each level adds
/// one vertex per edge and turns each edge into two plus three per triangle (`V' = V + E`,
/// `E' = 2E + 3F`, `F' = 4F`). Saturates instead of overflowing.
pub fn subdivided_vertex_count(mesh: &Mesh, levels: u32) -> usize {
    count_after(
        mesh.vertex_count(),
        mesh.edges().len(),
        mesh.triangles.len(),
        levels,
    )
}

/// [`subdivided_vertex_count`] of a topology given as a vertex count and triangles, `None`
/// for a level count outside `1..=MAX_LEVELS`: what a palette decoder checks a header's vertex
/// count against before it allocates anything for it (the mesh may still be refused by
/// [`loop_steps`]).
pub fn subdivided_count(vertex_count: usize, triangles: &[[u32; 3]], levels: u32) -> Option<usize> {
    if !(1..=MAX_LEVELS).contains(&levels) {
        return None;
    }
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .map(|(a, b)| (a.min(b), a.max(b)))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    Some(count_after(
        vertex_count,
        edges.len(),
        triangles.len(),
        levels,
    ))
}

fn count_after(vertices: usize, edges: usize, triangles: usize, levels: u32) -> usize {
    let (mut v, mut e, mut f) = (vertices, edges, triangles);
    for _ in 0..levels {
        v = v.saturating_add(e);
        e = e.saturating_mul(2).saturating_add(f.saturating_mul(3));
        f = f.saturating_mul(4);
    }
    v
}

/// A sparse matrix in compressed sparse row form with `f32` weights, applied to 3-vectors.
///
/// Row `i` has entries `cols[row_ptr[i]..row_ptr[i + 1]]` (sorted ascending, unique, all below
/// [`SparseMatrix::columns`]) with weights `vals[..]` at the same positions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseMatrix {
    columns: usize,
    row_ptr: Vec<u32>,
    cols: Vec<u32>,
    vals: Vec<f32>,
}

impl SparseMatrix {
    /// Number of rows (subdivided vertices).
    pub fn rows(&self) -> usize {
        self.row_ptr.len().saturating_sub(1)
    }

    /// Number of columns (base vertices).
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Number of stored entries.
    pub fn nnz(&self) -> usize {
        self.vals.len()
    }

    /// `rows() + 1` offsets into [`SparseMatrix::cols`] / [`SparseMatrix::vals`], from 0.
    pub fn row_ptr(&self) -> &[u32] {
        &self.row_ptr
    }

    /// Column indices of all entries, row after row.
    pub fn cols(&self) -> &[u32] {
        &self.cols
    }

    /// Weights of all entries, row after row.
    pub fn vals(&self) -> &[f32] {
        &self.vals
    }

    /// Row `i`: its column indices and weights.
    ///
    /// # Panics
    /// If `i >= rows()`.
    pub fn row(&self, i: usize) -> (&[u32], &[f32]) {
        let (s, e) = (self.row_ptr[i] as usize, self.row_ptr[i + 1] as usize);
        (&self.cols[s..e], &self.vals[s..e])
    }

    /// `out = S · x`. Allocates nothing; one pass over the matrix, gathering from `x`.
    pub fn apply(&self, x: &[Vec3], out: &mut [Vec3]) -> Result<(), SubdivisionError> {
        self.check(x, out.len())?;
        self.apply_rows(x, 0, out);
        Ok(())
    }

    /// `out = (S · x)[first_row .. first_row + out.len()]`: a run of rows, for callers that
    /// split the rows over threads. Sizes are the caller's to check (see
    /// [`SparseMatrix::apply`]).
    ///
    /// # Panics
    /// If the rows run past [`SparseMatrix::rows`] or `x` is shorter than
    /// [`SparseMatrix::columns`].
    #[inline]
    pub fn apply_rows(&self, x: &[Vec3], first_row: usize, out: &mut [Vec3]) {
        let ptr = &self.row_ptr[first_row..=first_row + out.len()];
        let x = &x[..self.columns];
        let mut start = ptr[0] as usize;
        for (o, &end) in out.iter_mut().zip(&ptr[1..]) {
            let end = end as usize;
            let mut acc = Vec3A::ZERO;
            for (&c, &w) in self.cols[start..end].iter().zip(&self.vals[start..end]) {
                acc += Vec3A::from(x[c as usize]) * w;
            }
            *o = acc.into();
            start = end;
        }
    }

    /// The compressed rows: `row_ptr` (one more than the rows), then each stored entry's
    /// column and value. For kernels outside this module (`runtime::detail`'s 4-lane product).
    pub(crate) fn parts(&self) -> (&[u32], &[u32], &[f32]) {
        (&self.row_ptr, &self.cols, &self.vals)
    }

    /// Checks `x` against the column count and an output length against the row count.
    pub fn check(&self, x: &[Vec3], out_len: usize) -> Result<(), SubdivisionError> {
        if x.len() != self.columns {
            return Err(SubdivisionError::Length {
                what: "base positions",
                expected: self.columns,
                got: x.len(),
            });
        }
        if out_len != self.rows() {
            return Err(SubdivisionError::Length {
                what: "output",
                expected: self.rows(),
                got: out_len,
            });
        }
        Ok(())
    }
}

/// Why a sparse matrix given in CSR form ([`SparseMatrix::from_csr`]) was refused.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CsrError {
    /// `row_ptr` does not start at 0, decreases, or does not end at the entry count.
    #[error("sparse matrix: row_ptr[{row}] = {value} is out of order (entries: {entries})")]
    RowPtr {
        /// The offending offset's position.
        row: usize,
        /// Its value.
        value: u32,
        /// The number of entries.
        entries: usize,
    },
    /// `cols` and `vals` differ in length.
    #[error("sparse matrix: {cols} column indices but {vals} weights")]
    Lengths {
        /// Column indices.
        cols: usize,
        /// Weights.
        vals: usize,
    },
    /// A row's columns are not ascending and unique, or one is past the column count.
    #[error("sparse matrix: row {row}: column {col} out of order or >= {columns}")]
    Column {
        /// The row.
        row: usize,
        /// The column index.
        col: u32,
        /// The column count.
        columns: usize,
    },
    /// A weight that is not finite.
    #[error("sparse matrix: weight {entry} is not finite")]
    Weight {
        /// The entry.
        entry: usize,
    },
}

impl SparseMatrix {
    /// A matrix of `columns` columns from its CSR arrays (as [`SparseMatrix::row_ptr`],
    /// [`SparseMatrix::cols`] and [`SparseMatrix::vals`] return them), checked: offsets from 0
    /// to the entry count in order, each row's columns ascending, unique and in range, weights
    /// finite.
    ///
    /// # Errors
    /// [`CsrError`] naming the first offending entry.
    pub fn from_csr(
        columns: usize,
        row_ptr: Vec<u32>,
        cols: Vec<u32>,
        vals: Vec<f32>,
    ) -> Result<SparseMatrix, CsrError> {
        if cols.len() != vals.len() {
            return Err(CsrError::Lengths {
                cols: cols.len(),
                vals: vals.len(),
            });
        }
        let entries = cols.len();
        let bad_ptr = |row: usize, value: u32| CsrError::RowPtr {
            row,
            value,
            entries,
        };
        match (row_ptr.first(), row_ptr.last()) {
            (Some(&0), Some(&last)) if last as usize == entries => {}
            (Some(&first), _) if first != 0 => return Err(bad_ptr(0, first)),
            (Some(_), Some(&last)) => return Err(bad_ptr(row_ptr.len() - 1, last)),
            _ => return Err(bad_ptr(0, 0)),
        }
        // Every offset in order first: a large offset followed by a smaller one must be refused
        // before a row is sliced with it (a fuzzer's finding, `fuzz/` mesh_stream).
        if let Some(row) = row_ptr.windows(2).position(|w| w[1] < w[0]) {
            return Err(bad_ptr(row + 1, row_ptr[row + 1]));
        }
        for (row, w) in row_ptr.windows(2).enumerate() {
            let mut prev: Option<u32> = None;
            for &col in &cols[w[0] as usize..w[1] as usize] {
                if col as usize >= columns || prev.is_some_and(|p| p >= col) {
                    return Err(CsrError::Column { row, col, columns });
                }
                prev = Some(col);
            }
        }
        if let Some(entry) = vals.iter().position(|v| !v.is_finite()) {
            return Err(CsrError::Weight { entry });
        }
        Ok(SparseMatrix {
            columns,
            row_ptr,
            cols,
            vals,
        })
    }
}

/// Loop subdivision of a fixed topology, `levels` times, as one sparse matrix (see the module
/// docs for the rules and the vertex and triangle order).
#[derive(Clone, Debug, PartialEq)]
pub struct LoopSubdivision {
    levels: u32,
    matrix: SparseMatrix,
    /// The one-level matrices whose product is `matrix`, first level first.
    steps: Vec<SparseMatrix>,
    triangles: Vec<[u32; 3]>,
}

impl LoopSubdivision {
    /// Builds `S` and the subdivided triangles of `mesh`'s topology (positions are not read).
    /// `levels` must be in `1..=MAX_LEVELS`.
    pub fn new(mesh: &Mesh, levels: u32) -> Result<LoopSubdivision, SubdivisionError> {
        if !(1..=MAX_LEVELS).contains(&levels) {
            return Err(SubdivisionError::BadLevels { levels });
        }
        let mut vertex_count = mesh.vertex_count();
        let mut triangles = mesh.triangles.clone();
        let mut product: Option<Csr64> = None;
        let mut steps = Vec::with_capacity(levels as usize);
        for _ in 0..levels {
            let level = Level::build(vertex_count, &triangles)?;
            steps.push(level.matrix.clone().into_f32());
            product = Some(match product {
                None => level.matrix,
                Some(p) => level.matrix.mul(&p),
            });
            vertex_count = level.vertex_count;
            triangles = level.triangles;
        }
        let matrix = product.expect("levels >= 1").into_f32();
        Ok(LoopSubdivision {
            levels,
            matrix,
            steps,
            triangles,
        })
    }

    /// The one-level matrices `S_1, ..., S_levels` with `S = S_levels ··· S_1`. Applied in turn
    /// they touch fewer entries than the composed `S` (on the hand at 2 levels: 4.8 entries per
    /// intermediate row and 4.8 per final row, against 8.0 per final row), which measured
    /// 20-40% faster per frame; the composed `S` is rounded once from `f64`, the steps each.
    pub fn steps(&self) -> &[SparseMatrix] {
        &self.steps
    }

    /// The number of levels.
    pub fn levels(&self) -> u32 {
        self.levels
    }

    /// `S`: subdivided vertices × base vertices.
    pub fn matrix(&self) -> &SparseMatrix {
        &self.matrix
    }

    /// The subdivided triangles (4^levels per base triangle, in place; module docs).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Number of subdivided vertices.
    pub fn vertex_count(&self) -> usize {
        self.matrix.rows()
    }

    /// Number of base vertices `S` expects.
    pub fn base_vertex_count(&self) -> usize {
        self.matrix.columns()
    }

    /// The subdivided mesh for `base_positions` (allocates; for one-off use, not per frame).
    pub fn mesh(&self, base_positions: &[Vec3]) -> Result<Mesh, SubdivisionError> {
        let mut positions = vec![Vec3::ZERO; self.vertex_count()];
        self.matrix.apply(base_positions, &mut positions)?;
        Ok(Mesh {
            positions,
            triangles: self.triangles.clone(),
        })
    }
}

/// The one-level matrices `S_1, ..., S_levels` of `levels` Loop subdivisions of a topology
/// (`vertex_count` vertices, `triangles`) and the subdivided triangles, without the composed
/// `S`: what a palette stream's decoder rebuilds from the base triangles (issue 41), applying
/// the steps in turn. The steps are those of [`LoopSubdivision::steps`], bit for bit (each
/// built in `f64` and rounded once to `f32`).
///
/// # Errors
/// As [`LoopSubdivision::new`].
pub fn loop_steps(
    vertex_count: usize,
    triangles: &[[u32; 3]],
    levels: u32,
) -> Result<(Vec<SparseMatrix>, Vec<[u32; 3]>), SubdivisionError> {
    if !(1..=MAX_LEVELS).contains(&levels) {
        return Err(SubdivisionError::BadLevels { levels });
    }
    let mut vertex_count = vertex_count;
    let mut triangles = triangles.to_vec();
    let mut steps = Vec::with_capacity(levels as usize);
    for _ in 0..levels {
        let level = Level::build(vertex_count, &triangles)?;
        steps.push(level.matrix.into_f32());
        vertex_count = level.vertex_count;
        triangles = level.triangles;
    }
    Ok((steps, triangles))
}

/// Marks the missing second opposite vertex of a boundary edge.
const NONE: u32 = u32::MAX;

/// A CSR matrix with `f64` weights: the levels and their product are built in `f64` and rounded
/// once, so a 2-level `S` has the same rounding as a 1-level one.
#[derive(Clone, Debug)]
struct Csr64 {
    columns: usize,
    row_ptr: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<f64>,
}

impl Csr64 {
    fn rows(&self) -> usize {
        self.row_ptr.len() - 1
    }

    fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let (s, e) = (self.row_ptr[i], self.row_ptr[i + 1]);
        (&self.cols[s..e], &self.vals[s..e])
    }

    /// `self · rhs` (Gustavson's row-by-row product with a dense accumulator), columns sorted.
    fn mul(&self, rhs: &Csr64) -> Csr64 {
        debug_assert_eq!(self.columns, rhs.rows());
        let mut acc = vec![0.0f64; rhs.columns];
        let mut mark = vec![usize::MAX; rhs.columns];
        let mut touched: Vec<u32> = Vec::new();
        let mut out = Csr64 {
            columns: rhs.columns,
            row_ptr: Vec::with_capacity(self.rows() + 1),
            cols: Vec::new(),
            vals: Vec::new(),
        };
        out.row_ptr.push(0);
        for i in 0..self.rows() {
            touched.clear();
            let (ks, ws) = self.row(i);
            for (&k, &a) in ks.iter().zip(ws) {
                let (js, bs) = rhs.row(k as usize);
                for (&j, &b) in js.iter().zip(bs) {
                    let j_ = j as usize;
                    if mark[j_] != i {
                        mark[j_] = i;
                        acc[j_] = 0.0;
                        touched.push(j);
                    }
                    acc[j_] += a * b;
                }
            }
            touched.sort_unstable();
            for &j in &touched {
                out.cols.push(j);
                out.vals.push(acc[j as usize]);
            }
            out.row_ptr.push(out.cols.len());
        }
        out
    }

    fn into_f32(self) -> SparseMatrix {
        SparseMatrix {
            columns: self.columns,
            // nnz < rows * 25 for MAX_LEVELS, and rows fit in u32 (checked per level).
            row_ptr: self
                .row_ptr
                .iter()
                .map(|&p| u32::try_from(p).expect("nnz fits u32"))
                .collect(),
            cols: self.cols,
            vals: self.vals.iter().map(|&v| v as f32).collect(),
        }
    }
}

/// One subdivision level: its matrix (new vertices × old) and the new triangles.
struct Level {
    matrix: Csr64,
    vertex_count: usize,
    triangles: Vec<[u32; 3]>,
}

/// Warren's β for an interior even vertex of valence `n` (module docs).
fn warren_beta(n: usize) -> f64 {
    if n > 3 {
        3.0 / (8.0 * n as f64)
    } else {
        3.0 / 16.0
    }
}

impl Level {
    fn build(vertex_count: usize, triangles: &[[u32; 3]]) -> Result<Level, SubdivisionError> {
        // Edges with their opposite vertices, from the sorted half-edges.
        let mut half: Vec<(u32, u32, u32)> = Vec::with_capacity(triangles.len() * 3);
        for (ti, t) in triangles.iter().enumerate() {
            if let Some(&index) = t.iter().find(|&&i| i as usize >= vertex_count) {
                return Err(SubdivisionError::IndexOutOfRange {
                    triangle: ti,
                    index,
                    vertex_count,
                });
            }
            if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
                return Err(SubdivisionError::DegenerateTriangle {
                    triangle: ti,
                    indices: *t,
                });
            }
            for k in 0..3 {
                let (a, b, c) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                half.push((a.min(b), a.max(b), c));
            }
        }
        half.sort_unstable();
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(half.len() / 2 + 1);
        let mut opposite: Vec<[u32; 2]> = Vec::with_capacity(half.len() / 2 + 1);
        for group in half.chunk_by(|x, y| (x.0, x.1) == (y.0, y.1)) {
            let (a, b, c) = group[0];
            match group.len() {
                1 => opposite.push([c, NONE]),
                2 => opposite.push([c, group[1].2]),
                n => {
                    return Err(SubdivisionError::NonManifoldEdge { a, b, triangles: n });
                }
            }
            edges.push([a, b]);
        }
        let new_count = vertex_count as u64 + edges.len() as u64;
        if new_count > u64::from(u32::MAX) {
            return Err(SubdivisionError::TooLarge {
                vertices: new_count,
            });
        }

        // New-vertex order: first appearance walking the triangles (module docs).
        let mut rank = vec![NONE; edges.len()];
        let mut next = 0u32;
        for t in triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let e = edges
                    .binary_search(&[a.min(b), a.max(b)])
                    .expect("every triangle edge was collected");
                if rank[e] == NONE {
                    rank[e] = next;
                    next += 1;
                }
            }
        }
        let (edges, opposite) = {
            let mut e2 = vec![[0u32; 2]; edges.len()];
            let mut o2 = vec![[0u32; 2]; edges.len()];
            for (e, &r) in rank.iter().enumerate() {
                e2[r as usize] = edges[e];
                o2[r as usize] = opposite[e];
            }
            (e2, o2)
        };

        // Vertex -> (neighbour, edge) in CSR, each list sorted by neighbour.
        let mut offsets = vec![0usize; vertex_count + 1];
        for &[a, b] in &edges {
            offsets[a as usize + 1] += 1;
            offsets[b as usize + 1] += 1;
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut fill = offsets[..vertex_count].to_vec();
        let mut nbr = vec![(0u32, 0u32); edges.len() * 2];
        for (e, &[a, b]) in edges.iter().enumerate() {
            nbr[fill[a as usize]] = (b, e as u32);
            fill[a as usize] += 1;
            nbr[fill[b as usize]] = (a, e as u32);
            fill[b as usize] += 1;
        }
        for v in 0..vertex_count {
            nbr[offsets[v]..offsets[v + 1]].sort_unstable();
        }
        let ring = |v: usize| &nbr[offsets[v]..offsets[v + 1]];
        let edge_of = |v: u32, u: u32| -> u32 {
            let r = ring(v as usize);
            let i = r
                .binary_search_by_key(&u, |&(w, _)| w)
                .expect("the opposite vertex of an edge at v is a neighbour of v");
            r[i].1
        };

        let mut m = Csr64 {
            columns: vertex_count,
            row_ptr: Vec::with_capacity(new_count as usize + 1),
            cols: Vec::new(),
            vals: Vec::new(),
        };
        m.row_ptr.push(0);
        let mut row: Vec<(u32, f64)> = Vec::new();
        // Even vertices.
        for v in 0..vertex_count {
            row.clear();
            let r = ring(v);
            let boundary: Vec<u32> = r
                .iter()
                .filter(|&&(_, e)| opposite[e as usize][1] == NONE)
                .map(|&(u, _)| u)
                .collect();
            let fans_err = |fans| SubdivisionError::SeveralFans {
                vertex: v as u32,
                fans,
            };
            match boundary.len() {
                // Isolated vertex: keeps its position.
                _ if r.is_empty() => row.push((v as u32, 1.0)),
                0 => {
                    let fans = count_fans(v as u32, r, &opposite, None, &edge_of);
                    if fans != 1 {
                        return Err(fans_err(fans));
                    }
                    let n = r.len();
                    let beta = warren_beta(n);
                    row.push((v as u32, 1.0 - n as f64 * beta));
                    row.extend(r.iter().map(|&(u, _)| (u, beta)));
                }
                2 => {
                    let fans = count_fans(v as u32, r, &opposite, Some(boundary[0]), &edge_of);
                    if fans != 1 {
                        return Err(fans_err(fans));
                    }
                    row.push((v as u32, 0.75));
                    row.push((boundary[0], 0.125));
                    row.push((boundary[1], 0.125));
                }
                n => {
                    return Err(SubdivisionError::NonManifoldVertex {
                        vertex: v as u32,
                        boundary_edges: n,
                    });
                }
            }
            push_row(&mut m, &mut row);
        }
        // Odd vertices, one per edge.
        for (&[a, b], &[c, d]) in edges.iter().zip(&opposite) {
            row.clear();
            if d == NONE {
                row.extend([(a, 0.5), (b, 0.5)]);
            } else {
                row.extend([(a, 0.375), (b, 0.375), (c, 0.125), (d, 0.125)]);
            }
            push_row(&mut m, &mut row);
        }

        let mid = |a: u32, b: u32| vertex_count as u32 + edge_of(a, b);
        let mut out = Vec::with_capacity(triangles.len() * 4);
        for &[a, b, c] in triangles {
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            out.extend([[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        Ok(Level {
            matrix: m,
            vertex_count: new_count as usize,
            triangles: out,
        })
    }
}

/// Sorts a row by column, merges repeated columns (an edge whose two opposite vertices
/// coincide), and appends it to `m`.
fn push_row(m: &mut Csr64, row: &mut [(u32, f64)]) {
    row.sort_unstable_by_key(|&(c, _)| c);
    for &(c, w) in row.iter() {
        if m.cols.len() > *m.row_ptr.last().expect("row_ptr starts with 0")
            && m.cols.last() == Some(&c)
        {
            *m.vals.last_mut().expect("cols and vals grow together") += w;
        } else {
            m.cols.push(c);
            m.vals.push(w);
        }
    }
    m.row_ptr.push(m.cols.len());
}

/// Counts the fans of triangles around `v` by walking its link: from neighbour `u`, the next
/// neighbour is the opposite vertex of edge `(v, u)` not just come from. `ring` is `v`'s
/// (neighbour, edge) list; `start` is a boundary neighbour for a boundary vertex (the walk then
/// ends at the other boundary edge), `None` for an interior vertex (the walk ends back at the
/// start). One fan visits every neighbour; otherwise the walks are repeated from an unvisited
/// neighbour and counted. Valences are small (≤ ~12), so the visited set is a linear scan.
fn count_fans(
    v: u32,
    ring: &[(u32, u32)],
    opposite: &[[u32; 2]],
    start: Option<u32>,
    edge_of: &impl Fn(u32, u32) -> u32,
) -> usize {
    let mut visited = vec![false; ring.len()];
    let index = |u: u32| {
        ring.binary_search_by_key(&u, |&(w, _)| w)
            .expect("link vertices are neighbours")
    };
    let mut fans = 0;
    let mut first = start;
    loop {
        let from = match first.take() {
            Some(u) => u,
            None => match visited.iter().position(|&x| !x) {
                Some(i) => ring[i].0,
                None => return fans,
            },
        };
        fans += 1;
        let (mut prev, mut cur) = (NONE, from);
        loop {
            let i = index(cur);
            if visited[i] {
                break;
            }
            visited[i] = true;
            let [c, d] = opposite[edge_of(v, cur) as usize];
            let next = if c != prev { c } else { d };
            if next == NONE {
                break;
            }
            prev = cur;
            cur = next;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    #[test]
    fn quad_matrix_rows_by_hand() {
        let s = LoopSubdivision::new(&quad(), 1).unwrap();
        let m = s.matrix();
        // 4 vertices + 5 edges in first-appearance order: [0,1] [1,2] [0,2] [2,3] [0,3].
        assert_eq!((m.rows(), m.columns()), (9, 4));
        // Vertex 0 is a boundary vertex with boundary neighbours 1 and 3.
        assert_eq!(m.row(0), (&[0, 1, 3][..], &[0.75, 0.125, 0.125][..]));
        // Edge [0, 2] (row 4 + 2) is the interior diagonal, opposite 1 and 3.
        assert_eq!(
            m.row(6),
            (&[0, 1, 2, 3][..], &[0.375, 0.125, 0.375, 0.125][..])
        );
        // Edge [0, 1] is on the boundary.
        assert_eq!(m.row(4), (&[0, 1][..], &[0.5, 0.5][..]));
        assert_eq!(s.triangles().len(), 8);
    }

    /// `loop_steps` (a palette decoder's rebuild) gives `LoopSubdivision`'s steps and
    /// triangles bit for bit, at every level, and refuses what `new` refuses.
    #[test]
    fn loop_steps_are_the_subdivisions_steps() {
        let m = quad();
        for levels in 1..=MAX_LEVELS {
            let s = LoopSubdivision::new(&m, levels).unwrap();
            let (steps, triangles) = loop_steps(m.vertex_count(), &m.triangles, levels).unwrap();
            assert_eq!(steps, s.steps(), "levels {levels}");
            assert_eq!(triangles, s.triangles(), "levels {levels}");
        }
        assert_eq!(
            loop_steps(4, &m.triangles, 0).unwrap_err(),
            SubdivisionError::BadLevels { levels: 0 }
        );
        assert!(matches!(
            loop_steps(3, &m.triangles, 1).unwrap_err(),
            SubdivisionError::IndexOutOfRange { index: 3, .. }
        ));
    }

    /// The documented triangle order (module docs), which `runtime::detail`'s grouped normal
    /// scatter relies on: each coarser triangle `[a, b, c]` becomes `[a, ab, ca]`,
    /// `[ab, b, bc]`, `[ca, bc, c]`, `[ab, bc, ca]`, in place, at every level.
    #[test]
    fn children_come_in_groups_of_four_in_place() {
        let m = quad();
        let one = LoopSubdivision::new(&m, 1).unwrap();
        let two = LoopSubdivision::new(&m, 2).unwrap();
        for (coarse, fine) in [
            (&m.triangles[..], one.triangles()),
            (one.triangles(), two.triangles()),
        ] {
            assert_eq!(fine.len(), 4 * coarse.len());
            for (t, g) in coarse.iter().zip(fine.chunks_exact(4)) {
                let [a, b, c] = *t;
                let (ab, bc, ca) = (g[0][1], g[1][2], g[0][2]);
                assert_eq!(
                    [g[0], g[1], g[2], g[3]],
                    [[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]],
                    "children of {t:?}"
                );
            }
        }
    }

    #[test]
    fn bad_levels_and_sizes_are_errors() {
        for levels in [0, MAX_LEVELS + 1] {
            let e = LoopSubdivision::new(&quad(), levels).unwrap_err();
            assert_eq!(e, SubdivisionError::BadLevels { levels });
        }
        let s = LoopSubdivision::new(&quad(), 1).unwrap();
        let mut out = vec![Vec3::ZERO; 9];
        let e = s.matrix().apply(&[Vec3::ZERO; 3], &mut out).unwrap_err();
        assert_eq!(
            e.to_string(),
            "base positions: 3 vertices, expected 4",
            "{e:?}"
        );
        let e = s
            .matrix()
            .apply(&[Vec3::ZERO; 4], &mut out[..8])
            .unwrap_err();
        assert_eq!(e.to_string(), "output: 8 vertices, expected 9");
    }

    #[test]
    fn degenerate_and_out_of_range_triangles_are_named() {
        let mut m = quad();
        m.triangles.push([1, 1, 2]);
        let e = LoopSubdivision::new(&m, 1).unwrap_err();
        assert_eq!(
            e.to_string(),
            "Loop subdivision: triangle 2 [1, 1, 2] is degenerate (repeats a vertex)"
        );
        m.triangles[2] = [1, 2, 7];
        let e = LoopSubdivision::new(&m, 1).unwrap_err();
        assert!(
            matches!(
                e,
                SubdivisionError::IndexOutOfRange {
                    triangle: 2,
                    index: 7,
                    vertex_count: 4
                }
            ),
            "{e}"
        );
    }

    #[test]
    fn isolated_vertex_keeps_its_position() {
        let mut m = quad();
        m.positions.push(Vec3::splat(5.0));
        let s = LoopSubdivision::new(&m, 2).unwrap();
        assert_eq!(s.matrix().row(4), (&[4u32][..], &[1.0f32][..]));
    }
}

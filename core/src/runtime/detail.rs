//! The detail layer at run time: HZY11 eq. 4's `+ h(c) n(v)` on the Loop-subdivided base mesh.
//!
//! HZY11 §5.3 (eq. 4): the skinned low-resolution mesh is subdivided "in the same way as in the
//! subdivision procedure for detail extraction" (§4), each subdivided vertex gets its normal
//! `n(v)`, and the regressed per-vertex displacement `h(c)` moves it along that normal. Per frame
//! (DESIGN step 9):
//! 1. `high = S · base` with the fixed Loop matrices ([`LoopSubdivision`]): [`DetailSynth`]
//!    applies the one-level matrices in turn ([`LoopSubdivision::steps`], fewer entries than
//!    the composed `S`), [`DetailSynth::subdivide`] the composed `S` in one product;
//! 2. area-weighted unit vertex normals of `high`, the definition of
//!    [`crate::mesh::compute_vertex_normals`] (which training uses to measure `h`);
//! 3. `out = high + h ⊙ n` ([`displace`]).
//!
//! `h = D · xi(c)` itself (one dense mat-vec) is the caller's; [`DetailSynth`] takes it as a
//! slice. [`DetailSynth`] holds `S`, the topology and its buffers, so a frame allocates nothing;
//! it fuses the normalisation of step 2 with step 3 in one pass over the vertices.
//!
//! Normals, two ways ([`NormalsMethod`]); measured on the 151K-vertex 2-level hand, one core
//! (`benches/detail.rs`), both bound by arithmetic, not memory (renumbering the vertices for
//! locality changed neither):
//! - scatter ([`scatter_normals`]): one cross product per triangle, added to its three corners;
//!   ~1.5 ms. Sequential: the corners of different triangles collide.
//! - gather ([`VertexFans`]): each vertex sums the face normals of its own triangles along its
//!   one-ring, so rows are independent and split over threads without atomics or per-thread
//!   buffers, but every face normal is computed at all three corners; ~2.8 ms on one core.
//!
//! [`NormalsMethod::Auto`] scatters on one thread and gathers when the rayon pool has several.
//! The two sum in different orders, so their normals differ in the last bits (≤ ~1e-6).
//!
//! With the `parallel` feature the vertex passes split into chunks of [`PARALLEL_CHUNK`] on the
//! rayon pool when the pool has more than one thread; otherwise the same kernels run on the
//! calling thread (as in [`super::skin`]).

use std::sync::Arc;

use glam::{Vec3, Vec3A};

use super::fill_rows;
#[cfg(feature = "parallel")]
use super::use_pool;
use crate::mesh::Mesh;
use crate::mesh::subdivision::{LoopSubdivision, SparseMatrix, SubdivisionError};
use crate::mesh::topology::accumulate_face_normals;

/// Vertices per rayon task. A subdivided vertex costs ~10 ns per pass, so 4096 of them
/// (~40 µs) dwarf the task overhead (~1 µs) while 151K vertices still make ~37 tasks.
pub const PARALLEL_CHUNK: usize = 4096;

/// An error from the detail layer: building the subdivision, or a buffer of the wrong size.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DetailError {
    /// Building `S` failed, or a base buffer does not match it.
    #[error(transparent)]
    Subdivision(#[from] SubdivisionError),
    /// A per-vertex buffer does not have one entry per subdivided vertex.
    #[error("detail layer: {what} has {got} entries, expected {expected} (one per vertex)")]
    Length {
        /// Which buffer ("displacements h", "normals", "output").
        what: &'static str,
        /// The length required.
        expected: usize,
        /// The length found.
        got: usize,
    },
}

fn check_len(what: &'static str, expected: usize, got: usize) -> Result<(), DetailError> {
    if expected == got {
        Ok(())
    } else {
        Err(DetailError::Length {
            what,
            expected,
            got,
        })
    }
}

/// Separates the chains of one vertex's fan in [`VertexFans`].
const BREAK: u32 = u32::MAX;

/// For every vertex, the triangles around it as chains of their other corners, in CSR form:
/// consecutive entries `r_i`, `r_i+1` of a chain are the other two corners of one incident
/// triangle in its winding order (the triangle is `[v, r_i, r_i+1]` up to rotation), so
/// `(p[r_i] - p[v]) × (p[r_i+1] - p[v])` is its face normal with twice its area as length.
///
/// On an oriented manifold each vertex's triangles form one chain, closed (first entry repeated
/// at the end) inside and open on the boundary: `n` triangles take `n + 1` entries and every
/// neighbour is loaded once, where a list of triangles would load each twice. Triangles that do
/// not chain (inconsistent winding, several fans) are stored as further chains after a
/// separator, so any triangle list gives the same normals as [`scatter_normals`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VertexFans {
    offsets: Vec<u32>,
    chains: Vec<u32>,
}

impl VertexFans {
    /// Builds the fans of `vertex_count` vertices from `triangles`.
    ///
    /// # Panics
    /// If a triangle index is `>= vertex_count`, or there are 2³² or more corners.
    pub fn new(vertex_count: usize, triangles: &[[u32; 3]]) -> VertexFans {
        // The incident triangles of every vertex as (b, c) pairs, in CSR.
        let mut start = vec![0u32; vertex_count + 1];
        for t in triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for v in 0..vertex_count {
            start[v + 1] += start[v];
        }
        let mut fill = start[..vertex_count].to_vec();
        let mut pairs = vec![[0u32; 2]; triangles.len() * 3];
        for &[a, b, c] in triangles {
            for (v, pair) in [(a, [b, c]), (b, [c, a]), (c, [a, b])] {
                pairs[fill[v as usize] as usize] = pair;
                fill[v as usize] += 1;
            }
        }
        // Chain them per vertex (valences are small: the quadratic scans cost nothing).
        let mut offsets = Vec::with_capacity(vertex_count + 1);
        let mut chains = Vec::with_capacity(pairs.len() + vertex_count);
        offsets.push(0u32);
        let mut used = Vec::new();
        for v in 0..vertex_count {
            let fan = &pairs[start[v] as usize..start[v + 1] as usize];
            used.clear();
            used.resize(fan.len(), false);
            let mut left = fan.len();
            while left > 0 {
                if chains.len() > *offsets.last().expect("starts with 0") as usize {
                    chains.push(BREAK);
                }
                // Open chains start at a pair whose first corner no other pair ends at.
                let unused = |i: &usize| !used[*i];
                let first = (0..fan.len())
                    .filter(unused)
                    .find(|&i| {
                        !(0..fan.len()).any(|j| !used[j] && j != i && fan[j][1] == fan[i][0])
                    })
                    .or_else(|| (0..fan.len()).find(unused))
                    .expect("left > 0");
                used[first] = true;
                left -= 1;
                chains.extend(fan[first]);
                let mut end = fan[first][1];
                while let Some(i) = (0..fan.len()).find(|&i| !used[i] && fan[i][0] == end) {
                    used[i] = true;
                    left -= 1;
                    end = fan[i][1];
                    chains.push(end);
                }
            }
            offsets.push(u32::try_from(chains.len()).expect("fewer than 2^32 corners"));
        }
        VertexFans { offsets, chains }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Stored entries (neighbour indices and separators), the table's size in `u32`s.
    pub fn len(&self) -> usize {
        self.chains.len()
    }

    /// Whether no vertex has a triangle.
    pub fn is_empty(&self) -> bool {
        self.chains.is_empty()
    }

    /// Area-weighted unit vertex normals of `positions` into `out` (one per vertex). A vertex
    /// whose triangles have no area (or that has none) gets `Vec3::ZERO`, as in
    /// [`crate::mesh::compute_vertex_normals`]: a displacement along it is no displacement.
    pub fn normals<P>(&self, positions: &[P], out: &mut [Vec3]) -> Result<(), DetailError>
    where
        P: Copy + Into<Vec3A> + Sync,
    {
        let n = self.vertex_count();
        check_len("positions", n, positions.len())?;
        check_len("normals", n, out.len())?;
        fill_rows(out, PARALLEL_CHUNK, |first, o| {
            self.normals_rows(positions, first, o)
        });
        Ok(())
    }

    /// [`VertexFans::normals`] for the vertices `first .. first + out.len()` only.
    ///
    /// # Panics
    /// If the range runs past [`VertexFans::vertex_count`] or a corner is outside `positions`.
    #[inline]
    pub fn normals_rows<P: Copy + Into<Vec3A>>(
        &self,
        positions: &[P],
        first: usize,
        out: &mut [Vec3],
    ) {
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.normal(positions, first + i).into();
        }
    }

    /// Normals and HZY11 eq. 4's displacement in one pass: for every vertex `v`,
    /// `normals[v] = n(v)` of `high` and `out[v] = high[v] + h[v] n(v)`. Reads `high` only, so
    /// every normal is that of the undisplaced mesh.
    pub fn normals_and_displace(
        &self,
        high: &[Vec3A],
        h: &[f32],
        normals: &mut [Vec3A],
        out: &mut [Vec3],
    ) -> Result<(), DetailError> {
        let n = self.vertex_count();
        check_len("positions", n, high.len())?;
        check_len("displacements h", n, h.len())?;
        check_len("normals", n, normals.len())?;
        check_len("output", n, out.len())?;
        #[cfg(feature = "parallel")]
        if use_pool(n, PARALLEL_CHUNK) {
            use rayon::prelude::*;
            out.par_chunks_mut(PARALLEL_CHUNK)
                .zip(normals.par_chunks_mut(PARALLEL_CHUNK))
                .enumerate()
                .for_each(|(c, (o, nm))| {
                    self.normals_and_displace_rows(high, h, c * PARALLEL_CHUNK, nm, o)
                });
            return Ok(());
        }
        self.normals_and_displace_rows(high, h, 0, normals, out);
        Ok(())
    }

    /// [`VertexFans::normals_and_displace`] for the vertices `first .. first + out.len()`
    /// (`normals` as long as `out`).
    ///
    /// # Panics
    /// If the range runs past [`VertexFans::vertex_count`], `h` or `high`.
    #[inline]
    pub fn normals_and_displace_rows(
        &self,
        high: &[Vec3A],
        h: &[f32],
        first: usize,
        normals: &mut [Vec3A],
        out: &mut [Vec3],
    ) {
        let rows = out.len();
        let iter = out
            .iter_mut()
            .zip(normals.iter_mut())
            .zip(&h[first..first + rows])
            .enumerate();
        for (i, ((o, nm), &hv)) in iter {
            let v = first + i;
            let n = self.normal(high, v);
            *nm = n;
            *o = (high[v] + hv * n).into();
        }
    }

    /// The unit area-weighted normal of vertex `v`: the sum of `d_i × d_i+1` along its chains,
    /// `d_i = p[r_i] - p[v]`.
    #[inline(always)]
    fn normal<P: Copy + Into<Vec3A>>(&self, positions: &[P], v: usize) -> Vec3A {
        let chain = &self.chains[self.offsets[v] as usize..self.offsets[v + 1] as usize];
        let p: Vec3A = positions[v].into();
        let mut it = chain.iter();
        let Some(&r) = it.next() else {
            return Vec3A::ZERO;
        };
        let mut q = positions[r as usize].into() - p;
        let mut n = Vec3A::ZERO;
        while let Some(&r) = it.next() {
            if r == BREAK {
                match it.next() {
                    Some(&r) => q = positions[r as usize].into() - p,
                    None => break,
                }
                continue;
            }
            let d = positions[r as usize].into() - p;
            n += q.cross(d);
            q = d;
        }
        n.normalize_or_zero()
    }
}

/// Area-weighted unit vertex normals by a scatter pass over the triangles (zero, accumulate each
/// face normal at its corners, normalise): the textbook method and the reference for
/// [`VertexFans::normals`]. Single-threaded; `out` must have one entry per position.
///
/// # Panics
/// If a triangle index is outside `positions`.
pub fn scatter_normals(
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    out: &mut [Vec3],
) -> Result<(), DetailError> {
    check_len("normals", positions.len(), out.len())?;
    accumulate_face_normals(positions, triangles, out);
    for n in out.iter_mut() {
        *n = n.normalize_or_zero();
    }
    Ok(())
}

/// HZY11 eq. 4's second term: `positions[v] += h[v] * normals[v]` for every vertex.
pub fn displace(positions: &mut [Vec3], normals: &[Vec3], h: &[f32]) -> Result<(), DetailError> {
    check_len("normals", positions.len(), normals.len())?;
    check_len("displacements h", positions.len(), h.len())?;
    #[cfg(feature = "parallel")]
    if use_pool(positions.len(), PARALLEL_CHUNK) {
        use rayon::prelude::*;
        positions
            .par_chunks_mut(PARALLEL_CHUNK)
            .zip(normals.par_chunks(PARALLEL_CHUNK))
            .zip(h.par_chunks(PARALLEL_CHUNK))
            .for_each(|((p, n), h)| displace_kernel(p, n, h));
        return Ok(());
    }
    displace_kernel(positions, normals, h);
    Ok(())
}

#[inline]
fn displace_kernel(positions: &mut [Vec3], normals: &[Vec3], h: &[f32]) {
    for ((p, &n), &h) in positions.iter_mut().zip(normals).zip(h) {
        *p += h * n;
    }
}

/// How [`DetailSynth`] computes vertex normals (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NormalsMethod {
    /// [`NormalsMethod::Scatter`] on one thread, [`NormalsMethod::Gather`] when the `parallel`
    /// feature is on and the rayon pool has more than one thread.
    #[default]
    Auto,
    /// One cross product per triangle added to its corners: fastest on one core, sequential.
    Scatter,
    /// Per vertex over its one-ring ([`VertexFans`]): 3x the arithmetic, but parallel.
    Gather,
}

/// `S`, the one-ring table and Loop's groups: the immutable part of a [`DetailSynth`], shared
/// between its clones (one per stream of frames) through an `Arc`.
#[derive(Debug)]
struct DetailTopology {
    subdivision: LoopSubdivision,
    fans: VertexFans,
    /// Every group of four subdivided triangles as its six vertices `[a, b, c, ab, bc, ca]`
    /// ([`loop_groups`]): half the bytes of the triangles the scatter would otherwise read.
    groups: Vec<[u32; 6]>,
    /// Each level's trailing rows of Loop edge points as stencils ([`EdgeStencils`]), one per
    /// [`LoopSubdivision::steps`].
    edges: Vec<EdgeStencils>,
}

/// The rows `first..` of one level's matrix that are Loop edge points (`3/8 (a + b) + 1/8 (c +
/// d)` inside, `1/2 (a + b)` on the boundary), as their four vertices `[a, b, c, d]` (`[a, b,
/// a, b]` on the boundary): 16 bytes a row instead of 36 in compressed rows, and no weights to
/// load (issue 23: the detail frame's matrices, `D` among them, overflow the last-level cache,
/// so its bytes are its time). Loop's documented order puts the edge points last; rows of any
/// other form before them stay compressed rows.
#[derive(Debug)]
struct EdgeStencils {
    first: usize,
    quads: Vec<[u32; 4]>,
}

impl EdgeStencils {
    /// The longest run of edge-point rows at the end of `s`.
    fn new(s: &SparseMatrix) -> EdgeStencils {
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

/// `out[k] = 3/8 (x[a] + x[b]) + 1/8 (x[c] + x[d])` for `quads[k] = [a, b, c, d]`.
#[inline(always)]
fn edge_rows(quads: &[[u32; 4]], x: &[Vec3A], out: &mut [Vec3A]) {
    for (o, q) in out.iter_mut().zip(quads) {
        let [a, b, c, d] = q.map(|i| x[i as usize]);
        *o = (a + b) * 0.375 + (c + d) * 0.125;
    }
}

/// Rows `first .. first + out.len()` of `s · x` on 4-lane rows: compressed rows before
/// `edges.first` ([`apply_rows_padded`]), stencils from there ([`edge_rows`]).
fn apply_step(
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
        let x = &x[..s.columns()];
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = super::simd::fma() {
            simd.vectorize(v3::EdgeRows {
                quads,
                x,
                out: stencils,
            });
            return;
        }
        edge_rows(quads, x, stencils);
    }
}

/// Rows of `h` regressed at a time in [`DetailSynth::synthesize_regressed`]'s last pass: 256
/// rows of a 14-example `D` are 14 KB, so a block's rows of `D`, its `h` and its positions meet
/// in the first-level cache instead of `h` making a round trip through memory.
pub const H_BLOCK: usize = 256;

/// Writes the displacements `h` of the vertices `first .. first + rows.len()` into `rows`
/// (e.g. `D xi + b` for those rows,
/// [`DetailRegressor::apply_rows`](super::displacement::DetailRegressor::apply_rows)).
pub type RegressRows<'a> = &'a (dyn Fn(usize, &mut [f32]) + Sync);

/// The per-frame detail synthesis of HZY11 eq. 4 (module docs): `S`, the subdivided topology,
/// and reusable buffers for `S · base` and the normals. Cloning shares `S` and the topology and
/// copies only the buffers, so each stream of frames clones its own from one built per model.
///
/// Its buffers hold 4-lane positions ([`Vec3A`]): the sparse product reads a vertex in one load
/// and writes it in one store, and so do the normal scatter's loads and read-modify-writes
/// (issue 23: a 3-lane `Vec3` takes two loads and an insert, a store two).
#[derive(Clone, Debug)]
pub struct DetailSynth {
    topology: Arc<DetailTopology>,
    method: NormalsMethod,
    /// The frame's base positions as 4-lane rows, the first level's input.
    base: Vec<Vec3A>,
    /// The intermediate levels' vertices (`levels - 1` buffers) of the factored product.
    stages: Vec<Vec<Vec3A>>,
    /// `S · base` of the current frame: the normals must be those of the undisplaced mesh.
    high: Vec<Vec3A>,
    normals: Vec<Vec3A>,
}

/// Where a frame's displacements come from.
enum Heights<'a> {
    /// Computed by the caller.
    Given(&'a [f32]),
    /// Regressed block by block into `h` by `rows` during the last pass.
    Regressed {
        h: &'a mut [f32],
        rows: RegressRows<'a>,
    },
}

impl DetailSynth {
    /// The synthesis for a subdivision built by the caller (e.g. the one training used), with
    /// [`NormalsMethod::Auto`].
    pub fn new(subdivision: LoopSubdivision) -> DetailSynth {
        let n = subdivision.vertex_count();
        let fans = VertexFans::new(n, subdivision.triangles());
        let groups = loop_groups(subdivision.triangles());
        let steps = subdivision.steps();
        let edges = steps.iter().map(EdgeStencils::new).collect();
        let stages = steps[..steps.len().saturating_sub(1)]
            .iter()
            .map(|s| vec![Vec3A::ZERO; s.rows()])
            .collect();
        DetailSynth {
            stages,
            base: Vec::with_capacity(subdivision.base_vertex_count()),
            topology: Arc::new(DetailTopology {
                subdivision,
                fans,
                groups,
                edges,
            }),
            method: NormalsMethod::Auto,
            high: vec![Vec3A::ZERO; n],
            normals: vec![Vec3A::ZERO; n],
        }
    }

    /// Subdivides `base`'s topology `levels` times ([`LoopSubdivision::new`]) and prepares the
    /// synthesis.
    pub fn from_mesh(base: &Mesh, levels: u32) -> Result<DetailSynth, DetailError> {
        Ok(DetailSynth::new(LoopSubdivision::new(base, levels)?))
    }

    /// The same synthesis computing normals with `method`.
    pub fn with_normals_method(mut self, method: NormalsMethod) -> DetailSynth {
        self.method = method;
        self
    }

    /// The normals method chosen.
    pub fn normals_method(&self) -> NormalsMethod {
        self.method
    }

    /// The subdivision: `S` and the subdivided triangles (the index buffer to render `out`).
    pub fn subdivision(&self) -> &LoopSubdivision {
        &self.topology.subdivision
    }

    /// The one-ring table of [`NormalsMethod::Gather`].
    pub fn fans(&self) -> &VertexFans {
        &self.topology.fans
    }

    /// Number of subdivided vertices: the length of `h` and `out`.
    pub fn vertex_count(&self) -> usize {
        self.topology.subdivision.vertex_count()
    }

    /// Number of base vertices: the length of `base`.
    pub fn base_vertex_count(&self) -> usize {
        self.topology.subdivision.base_vertex_count()
    }

    /// The unit normals of the undisplaced subdivided mesh `S · base` from the last
    /// [`DetailSynth::synthesize`] (zeros before the first).
    pub fn normals(&self) -> &[Vec3A] {
        &self.normals
    }

    /// `out = S · base` (rows split over the pool with the `parallel` feature).
    pub fn subdivide(&self, base: &[Vec3], out: &mut [Vec3]) -> Result<(), DetailError> {
        let s = self.topology.subdivision.matrix();
        s.check(base, out.len())?;
        fill_rows(out, PARALLEL_CHUNK, |first, o| s.apply_rows(base, first, o));
        Ok(())
    }

    /// HZY11 eq. 4: `out = S · base + h ⊙ n(S · base)`. `base` has
    /// [`DetailSynth::base_vertex_count`] entries (the skinned base mesh), `h` and `out`
    /// [`DetailSynth::vertex_count`]. Afterwards [`DetailSynth::normals`] holds `n`.
    /// Allocates nothing.
    pub fn synthesize(
        &mut self,
        base: &[Vec3],
        h: &[f32],
        out: &mut [Vec3],
    ) -> Result<(), DetailError> {
        check_len("displacements h", self.vertex_count(), h.len())?;
        self.synthesize_heights(base, Heights::Given(h), out)
    }

    /// [`DetailSynth::synthesize`] with `h` regressed during the last pass: `rows(first,
    /// block)` fills `h[first .. first + block.len()]` just before those vertices are displaced
    /// (blocks of [`H_BLOCK`] on one thread), so the regression's matrix streams through the
    /// cache once beside the positions it moves instead of in a pass of its own that evicts
    /// them (issue 23). Afterwards `h` holds every vertex's displacement. Allocates nothing.
    pub fn synthesize_regressed(
        &mut self,
        base: &[Vec3],
        rows: RegressRows<'_>,
        h: &mut [f32],
        out: &mut [Vec3],
    ) -> Result<(), DetailError> {
        check_len("displacements h", self.vertex_count(), h.len())?;
        self.synthesize_heights(base, Heights::Regressed { h, rows }, out)
    }

    fn synthesize_heights(
        &mut self,
        base: &[Vec3],
        heights: Heights<'_>,
        out: &mut [Vec3],
    ) -> Result<(), DetailError> {
        check_len("output", self.vertex_count(), out.len())?;
        self.subdivide_steps(base)?;
        let n = self.vertex_count();
        let (h, pooled): (&[f32], bool) = match heights {
            Heights::Given(h) => (h, pooled(n)),
            Heights::Regressed { h, rows } if pooled(n) || self.gathers() => {
                // Several threads (or the gather): regress in a parallel pass of its own.
                fill_rows(h, PARALLEL_CHUNK, rows);
                (h, pooled(n))
            }
            Heights::Regressed { h, rows } => {
                scatter_groups(&self.high, &self.topology.groups, &mut self.normals);
                regress_and_displace(rows, &self.high, h, &mut self.normals, out);
                return Ok(());
            }
        };
        if self.gathers() {
            return self
                .topology
                .fans
                .normals_and_displace(&self.high, h, &mut self.normals, out);
        }
        scatter_groups(&self.high, &self.topology.groups, &mut self.normals);
        normalize_and_displace(&self.high, h, &mut self.normals, out, pooled);
        Ok(())
    }

    /// `self.high = S · base` as the one-level products in turn
    /// ([`LoopSubdivision::steps`]), each from and to 4-lane rows ([`apply_rows_padded`]).
    fn subdivide_steps(&mut self, base: &[Vec3]) -> Result<(), DetailError> {
        let topology = &*self.topology;
        let steps = topology.subdivision.steps();
        let (last, inner) = steps.split_last().expect("at least one level");
        let last_edges = topology.edges.last().expect("one per level");
        steps[0].check(base, steps[0].rows())?;
        self.base.clear();
        self.base.extend(base.iter().map(|&p| Vec3A::from(p)));
        for (k, (step, edges)) in inner.iter().zip(&topology.edges).enumerate() {
            let (done, rest) = self.stages.split_at_mut(k);
            let input = done.last().unwrap_or(&self.base);
            fill_rows(&mut rest[0], PARALLEL_CHUNK, |first, o| {
                apply_step(step, edges, input, first, o)
            });
        }
        let input = self.stages.last().unwrap_or(&self.base);
        fill_rows(&mut self.high, PARALLEL_CHUNK, |first, o| {
            apply_step(last, last_edges, input, first, o)
        });
        Ok(())
    }

    /// Whether this frame's normals are gathered (resolves [`NormalsMethod::Auto`]).
    fn gathers(&self) -> bool {
        match self.method {
            NormalsMethod::Scatter => false,
            NormalsMethod::Gather => true,
            NormalsMethod::Auto => pooled(self.vertex_count()),
        }
    }
}

/// Whether passes over `n` vertices split over the rayon pool.
fn pooled(n: usize) -> bool {
    #[cfg(feature = "parallel")]
    return use_pool(n, PARALLEL_CHUNK);
    #[cfg(not(feature = "parallel"))]
    {
        let _ = n;
        false
    }
}

/// The six vertices `[a, b, c, ab, bc, ca]` of each group of four triangles in
/// [`LoopSubdivision::triangles`]' order (`[a, ab, ca]`, `[ab, b, bc]`, `[ca, bc, c]`,
/// `[ab, bc, ca]` per coarser triangle: the module's documented order, checked by its tests).
fn loop_groups(triangles: &[[u32; 3]]) -> Vec<[u32; 6]> {
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
fn scatter_groups(positions: &[Vec3A], groups: &[[u32; 6]], acc: &mut [Vec3A]) {
    acc.fill(Vec3A::ZERO);
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = super::simd::fma() {
        simd.vectorize(v3::ScatterGroups {
            positions,
            groups,
            acc,
        });
        return;
    }
    scatter_groups_body(positions, groups, acc);
}

/// [`scatter_groups`] after the zeroing: the same code for every instruction set.
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
fn normalize_and_displace(
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
    normalize_and_displace_kernel(high, h, normals, out);
}

/// The detail passes written in plain Rust (glam's 4-lane vectors, arrays the compiler
/// vectorises) compiled a second time for AVX2 + FMA, chosen at run time: three-operand
/// instructions instead of SSE2's copies, 8-wide square roots and divisions. Each is a struct
/// whose `call` is inlined into pulp's feature context (ARCHITECTURE.md, "Per-frame SIMD").
#[cfg(target_arch = "x86_64")]
mod v3 {
    use glam::{Vec3, Vec3A};

    use super::RegressRows;

    /// [`super::edge_rows`].
    pub(super) struct EdgeRows<'a> {
        pub(super) quads: &'a [[u32; 4]],
        pub(super) x: &'a [Vec3A],
        pub(super) out: &'a mut [Vec3A],
    }

    impl pulp::NullaryFnOnce for EdgeRows<'_> {
        type Output = ();

        #[inline(always)]
        fn call(self) {
            super::edge_rows(self.quads, self.x, self.out);
        }
    }

    /// [`super::scatter_groups_body`].
    pub(super) struct ScatterGroups<'a> {
        pub(super) positions: &'a [Vec3A],
        pub(super) groups: &'a [[u32; 6]],
        pub(super) acc: &'a mut [Vec3A],
    }

    impl pulp::NullaryFnOnce for ScatterGroups<'_> {
        type Output = ();

        #[inline(always)]
        fn call(self) {
            super::scatter_groups_body(self.positions, self.groups, self.acc);
        }
    }

    /// The fused last pass of [`super::DetailSynth::synthesize_regressed`] on one thread.
    pub(super) struct RegressAndDisplace<'a> {
        pub(super) rows: RegressRows<'a>,
        pub(super) high: &'a [Vec3A],
        pub(super) h: &'a mut [f32],
        pub(super) normals: &'a mut [Vec3A],
        pub(super) out: &'a mut [Vec3],
    }

    impl pulp::NullaryFnOnce for RegressAndDisplace<'_> {
        type Output = ();

        #[inline(always)]
        fn call(self) {
            super::regress_and_displace_body(self.rows, self.high, self.h, self.normals, self.out);
        }
    }
}

/// The single-threaded last pass with `h` regressed a block of [`H_BLOCK`] at a time.
fn regress_and_displace(
    rows: RegressRows<'_>,
    high: &[Vec3A],
    h: &mut [f32],
    normals: &mut [Vec3A],
    out: &mut [Vec3],
) {
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = super::simd::fma() {
        simd.vectorize(v3::RegressAndDisplace {
            rows,
            high,
            h,
            normals,
            out,
        });
        return;
    }
    regress_and_displace_body(rows, high, h, normals, out);
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
    if let Some(simd) = super::simd::fma() {
        super::simd::sparse_rows4(simd, ptr, cols, vals, x, out);
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
    use super::*;

    fn tetrahedron() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(1.0, 1.0, 1.0),
                Vec3::new(1.0, -1.0, -1.0),
                Vec3::new(-1.0, 1.0, -1.0),
                Vec3::new(-1.0, -1.0, 1.0),
            ],
            triangles: vec![[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
        }
    }

    #[test]
    fn fan_normals_match_scatter_normals_with_degenerate_and_isolated_vertices() {
        let mut m = tetrahedron();
        // A zero-area triangle (collinear corners) and an isolated vertex.
        m.positions.push(Vec3::new(3.0, 0.0, 0.0));
        m.positions.push(Vec3::new(5.0, 0.0, 0.0));
        m.positions.push(Vec3::new(9.0, 9.0, 9.0));
        m.triangles.push([4, 5, 0]);
        m.positions[0] = Vec3::new(4.0, 0.0, 0.0);
        let fans = VertexFans::new(m.vertex_count(), &m.triangles);
        let mut a = vec![Vec3::NAN; m.vertex_count()];
        let mut b = vec![Vec3::NAN; m.vertex_count()];
        fans.normals(&m.positions, &mut a).unwrap();
        scatter_normals(&m.positions, &m.triangles, &mut b).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((*x - *y).length() < 1e-6, "{x} vs {y}");
        }
        assert_eq!(a[6], Vec3::ZERO);
        assert_eq!(a[4], Vec3::ZERO);
    }

    /// A grid of `nx x ny` vertices at `at(i, j)`, two triangles a quad.
    fn grid(nx: u32, ny: u32, at: impl Fn(u32, u32) -> Vec3) -> Mesh {
        let mut m = Mesh::default();
        for j in 0..ny {
            for i in 0..nx {
                m.positions.push(at(i, j));
            }
        }
        let id = |a: u32, b: u32| b * nx + a;
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                m.triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                m.triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        m
    }

    #[test]
    fn fan_normals_match_scatter_normals_with_inconsistent_winding() {
        // A 3 x 3 grid of quads with bumpy heights, one triangle flipped.
        let mut m = grid(4, 4, |i, j| {
            Vec3::new(i as f32, j as f32, ((i * 7 + j * 3) % 5) as f32 * 0.1)
        });
        m.triangles[7].swap(1, 2);
        let fans = VertexFans::new(m.vertex_count(), &m.triangles);
        let mut a = vec![Vec3::NAN; m.vertex_count()];
        let mut b = vec![Vec3::NAN; m.vertex_count()];
        fans.normals(&m.positions, &mut a).unwrap();
        scatter_normals(&m.positions, &m.triangles, &mut b).unwrap();
        for (x, y) in a.iter().zip(&b) {
            assert!((*x - *y).length() < 1e-6, "{x} vs {y}");
        }
        // 18 triangles: 54 corners, plus one closing/separating entry per chain.
        assert!(fans.len() > 54, "{}", fans.len());
    }

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

    /// The fused synthesis (h regressed a block at a time inside the last pass) against an
    /// independent frame: the composed `S` applied with `SparseMatrix::apply_rows`, the plain
    /// scatter's normals, and `h` from the same row function, on a mesh of several blocks.
    #[test]
    fn regressed_synthesis_equals_the_unfused_frame() {
        let m = grid(13, 11, |i, j| {
            Vec3::new(i as f32 * 0.7, j as f32, ((i * 5 + j * 3) % 7) as f32 * 0.2)
        });
        let mut synth = DetailSynth::from_mesh(&m, 2).unwrap();
        let n = synth.vertex_count();
        assert!(
            n > 4 * H_BLOCK + 7,
            "{n} vertices: want several blocks and a partial one"
        );
        let height = |v: usize| ((v * 37) % 101) as f32 * 1e-3 - 0.05;
        let rows = |first: usize, rows: &mut [f32]| {
            for (k, r) in rows.iter_mut().enumerate() {
                *r = height(first + k);
            }
        };
        let mut h = vec![f32::NAN; n];
        let mut out = vec![Vec3::NAN; n];
        synth
            .synthesize_regressed(&m.positions, &rows, &mut h, &mut out)
            .unwrap();

        let mut high = vec![Vec3::ZERO; n];
        synth.subdivide(&m.positions, &mut high).unwrap();
        let mut normals = vec![Vec3::ZERO; n];
        scatter_normals(&high, synth.subdivision().triangles(), &mut normals).unwrap();
        for v in 0..n {
            assert_eq!(h[v], height(v), "h[{v}]");
            let want = high[v] + height(v) * normals[v];
            assert!(
                (out[v] - want).length() < 1e-5,
                "vertex {v}: {} vs {want}",
                out[v]
            );
            let got = Vec3::from(synth.normals()[v]);
            assert!((got - normals[v]).length() < 1e-5, "normal {v}");
        }
        // The given-h path writes the same frame.
        let mut given = vec![Vec3::NAN; n];
        synth.synthesize(&m.positions, &h, &mut given).unwrap();
        assert_eq!(given, out);
        let e = synth
            .synthesize_regressed(&m.positions, &rows, &mut h[1..], &mut out)
            .unwrap_err();
        assert!(e.to_string().contains("displacements h has"), "{e}");
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

    #[test]
    fn sizes_are_checked() {
        let mut d = DetailSynth::from_mesh(&tetrahedron(), 1).unwrap();
        let mut out = vec![Vec3::ZERO; 10];
        let e = d
            .synthesize(&tetrahedron().positions, &[0.0; 9], &mut out)
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "detail layer: displacements h has 9 entries, expected 10 (one per vertex)"
        );
        let e = d
            .synthesize(&tetrahedron().positions[..3], &[0.0; 10], &mut out)
            .unwrap_err();
        assert_eq!(e.to_string(), "base positions: 3 vertices, expected 4");
        let e = DetailSynth::from_mesh(&tetrahedron(), 0).unwrap_err();
        assert!(matches!(
            e,
            DetailError::Subdivision(SubdivisionError::BadLevels { levels: 0 })
        ));
    }
}

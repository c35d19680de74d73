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
//! `h = D · xi(c)` itself (one dense mat-vec) is the caller's: [`DetailSynth::synthesize`] takes
//! it as a slice, [`DetailSynth::synthesize_regressed`] as a function it calls a block of
//! [`H_BLOCK`] vertices at a time inside the last pass (the predictor's frame: `D` streams once
//! beside the positions it moves). [`DetailSynth`] holds `S`, the topology and its buffers, so a
//! frame allocates nothing; it fuses the normalisation of step 2 with step 3 in one pass over
//! the vertices. The passes themselves, on 4-lane positions, are in `passes`; the normals'
//! two methods and the plain displacement in `fans`.
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

mod fans;
mod passes;

pub use fans::{VertexFans, displace, scatter_normals};

use super::fill_rows;
#[cfg(feature = "parallel")]
use super::use_pool;
use crate::mesh::Mesh;
use crate::mesh::subdivision::{LoopSubdivision, SubdivisionError};
use passes::{
    EdgeStencils, apply_step, loop_groups, normalize_and_displace, regress_and_displace,
    scatter_groups,
};

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
    /// Each level's vertices of the factored product, one buffer per
    /// [`LoopSubdivision::steps`]; the last is `S · base` of the current frame (the normals must
    /// be those of the undisplaced mesh).
    levels: Vec<Vec<Vec3A>>,
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

impl<'a> Heights<'a> {
    /// All of `h`, regressed first in a pass of its own (over the pool with the `parallel`
    /// feature) when it is not given.
    fn into_slice(self) -> &'a [f32] {
        match self {
            Heights::Given(h) => h,
            Heights::Regressed { h, rows } => {
                fill_rows(h, PARALLEL_CHUNK, rows);
                h
            }
        }
    }
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
        let levels = steps.iter().map(|s| vec![Vec3A::ZERO; s.rows()]).collect();
        DetailSynth {
            levels,
            base: Vec::with_capacity(subdivision.base_vertex_count()),
            topology: Arc::new(DetailTopology {
                subdivision,
                fans,
                groups,
                edges,
            }),
            method: NormalsMethod::Auto,
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
        let pooled = pooled(self.vertex_count());
        let gathers = self.gathers();
        let high = self.levels.last().expect("one buffer per level");
        if gathers {
            let h = heights.into_slice();
            return self
                .topology
                .fans
                .normals_and_displace(high, h, &mut self.normals, out);
        }
        scatter_groups(high, &self.topology.groups, &mut self.normals);
        match heights {
            // One thread: each block regressed just before it is displaced.
            Heights::Regressed { h, rows } if !pooled => {
                regress_and_displace(rows, high, h, &mut self.normals, out);
            }
            heights => {
                normalize_and_displace(high, heights.into_slice(), &mut self.normals, out, pooled);
            }
        }
        Ok(())
    }

    /// Each level's vertices from the one before (`base` first): the one-level products in
    /// turn ([`LoopSubdivision::steps`]), on 4-lane rows (`passes::apply_step`).
    fn subdivide_steps(&mut self, base: &[Vec3]) -> Result<(), DetailError> {
        let topology = &*self.topology;
        let steps = topology.subdivision.steps();
        steps[0].check(base, steps[0].rows())?;
        self.base.clear();
        self.base.extend(base.iter().map(|&p| Vec3A::from(p)));
        for (k, (step, edges)) in steps.iter().zip(&topology.edges).enumerate() {
            let (done, rest) = self.levels.split_at_mut(k);
            let input = done.last().unwrap_or(&self.base);
            fill_rows(&mut rest[0], PARALLEL_CHUNK, |first, o| {
                apply_step(step, edges, input, first, o)
            });
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::{grid, tetrahedron};

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

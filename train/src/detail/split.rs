//! The automatic base/detail split (HZY11 §4, DESIGN.md data flow step 2), for example sets
//! that come at a single resolution.
//!
//! HZY11 §4 gets its smooth low-resolution meshes `P̄_i` by "mesh retiling and Laplacian
//! smoothing techniques \[Tur92\]" and measures the detail of each example `P_i` against the
//! subdivided `P̄_i`. Here the retiling is a vertex subset of the rest mesh chosen by
//! meshoptimizer's edge-collapse simplifier (whose output index buffer only references original
//! vertices), so the same subset taken from every example gives base meshes `B_i` in
//! correspondence with no registration step; each is then smoothed on the base topology with
//! the umbrella operator (Laplacian smoothing, as in Taubin, "A signal processing approach to
//! fair surface design", SIGGRAPH 1995, §4):
//!
//! ```text
//! p_v <- p_v + λ · (1/|N(v)|) Σ_{u ∈ N(v)} (p_u - p_v)        (all v at once, `iterations` times)
//! ```
//!
//! `N(v)` is `v`'s neighbours on the base topology, except that a vertex on the boundary uses
//! only its two boundary neighbours, so an open rim (the hand's wrist) is smoothed as a curve
//! and does not shrink into the surface.
//!
//! [`BaseSubset::simplify`] hits the requested vertex count within
//! [`VERTEX_COUNT_TOLERANCE`]: meshoptimizer stops at a target *index* count, so the target is
//! searched (proportional steps inside a bisection bracket, a handful of simplifier runs). The
//! result is compacted (subset ascending, triangles renumbered, degenerate triangles and
//! two-sided "pillows" dropped, see `compact`) and must be accepted by
//! [`LoopSubdivision::new`], which the detail layer runs on it: a simplification it still
//! refuses (a non-manifold edge or vertex) is retried with nearby targets, and if none is
//! accepted the split fails with the subdivision's reason. On the horse (8,431 vertices) every
//! target from 300 to 8,431 that was tried succeeds; at 200 its legs are squeezed until two
//! sheets share an edge, and the split says so.

use crease_core::glam::Vec3;
use crease_core::mesh::subdivision::{LoopSubdivision, SubdivisionError};
use crease_core::mesh::{Adjacency, Mesh, MeshError};
use meshopt::SimplifyOptions;

/// Allowed relative difference between the requested and the achieved base vertex count
/// (at least one vertex either way). The base resolution is a quality knob, not a contract: 2%
/// of 2,000 vertices changes the base edge length by 1% and is reached in two or three
/// simplifier runs, where an exact count would need many more runs and may not exist at all
/// (each edge collapse removes one vertex, but the simplifier works in batches).
pub const VERTEX_COUNT_TOLERANCE: f64 = 0.02;

/// Most simplifier runs spent searching for the target count: the used-vertex count is close to
/// linear in the target index count (a closed surface has about two triangles per vertex), so
/// proportional steps converge in two or three runs; the rest is margin for bisection on
/// unusual meshes.
const MAX_SEARCH_RUNS: usize = 24;

/// Nearby index targets (`+3, -3, +6, …` indices around the first count within tolerance)
/// tried when a simplification is refused by [`LoopSubdivision::new`]. Each differs by one
/// triangle, which changes which collapses the simplifier makes last, where non-manifold
/// configurations appear. 16 probes reach ±8 triangles (about ±4 vertices): the whole
/// tolerance band at a few hundred vertices. A mesh squeezed until its thin parts touch fails
/// on all of them, and more probes would not help it.
const MANIFOLD_PROBES: usize = 16;

/// meshoptimizer's error limit, relative to the mesh extents: 1.0 allows any collapse, so the
/// target count, not the error, is what stops the simplifier.
const TARGET_ERROR: f32 = 1.0;

/// Errors of the base/detail split. Each names what was expected and what was found.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SplitError {
    /// The rest mesh is invalid (a non-finite coordinate, an index out of range).
    #[error("base/detail split: rest mesh: {0}")]
    Mesh(String),
    /// The rest mesh has no triangles to simplify.
    #[error("base/detail split: the rest mesh has no triangles")]
    NoTriangles,
    /// The requested base vertex count is 0 or more than the mesh has.
    #[error(
        "base/detail split: {target} base vertices requested, expected 1..={vertex_count} \
         (the rest mesh's vertex count)"
    )]
    TargetOutOfRange {
        /// The requested count.
        target: usize,
        /// The rest mesh's vertex count.
        vertex_count: usize,
    },
    /// No simplification came within the tolerance of the requested vertex count.
    #[error(
        "base/detail split: {target} ± {tolerance} base vertices requested, the closest the \
         simplifier reached in {runs} runs is {closest}"
    )]
    CountNotReached {
        /// The requested count.
        target: usize,
        /// The allowed difference ([`VERTEX_COUNT_TOLERANCE`]).
        tolerance: usize,
        /// The achieved count nearest the target.
        closest: usize,
        /// Simplifier runs made.
        runs: usize,
    },
    /// Every simplification within tolerance was refused by Loop subdivision.
    #[error(
        "base/detail split: no manifold simplification to {target} ± {tolerance} vertices \
         ({tried} tried); the first was refused: {reason}"
    )]
    NotManifold {
        /// The requested count.
        target: usize,
        /// The allowed difference.
        tolerance: usize,
        /// Simplifications within tolerance that were checked.
        tried: usize,
        /// Why the first one was refused.
        reason: SubdivisionError,
    },
    /// A subset given to [`BaseSubset::from_parts`] is not strictly ascending.
    #[error(
        "base/detail split: subset entry {index} is vertex {vertex}, not above the previous \
         entry (expected strictly ascending)"
    )]
    SubsetOrder {
        /// Position in the subset.
        index: usize,
        /// The vertex found there.
        vertex: u32,
    },
    /// A subset given to [`BaseSubset::from_parts`] names a vertex the full mesh lacks.
    #[error(
        "base/detail split: subset entry {index} is vertex {vertex}, but the full mesh has \
         {full_vertex_count} vertices"
    )]
    SubsetOutOfRange {
        /// Position in the subset.
        index: usize,
        /// The vertex found there.
        vertex: u32,
        /// The full mesh's vertex count.
        full_vertex_count: usize,
    },
    /// Base triangles given to [`BaseSubset::from_parts`] are refused by Loop subdivision
    /// (an index out of range, a degenerate triangle, a non-manifold edge or vertex).
    #[error("base/detail split: base topology: {0}")]
    Topology(SubdivisionError),
    /// An example's position array does not match the rest mesh's vertex count.
    #[error("base/detail split: example has {got} vertices, expected {expected}")]
    Length {
        /// The rest mesh's vertex count.
        expected: usize,
        /// The length found.
        got: usize,
    },
    /// A position the base reads is NaN or infinite.
    #[error(
        "base/detail split: vertex {vertex} (base vertex {base_vertex}) is not finite: {value}"
    )]
    NonFinite {
        /// Index in the full mesh.
        vertex: usize,
        /// Index in the base mesh.
        base_vertex: usize,
        /// The position.
        value: Vec3,
    },
    /// The smoothing parameters are outside their stable range.
    #[error("base/detail split: smoothing lambda {lambda} outside [0, 1]")]
    BadSmoothing {
        /// The rejected step size.
        lambda: f32,
    },
}

impl From<MeshError> for SplitError {
    fn from(e: MeshError) -> Self {
        // MeshError holds an io::Error (not Clone); its message names everything needed.
        SplitError::Mesh(e.to_string())
    }
}

/// Umbrella-operator smoothing of the base meshes (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Smoothing {
    /// Number of simultaneous smoothing steps; 0 leaves the subset positions as they are.
    pub iterations: usize,
    /// Step size `λ` in `[0, 1]`: the fraction of the way to the neighbours' centroid each
    /// vertex moves per step. Above 1 the highest-frequency mode (eigenvalue 2 of the
    /// normalised umbrella operator) would be amplified instead of damped.
    pub lambda: f32,
}

impl Default for Smoothing {
    /// Three steps of `λ = 0.5`. The base vertices are samples of the detailed surface, so
    /// each carries the local detail (a wrinkle, a vein) as noise at base resolution; that
    /// noise is the highest-frequency content of the base mesh, which one `λ = 0.5` step halves
    /// or better, so three steps damp it by roughly 8x. Smooth large-scale shape (the signal
    /// the bones must fit) decays with the square of its frequency, so three steps move it
    /// by a fraction of a base edge: on the horse at 2,000 base vertices the smoothed rest
    /// base lies 0.11 base edges (0.3% of the horse's size) from the full surface on average,
    /// 0.65 at most. More steps would shrink thin parts further (Laplacian smoothing is not
    /// volume-preserving) and grow the displacements the detail layer must carry.
    fn default() -> Self {
        Smoothing {
            iterations: 3,
            lambda: 0.5,
        }
    }
}

/// How [`BaseSubset::simplify`] got its result.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimplifyStats {
    /// The requested vertex count.
    pub target: usize,
    /// meshoptimizer runs, search and manifold probes together.
    pub simplifier_runs: usize,
    /// Simplifications within tolerance refused by Loop subdivision before one was accepted.
    pub refused: usize,
    /// Triangles of the accepted simplification left out as degenerate or as cancelling
    /// duplicates (see the module docs).
    pub removed_triangles: usize,
    /// meshoptimizer's own error estimate of the result, relative to the mesh extents.
    pub relative_error: f32,
}

/// The vertex subset and simplified topology of the base mesh, shared by every example.
#[derive(Clone, Debug)]
pub struct BaseSubset {
    /// Base vertex `k` is full vertex `vertices[k]`; ascending.
    vertices: Vec<u32>,
    /// Triangles in base indices.
    triangles: Vec<[u32; 3]>,
    /// Vertex count of the full meshes the subset is taken from.
    full_vertex_count: usize,
    /// The smoothing neighbourhoods: all neighbours of an interior vertex, the boundary
    /// neighbours of a boundary vertex (module docs).
    smoothing: Adjacency,
    stats: SimplifyStats,
}

/// One simplifier run: the index target, its output and the vertices it uses.
struct Run {
    index_target: usize,
    indices: Vec<u32>,
    used: usize,
    error: f32,
}

impl BaseSubset {
    /// Simplifies `rest` to about `target_vertices` vertices (within
    /// [`VERTEX_COUNT_TOLERANCE`]) whose topology [`LoopSubdivision::new`] accepts (module
    /// docs). Deterministic.
    ///
    /// Borders are not locked (`SimplifyOptions::LockBorder`): the simplifier already only
    /// collapses border vertices along the border, so an open rim stays a rim; locking would
    /// keep every border vertex and could make a small target unreachable.
    pub fn simplify(rest: &Mesh, target_vertices: usize) -> Result<BaseSubset, SplitError> {
        rest.validate()?;
        let vertex_count = rest.vertex_count();
        if target_vertices == 0 || target_vertices > vertex_count {
            return Err(SplitError::TargetOutOfRange {
                target: target_vertices,
                vertex_count,
            });
        }
        if rest.triangles.is_empty() {
            return Err(SplitError::NoTriangles);
        }
        let tolerance = ((target_vertices as f64 * VERTEX_COUNT_TOLERANCE).floor() as usize).max(1);
        let within = |used: usize| used.abs_diff(target_vertices) <= tolerance;

        let indices: Vec<u32> = rest.triangles.iter().flatten().copied().collect();
        let positions: Vec<[f32; 3]> = rest.positions.iter().map(|p| p.to_array()).collect();
        let mut simplifier = Simplifier {
            indices: &indices,
            positions: &positions,
            stamp: vec![0; vertex_count],
            runs: 0,
        };

        // Search the index target: proportional steps (used vertices ~ linear in indices),
        // kept inside a bracket [lo, hi] whose ends gave too few / too many vertices.
        let all_used = simplifier.count_used(&indices);
        if all_used + tolerance < target_vertices {
            return Err(SplitError::CountNotReached {
                target: target_vertices,
                tolerance,
                closest: all_used,
                runs: 0,
            });
        }
        let (mut lo, mut hi) = (0usize, indices.len());
        let mut guess = round3(target_vertices as f64 * indices.len() as f64 / all_used as f64);
        let mut closest: Option<usize> = None;
        let mut found: Option<Run> = None;
        for _ in 0..MAX_SEARCH_RUNS {
            let run = simplifier.run(guess);
            if within(run.used) {
                found = Some(run);
                break;
            }
            if run.used < target_vertices {
                lo = lo.max(guess);
            } else {
                hi = hi.min(guess);
            }
            let used = run.used.max(1);
            if closest
                .is_none_or(|c| run.used.abs_diff(target_vertices) < c.abs_diff(target_vertices))
            {
                closest = Some(run.used);
            }
            let proportional = round3(guess as f64 * target_vertices as f64 / used as f64);
            let next = if proportional > lo && proportional < hi && proportional != guess {
                proportional
            } else {
                round3((lo + hi) as f64 / 2.0)
            };
            if next <= lo || next >= hi || next == guess {
                break;
            }
            guess = next;
        }
        let Some(first) = found else {
            return Err(SplitError::CountNotReached {
                target: target_vertices,
                tolerance,
                closest: closest.unwrap_or(all_used),
                runs: simplifier.runs,
            });
        };

        // The first candidate, then nearby targets, until one compacts to a count within
        // tolerance that Loop subdivision accepts.
        let base_target = first.index_target;
        let mut pending = Some(first);
        let mut refused = 0;
        let mut first_reason: Option<SubdivisionError> = None;
        let mut compacted_counts = Vec::new();
        for probe in 0..=MANIFOLD_PROBES {
            let run = match pending.take() {
                Some(run) => run,
                None => {
                    // +3, -3, +6, -6, … indices around the first index target within tolerance.
                    let step = 3 * probe.div_ceil(2);
                    let target = if probe % 2 == 1 {
                        base_target + step
                    } else {
                        base_target.saturating_sub(step)
                    };
                    if target == 0 || target > indices.len() {
                        continue;
                    }
                    let run = simplifier.run(target);
                    if !within(run.used) {
                        continue;
                    }
                    run
                }
            };
            let compacted = compact(&run.indices, vertex_count);
            if !within(compacted.vertices.len()) {
                compacted_counts.push(compacted.vertices.len());
                continue;
            }
            match checked_topology(compacted.vertices.len(), &compacted.triangles) {
                Ok(smoothing) => {
                    return Ok(BaseSubset {
                        vertices: compacted.vertices,
                        triangles: compacted.triangles,
                        full_vertex_count: vertex_count,
                        smoothing,
                        stats: SimplifyStats {
                            target: target_vertices,
                            simplifier_runs: simplifier.runs,
                            refused,
                            removed_triangles: compacted.removed,
                            relative_error: run.error,
                        },
                    });
                }
                Err(reason) => {
                    refused += 1;
                    first_reason.get_or_insert(reason);
                }
            }
        }
        Err(match first_reason {
            Some(reason) => SplitError::NotManifold {
                target: target_vertices,
                tolerance,
                tried: refused,
                reason,
            },
            // Every candidate lost too many vertices to removed triangles.
            None => SplitError::CountNotReached {
                target: target_vertices,
                tolerance,
                closest: compacted_counts
                    .iter()
                    .copied()
                    .min_by_key(|&c| c.abs_diff(target_vertices))
                    .unwrap_or(0),
                runs: simplifier.runs,
            },
        })
    }

    /// A subset chosen elsewhere (e.g. read back from a trained model): base vertex `k` is full
    /// vertex `vertices[k]` (strictly ascending, below `full_vertex_count`), `triangles` in base
    /// indices, which [`LoopSubdivision::new`] must accept.
    pub fn from_parts(
        full_vertex_count: usize,
        vertices: Vec<u32>,
        triangles: Vec<[u32; 3]>,
    ) -> Result<BaseSubset, SplitError> {
        for (index, &vertex) in vertices.iter().enumerate() {
            if vertex as usize >= full_vertex_count {
                return Err(SplitError::SubsetOutOfRange {
                    index,
                    vertex,
                    full_vertex_count,
                });
            }
            if index > 0 && vertex <= vertices[index - 1] {
                return Err(SplitError::SubsetOrder { index, vertex });
            }
        }
        let smoothing =
            checked_topology(vertices.len(), &triangles).map_err(SplitError::Topology)?;
        let stats = SimplifyStats {
            target: vertices.len(),
            ..SimplifyStats::default()
        };
        Ok(BaseSubset {
            vertices,
            triangles,
            full_vertex_count,
            smoothing,
            stats,
        })
    }

    /// The subset: base vertex `k` is full vertex `vertices()[k]`, ascending.
    pub fn vertices(&self) -> &[u32] {
        &self.vertices
    }

    /// The base triangles, in base vertex indices (the rest mesh's orientation).
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    /// Number of base vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Vertex count of the full meshes this subset is taken from.
    pub fn full_vertex_count(&self) -> usize {
        self.full_vertex_count
    }

    /// How the simplification went (all zero but `target` for [`BaseSubset::from_parts`]).
    pub fn stats(&self) -> SimplifyStats {
        self.stats
    }

    /// The base positions of one example into `out` (cleared and resized): the subset of
    /// `full`, smoothed on the base topology (module docs). Allocates one scratch buffer of
    /// the base size, and `out` only if it is too small. Only the subset's positions are read
    /// and checked for finiteness.
    pub fn base_positions(
        &self,
        full: &[Vec3],
        smoothing: &Smoothing,
        out: &mut Vec<Vec3>,
    ) -> Result<(), SplitError> {
        if full.len() != self.full_vertex_count {
            return Err(SplitError::Length {
                expected: self.full_vertex_count,
                got: full.len(),
            });
        }
        if !(0.0..=1.0).contains(&smoothing.lambda) {
            return Err(SplitError::BadSmoothing {
                lambda: smoothing.lambda,
            });
        }
        out.clear();
        out.reserve(self.vertices.len());
        for (base_vertex, &v) in self.vertices.iter().enumerate() {
            let p = full[v as usize];
            if !p.is_finite() {
                return Err(SplitError::NonFinite {
                    vertex: v as usize,
                    base_vertex,
                    value: p,
                });
            }
            out.push(p);
        }
        if smoothing.iterations == 0 {
            return Ok(());
        }
        let mut scratch = vec![Vec3::ZERO; out.len()];
        for _ in 0..smoothing.iterations {
            umbrella_step(&self.smoothing, smoothing.lambda, out, &mut scratch);
            std::mem::swap(out, &mut scratch);
        }
        Ok(())
    }

    /// The base mesh of one example: [`BaseSubset::base_positions`] with the base triangles.
    pub fn base_mesh(&self, full: &[Vec3], smoothing: &Smoothing) -> Result<Mesh, SplitError> {
        let mut positions = Vec::new();
        self.base_positions(full, smoothing, &mut positions)?;
        Ok(Mesh {
            positions,
            triangles: self.triangles.clone(),
        })
    }
}

/// meshoptimizer over one mesh, counting runs; `stamp` marks used vertices without clearing.
struct Simplifier<'a> {
    indices: &'a [u32],
    positions: &'a [[f32; 3]],
    stamp: Vec<usize>,
    runs: usize,
}

impl Simplifier<'_> {
    fn run(&mut self, index_target: usize) -> Run {
        let mut error = 0.0f32;
        let indices = meshopt::simplify_decoder(
            self.indices,
            self.positions,
            index_target,
            TARGET_ERROR,
            SimplifyOptions::None,
            Some(&mut error),
        );
        self.runs += 1;
        let used = self.count_used(&indices);
        Run {
            index_target,
            indices,
            used,
            error,
        }
    }

    /// Distinct vertices in `indices`; the stamp of a call is its run number + 1, so the array
    /// never needs clearing.
    fn count_used(&mut self, indices: &[u32]) -> usize {
        let mark = self.runs + 1;
        let mut used = 0;
        for &i in indices {
            let s = &mut self.stamp[i as usize];
            if *s != mark {
                *s = mark;
                used += 1;
            }
        }
        used
    }
}

/// Checks `triangles` over `vertex_count` vertices with [`LoopSubdivision::new`] (which reads
/// no positions) and returns their smoothing neighbourhoods.
fn checked_topology(
    vertex_count: usize,
    triangles: &[[u32; 3]],
) -> Result<Adjacency, SubdivisionError> {
    let mesh = Mesh {
        positions: vec![Vec3::ZERO; vertex_count],
        triangles: triangles.to_vec(),
    };
    LoopSubdivision::new(&mesh, 1)?;
    Ok(smoothing_adjacency(&mesh))
}

/// Nearest multiple of 3 to `x`, at least 3.
fn round3(x: f64) -> usize {
    ((x / 3.0).round().max(1.0) as usize) * 3
}

/// A simplifier run made into a base: [`compact`]'s result.
struct Compacted {
    /// The used vertices, ascending.
    vertices: Vec<u32>,
    /// The kept triangles, renumbered.
    triangles: Vec<[u32; 3]>,
    /// Triangles dropped as degenerate or as cancelling duplicates.
    removed: usize,
}

/// The used vertices of `indices` ascending and its triangles renumbered, without degenerate
/// triangles (a repeated index) and without duplicates: triangles on the same three vertices
/// cancel in pairs of opposite orientation and repeat once at most otherwise. meshoptimizer
/// leaves such a pair where it has squeezed a sliver or a hole to nothing (on the horse, a
/// 3-edge hole at 3,000 vertices): a two-sided "pillow" of zero volume glued to the surface,
/// whose edges have four triangles. Removing both sides leaves the surface around it
/// manifold; a vertex only the pillow used drops out of the subset.
fn compact(indices: &[u32], vertex_count: usize) -> Compacted {
    let triangles: Vec<[u32; 3]> = indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .collect();
    // Each non-degenerate triangle as (sorted vertices, +1 / -1 orientation, position).
    let mut keyed: Vec<([u32; 3], i32, usize)> = triangles
        .iter()
        .enumerate()
        .filter(|(_, t)| t[0] != t[1] && t[1] != t[2] && t[2] != t[0])
        .map(|(k, &[a, b, c])| {
            let mut key = [a, b, c];
            key.sort_unstable();
            // An even permutation of the sorted order has the same orientation.
            let even = [[a, b, c], [b, c, a], [c, a, b]].contains(&key);
            (key, if even { 1 } else { -1 }, k)
        })
        .collect();
    keyed.sort_unstable();
    let mut keep = vec![false; triangles.len()];
    for group in keyed.chunk_by(|x, y| x.0 == y.0) {
        let net: i32 = group.iter().map(|g| g.1).sum();
        if let Some(first) = group.iter().find(|g| g.1 == net.signum()) {
            keep[first.2] = true;
        }
    }
    let kept: Vec<[u32; 3]> = triangles
        .iter()
        .zip(&keep)
        .filter(|(_, k)| **k)
        .map(|(t, _)| *t)
        .collect();
    let mut vertices: Vec<u32> = kept.iter().flatten().copied().collect();
    vertices.sort_unstable();
    vertices.dedup();
    let mut map = vec![u32::MAX; vertex_count];
    for (k, &v) in vertices.iter().enumerate() {
        // k < vertices.len() <= vertex_count, which came from u32 indices.
        map[v as usize] = k as u32;
    }
    Compacted {
        removed: triangles.len() - kept.len(),
        triangles: kept.iter().map(|t| t.map(|v| map[v as usize])).collect(),
        vertices,
    }
}

/// The smoothing neighbourhoods of `mesh` (module docs): a vertex with boundary edges (used by
/// one triangle) gets its boundary neighbours, any other its whole one-ring.
fn smoothing_adjacency(mesh: &Mesh) -> Adjacency {
    let all = mesh.vertex_adjacency();
    let mut edges: Vec<[u32; 2]> = mesh
        .triangles
        .iter()
        .flat_map(|&[a, b, c]| [[a, b], [b, c], [c, a]])
        .map(|[a, b]| [a.min(b), a.max(b)])
        .collect();
    edges.sort_unstable();
    let mut boundary = Vec::new();
    let mut i = 0;
    while i < edges.len() {
        let run = edges[i..].iter().take_while(|&&e| e == edges[i]).count();
        if run == 1 {
            boundary.push(edges[i]);
        }
        i += run;
    }
    let rim = Adjacency::from_edges(mesh.vertex_count(), &boundary);
    let mut offsets = Vec::with_capacity(mesh.vertex_count() + 1);
    let mut neighbors = Vec::with_capacity(all.neighbors.len());
    offsets.push(0u32);
    for v in 0..mesh.vertex_count() {
        let ring = if rim.degree(v) > 0 {
            rim.neighbors(v)
        } else {
            all.neighbors(v)
        };
        neighbors.extend_from_slice(ring);
        // At most the edge count times two, which fits u32 as the indices do.
        offsets.push(neighbors.len() as u32);
    }
    Adjacency { offsets, neighbors }
}

/// One simultaneous umbrella step, `dst = src + λ · mean(neighbours - self)`. The differences
/// (rather than the neighbours' mean minus `p`) keep a constant field exactly fixed and a
/// mesh in the plane z = 0 exactly in it.
fn umbrella_step(adjacency: &Adjacency, lambda: f32, src: &[Vec3], dst: &mut [Vec3]) {
    for (v, (d, &p)) in dst.iter_mut().zip(src).enumerate() {
        let ring = adjacency.neighbors(v);
        if ring.is_empty() {
            *d = p;
            continue;
        }
        let sum: Vec3 = ring.iter().map(|&u| src[u as usize] - p).sum();
        *d = p + sum * (lambda / ring.len() as f32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn compact_drops_degenerate_and_cancels_duplicates() {
        // 0..4 a quad [0,1,2] + [0,2,3]; a degenerate [1,1,2]; the same-orientation repeat
        // [2,0,1] of [0,1,2]; a pillow [0,2,5] + [5,2,0] (vertex 5 only there); vertices 4 and
        // 6 unused.
        let indices = [0, 1, 2, 0, 2, 3, 1, 1, 2, 2, 0, 1, 0, 2, 5, 5, 2, 0];
        let c = compact(&indices, 7);
        assert_eq!(c.vertices, vec![0, 1, 2, 3]);
        assert_eq!(c.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert_eq!(c.removed, 4);
    }

    #[test]
    fn compact_keeps_the_majority_orientation() {
        // Two copies one way, one the other: one triangle of the majority survives.
        let c = compact(&[3, 1, 2, 2, 1, 3, 1, 2, 3], 4);
        assert_eq!(c.vertices, vec![1, 2, 3]);
        assert_eq!(c.triangles, vec![[2, 0, 1]]);
    }

    #[test]
    fn round3_rounds_to_whole_triangles() {
        assert_eq!(round3(0.0), 3);
        assert_eq!(round3(4.4), 3);
        assert_eq!(round3(4.6), 6);
        assert_eq!(round3(11_998.0), 11_997);
    }
}

//! Displacement extraction for the base/detail split (HZY11 §4, DESIGN.md data flow step 2):
//! "At each vertex of the subdivided P̃_i, a per-vertex displacement with respect to P_i is
//! calculated along the vertex normals" — the maps `h_i` the detail regressor
//! ([`super::regress`], HZY11 §5.2) learns, and that synthesis adds back as
//! `v + h(c) n(v)` (HZY11 eq. 4).
//!
//! For one subdivided base vertex `v` with unit normal `n` and a detailed target surface `P`:
//!
//! ```text
//! t+ = first hit of the ray v + t n  on P, 0 <= t < max_distance
//! t- = first hit of the ray v - t n  on P, 0 <= t < max_distance
//! h  = +t+ or -t-, whichever is nearer (a tie goes outward)
//! h  = (closest_P(v) - v) . n            when neither ray hits (the fallback)
//! ```
//!
//! The signed ray distance is the displacement that reproduces `P` exactly along the normal;
//! the fallback keeps `h` finite where the normal misses the target (an open target, a hole,
//! or a target farther than `max_distance`), and [`ExtractStats::fallbacks`] counts it so a
//! caller can tell a good split from a poor one.
//!
//! The acceleration structure is `parry3d`'s [`TriMesh`]: its BVH is built once per target;
//! the closest-point fallback is parry's own query. The ray casts walk the same BVH
//! (`Bvh::find_best`, best-first) with this module's own box and triangle tests, because
//! parry's (0.31) are not watertight: a ray through a shared vertex can slip between the
//! triangles around it, and a ray with a zero direction component lying in a box's face
//! misses that box — both routine here (a target built as `v + h n` puts every hit on a
//! vertex; axis-aligned normals are common). Ours run in f64, accept barycentric coordinates
//! down to `BARYCENTRIC_SLACK` below zero and pad every box by `BOX_PAD` of the target's
//! size. parry works in its own `glam` version; points are converted at this module's
//! boundary and nothing of parry's appears in the public API.

use glam::{DVec3, Vec3};
use parry3d::math::Vector as ParryVec;
use parry3d::partitioning::BvhNode;
use parry3d::shape::{CompositeShapeRef, TriMesh};

/// Points handed to one rayon task: large enough that scheduling is noise next to about a
/// microsecond of BVH queries per point, small enough to balance a 150K-vertex mesh over
/// many cores.
const CHUNK: usize = 1024;

/// How far outside a triangle (in barycentric coordinates) a ray still counts as hitting it:
/// enough that a ray through a shared vertex or edge, after rounding, hits at least one of the
/// triangles around it; small enough that the hit point moves by a ten-millionth of an edge.
const BARYCENTRIC_SLACK: f64 = 1e-7;

/// Padding of the BVH boxes in the ray search, relative to the target's largest coordinate:
/// far above f32 rounding of the box corners, far below any feature, so a box is never missed
/// by a ray that touches its face or corner and the extra boxes visited are few.
const BOX_PAD: f64 = 1e-6;

/// Errors of displacement extraction. Each names the array and index (and, from
/// [`extract_all`], the example) at fault.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DetailError {
    /// The target mesh has no vertices or no usable (non-degenerate) triangles.
    #[error("target mesh has no {0}")]
    EmptyTarget(&'static str),
    /// A coordinate is NaN or infinite.
    #[error("{what} {index} is not finite")]
    NotFinite {
        /// Which array: "target vertex", "point" or "normal".
        what: &'static str,
        /// Index into that array.
        index: usize,
    },
    /// A target triangle refers to a vertex that does not exist.
    #[error("target triangle {triangle} uses vertex {vertex}, but the target has {count} vertices")]
    IndexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// The offending vertex index.
        vertex: u32,
        /// Number of target vertices.
        count: usize,
    },
    /// A normal has zero length, so it gives no direction to search along.
    #[error("normal {index} has zero length")]
    ZeroNormal {
        /// Index of the normal.
        index: usize,
    },
    /// Two arrays that must be parallel differ in length.
    #[error("{what}: expected {expected}, got {got}")]
    CountMismatch {
        /// Which array, relative to which.
        what: &'static str,
        /// The length it must have.
        expected: usize,
        /// The length it has.
        got: usize,
    },
    /// The maximum search distance is negative or NaN.
    #[error("max_distance must be >= 0 (infinity allowed), got {0}")]
    MaxDistance(f32),
    /// An error in one example of [`extract_all`].
    #[error("example {example}: {source}")]
    Example {
        /// Index of the example.
        example: usize,
        /// What is wrong with it.
        source: Box<DetailError>,
    },
}

/// How one displacement was found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DisplacementSource {
    /// A ray along `+n` or `-n` hit the target within the maximum distance.
    Ray,
    /// Neither ray hit; `h` is the closest target point's offset along the normal.
    Closest,
}

/// One vertex's displacement and how it was found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Displacement {
    /// Signed distance along the unit normal (positive outward, i.e. along `+n`).
    pub h: f32,
    /// Ray hit or closest-point fallback.
    pub source: DisplacementSource,
}

/// Summary of one [`DisplacementTarget::displacements`] call.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExtractStats {
    /// Vertices whose displacement came from a ray hit.
    pub hits: usize,
    /// Vertices that fell back to the closest target point (no hit within the maximum
    /// distance either way).
    pub fallbacks: usize,
    /// Largest `|h|` over all vertices (0 for none).
    pub max_abs: f32,
}

impl ExtractStats {
    /// The stats of `self` and `other` together (counts add, `max_abs` is the larger).
    pub fn merge(self, other: ExtractStats) -> ExtractStats {
        ExtractStats {
            hits: self.hits + other.hits,
            fallbacks: self.fallbacks + other.fallbacks,
            max_abs: self.max_abs.max(other.max_abs),
        }
    }

    fn add(&mut self, d: Displacement) {
        match d.source {
            DisplacementSource::Ray => self.hits += 1,
            DisplacementSource::Closest => self.fallbacks += 1,
        }
        self.max_abs = self.max_abs.max(d.h.abs());
    }
}

/// A detailed example surface `P_i` (HZY11 §4) with its bounding-volume hierarchy, built once
/// and queried for every subdivided base vertex.
#[derive(Clone)]
pub struct DisplacementTarget {
    mesh: TriMesh,
    dropped: usize,
    /// [`BOX_PAD`] times the largest absolute target coordinate.
    pad: f64,
}

impl std::fmt::Debug for DisplacementTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DisplacementTarget")
            .field("vertices", &self.mesh.vertices().len())
            .field("triangles", &self.mesh.indices().len())
            .field("dropped_degenerate", &self.dropped)
            .finish()
    }
}

impl DisplacementTarget {
    /// Builds the target from a triangle mesh of any topology (open, several components, not
    /// necessarily matching the base mesh). Zero-area triangles (repeated indices or collinear
    /// corners) are left out: they add no surface, and a closest-point query on them is
    /// ill-conditioned; [`DisplacementTarget::dropped_degenerate`] says how many.
    ///
    /// # Errors
    /// [`DetailError::EmptyTarget`] without vertices or non-degenerate triangles,
    /// [`DetailError::NotFinite`] naming the first non-finite vertex,
    /// [`DetailError::IndexOutOfRange`] naming the first triangle with a bad index.
    pub fn new(positions: &[Vec3], triangles: &[[u32; 3]]) -> Result<Self, DetailError> {
        if positions.is_empty() {
            return Err(DetailError::EmptyTarget("vertices"));
        }
        if let Some(index) = positions.iter().position(|p| !p.is_finite()) {
            return Err(DetailError::NotFinite {
                what: "target vertex",
                index,
            });
        }
        let count = positions.len();
        let mut kept = Vec::with_capacity(triangles.len());
        for (triangle, t) in triangles.iter().enumerate() {
            if let Some(&vertex) = t.iter().find(|&&k| k as usize >= count) {
                return Err(DetailError::IndexOutOfRange {
                    triangle,
                    vertex,
                    count,
                });
            }
            let [a, b, c] = t.map(|k| positions[k as usize]);
            if (b - a).cross(c - a).length_squared() > 0.0 {
                kept.push(*t);
            }
        }
        if kept.is_empty() {
            return Err(DetailError::EmptyTarget("non-degenerate triangles"));
        }
        let dropped = triangles.len() - kept.len();
        let scale = positions
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0f32, f32::max);
        let pad = BOX_PAD * f64::from(scale.max(f32::MIN_POSITIVE));
        let vertices = positions.iter().map(|&p| to_parry(p)).collect();
        // Cannot fail: parry only rejects an empty index buffer (checked above) and, with no
        // flags, builds no topology it could find inconsistent; map it anyway rather than
        // unwrap.
        let mesh = TriMesh::new(vertices, kept)
            .map_err(|_| DetailError::EmptyTarget("triangles parry accepts"))?;
        Ok(DisplacementTarget { mesh, dropped, pad })
    }

    /// Number of zero-area triangles [`DisplacementTarget::new`] left out.
    pub fn dropped_degenerate(&self) -> usize {
        self.dropped
    }

    /// The displacement of one point (module docs). `normal` need not be unit: it is
    /// normalised here, and `h` is measured along the unit normal.
    ///
    /// # Errors
    /// [`DetailError::NotFinite`] (index 0) for a non-finite point or normal,
    /// [`DetailError::ZeroNormal`] for a zero normal, [`DetailError::MaxDistance`] for a
    /// negative or NaN `max_distance`.
    pub fn displacement(
        &self,
        point: Vec3,
        normal: Vec3,
        max_distance: f32,
    ) -> Result<Displacement, DetailError> {
        check_max_distance(max_distance)?;
        let n = checked_normal(point, normal, 0)?;
        Ok(self.displacement_unchecked(point, n, max_distance))
    }

    /// The displacements of `points` along `normals` into `out` (module docs), in parallel
    /// under the `parallel` feature. Each output depends on its own point only and the stats
    /// are merged in index order, so the result is the same for any thread count.
    ///
    /// `max_distance` bounds both ray searches (use `f32::INFINITY` for none); rays that find
    /// nothing within it fall back to the closest target point, which is not bounded.
    ///
    /// # Errors
    /// [`DetailError::CountMismatch`] when `normals` or `out` differ in length from `points`,
    /// [`DetailError::NotFinite`] / [`DetailError::ZeroNormal`] naming the first bad point or
    /// normal, [`DetailError::MaxDistance`]. Nothing is written to `out` on error.
    pub fn displacements(
        &self,
        points: &[Vec3],
        normals: &[Vec3],
        max_distance: f32,
        out: &mut [f32],
    ) -> Result<ExtractStats, DetailError> {
        check_max_distance(max_distance)?;
        for (what, got) in [
            ("normals vs points", normals.len()),
            ("out vs points", out.len()),
        ] {
            if got != points.len() {
                return Err(DetailError::CountMismatch {
                    what,
                    expected: points.len(),
                    got,
                });
            }
        }
        for (i, (&p, &n)) in points.iter().zip(normals).enumerate() {
            checked_normal(p, n, i)?;
        }
        let partial = crate::par::map_chunks_mut(
            out,
            CHUNK,
            || (),
            |_, c, chunk| {
                let mut stats = ExtractStats::default();
                for (k, h) in chunk.iter_mut().enumerate() {
                    let i = c * CHUNK + k;
                    // Normalising cannot fail: `checked_normal` accepted every normal above.
                    let d = self.displacement_unchecked(
                        points[i],
                        normals[i].normalize(),
                        max_distance,
                    );
                    *h = d.h;
                    stats.add(d);
                }
                stats
            },
        );
        Ok(partial
            .into_iter()
            .fold(ExtractStats::default(), ExtractStats::merge))
    }

    /// [`DisplacementTarget::displacement`] for a finite point and unit normal.
    fn displacement_unchecked(&self, point: Vec3, n: Vec3, max_distance: f32) -> Displacement {
        let (o, d) = (point.as_dvec3(), n.as_dvec3());
        let out = self.cast_ray(o, d, max_distance);
        let inward = self.cast_ray(o, -d, max_distance);
        let h = match (out, inward) {
            (Some(a), Some(b)) => Some(if a <= b { a } else { -b }),
            (Some(a), None) => Some(a),
            (None, Some(b)) => Some(-b),
            (None, None) => None,
        };
        if let Some(h) = h {
            return Displacement {
                h,
                source: DisplacementSource::Ray,
            };
        }
        // The fallback. `project_local_point` answers `None` only for a non-finite query or an
        // empty mesh; both were ruled out (`new`, `checked_normal`), so `h = 0` is unreachable
        // and only keeps this panic-free.
        let h = CompositeShapeRef(&self.mesh)
            .project_local_point(to_parry(point), f32::MAX, false)
            .map_or(0.0, |(_, proj)| (from_parry(proj.point) - point).dot(n));
        Displacement {
            h,
            source: DisplacementSource::Closest,
        }
    }

    /// Distance to the first target triangle along the ray `o + t d`, `0 <= t < max_distance`
    /// (`d` unit), best-first over parry's BVH with the robust tests of the module docs.
    fn cast_ray(&self, o: DVec3, d: DVec3, max_distance: f32) -> Option<f32> {
        let vertices = self.mesh.vertices();
        let indices = self.mesh.indices();
        self.mesh
            .bvh()
            .find_best(
                max_distance,
                |node: &BvhNode, _| self.box_entry(node, o, d),
                |leaf, _| {
                    let [a, b, c] = indices[leaf as usize].map(|k| {
                        let v = vertices[k as usize];
                        DVec3::new(v.x.into(), v.y.into(), v.z.into())
                    });
                    ray_triangle(o, d, a, b, c).map(|t| t as f32)
                },
            )
            .map(|(_, t)| t)
    }

    /// Where the ray `o + t d` enters `node`'s box padded by `self.pad` (0 when it starts
    /// inside), or `f32::MAX` when it misses (the slab test, with a zero direction component
    /// handled exactly rather than through an infinite inverse).
    fn box_entry(&self, node: &BvhNode, o: DVec3, d: DVec3) -> f32 {
        let (mins, maxs) = (node.mins(), node.maxs());
        let (mut enter, mut exit) = (0.0f64, f64::INFINITY);
        for axis in 0..3 {
            let lo = f64::from(mins[axis]) - self.pad;
            let hi = f64::from(maxs[axis]) + self.pad;
            if d[axis] == 0.0 {
                if o[axis] < lo || o[axis] > hi {
                    return f32::MAX;
                }
                continue;
            }
            let (a, b) = ((lo - o[axis]) / d[axis], (hi - o[axis]) / d[axis]);
            enter = enter.max(a.min(b));
            exit = exit.min(a.max(b));
        }
        if enter <= exit {
            enter as f32
        } else {
            f32::MAX
        }
    }
}

/// Distance along the ray `o + t d` (`t >= 0`) to triangle `abc`, or `None`: Möller-Trumbore
/// in f64, with barycentric coordinates allowed [`BARYCENTRIC_SLACK`] below zero so that rays
/// through shared vertices and edges are not lost to rounding. A ray in the triangle's plane
/// is a miss (the triangles around it answer).
fn ray_triangle(o: DVec3, d: DVec3, a: DVec3, b: DVec3, c: DVec3) -> Option<f64> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = o - a;
    let u = s.dot(p) * inv;
    if !(-BARYCENTRIC_SLACK..=1.0 + BARYCENTRIC_SLACK).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < -BARYCENTRIC_SLACK || u + v > 1.0 + BARYCENTRIC_SLACK {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t >= 0.0).then_some(t)
}

/// One example for [`extract_all`]: the subdivided base mesh `S·B_i` (positions and normals)
/// and the detailed mesh `P_i` it is measured against.
#[derive(Clone, Copy, Debug)]
pub struct DetailExample<'a> {
    /// Subdivided base vertex positions.
    pub points: &'a [Vec3],
    /// Their normals (one per point; normalised internally).
    pub normals: &'a [Vec3],
    /// Detailed mesh vertex positions.
    pub target_positions: &'a [Vec3],
    /// Detailed mesh triangles (any topology).
    pub target_triangles: &'a [[u32; 3]],
}

/// The displacement map of one example and how it was found.
#[derive(Clone, Debug, PartialEq)]
pub struct Extracted {
    /// `h_i`, one value per subdivided base vertex.
    pub h: Vec<f32>,
    /// Hits, fallbacks, largest `|h|`.
    pub stats: ExtractStats,
}

/// Progress of [`extract_all`], reported after each example.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExtractProgress {
    /// Index of the example just finished.
    pub example: usize,
    /// Number of examples.
    pub total: usize,
    /// Its stats.
    pub stats: ExtractStats,
}

/// The displacement maps `h_i` of every example (HZY11 §4): builds each target's hierarchy,
/// extracts, and drops it before the next, so one detailed mesh's BVH is alive at a time.
///
/// # Errors
/// The first error of [`DisplacementTarget::new`] or [`DisplacementTarget::displacements`],
/// wrapped in [`DetailError::Example`] with the example's index.
pub fn extract_all(
    examples: &[DetailExample<'_>],
    max_distance: f32,
    mut progress: impl FnMut(ExtractProgress),
) -> Result<Vec<Extracted>, DetailError> {
    let total = examples.len();
    examples
        .iter()
        .enumerate()
        .map(|(example, ex)| {
            let wrap = |e| DetailError::Example {
                example,
                source: Box::new(e),
            };
            let target =
                DisplacementTarget::new(ex.target_positions, ex.target_triangles).map_err(wrap)?;
            let mut h = vec![0.0; ex.points.len()];
            let stats = target
                .displacements(ex.points, ex.normals, max_distance, &mut h)
                .map_err(wrap)?;
            progress(ExtractProgress {
                example,
                total,
                stats,
            });
            Ok(Extracted { h, stats })
        })
        .collect()
}

fn check_max_distance(max_distance: f32) -> Result<(), DetailError> {
    if max_distance >= 0.0 {
        Ok(())
    } else {
        Err(DetailError::MaxDistance(max_distance))
    }
}

/// `normal` normalised, after checking `point` and `normal` (index `index`) are usable.
fn checked_normal(point: Vec3, normal: Vec3, index: usize) -> Result<Vec3, DetailError> {
    if !point.is_finite() {
        return Err(DetailError::NotFinite {
            what: "point",
            index,
        });
    }
    if !normal.is_finite() {
        return Err(DetailError::NotFinite {
            what: "normal",
            index,
        });
    }
    normal
        .try_normalize()
        .ok_or(DetailError::ZeroNormal { index })
}

/// glam 0.34 (this workspace) to parry's glam.
fn to_parry(v: Vec3) -> ParryVec {
    ParryVec::new(v.x, v.y, v.z)
}

/// parry's glam to glam 0.34.
fn from_parry(v: ParryVec) -> Vec3 {
    Vec3::new(v.x, v.y, v.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit square in z = 0 (two triangles) plus a degenerate triangle.
    fn square() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
        ];
        (p, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4], [3, 3, 2]])
    }

    #[test]
    fn degenerate_triangles_are_dropped_and_counted() {
        let (p, t) = square();
        let target = DisplacementTarget::new(&p, &t).unwrap();
        assert_eq!(target.dropped_degenerate(), 2);
        let only_degenerate = DisplacementTarget::new(&p, &t[2..]).unwrap_err();
        assert_eq!(
            only_degenerate,
            DetailError::EmptyTarget("non-degenerate triangles")
        );
    }

    /// parry 0.31's own ray cast misses here: the inward ray `-n = (-0, +0, -1)` lies in the
    /// face y = 1 (the box's max) with a direction component of +0.0, which its slab test
    /// turns into +1/EPSILON, so the slab's exit is at t = 0, before the hit at 0.5.
    #[test]
    fn regression_ray_in_a_box_face_with_negative_zero_component() {
        let (p, t) = square();
        let target = DisplacementTarget::new(&p, &t[..2]).unwrap();
        let d = target
            .displacement(Vec3::new(0.5, 1.0, 0.5), Vec3::new(0.0, -0.0, 1.0), 1.0)
            .unwrap();
        assert_eq!(d.source, DisplacementSource::Ray);
        assert_eq!(d.h, -0.5);
    }

    #[test]
    fn a_tie_goes_outward() {
        // The square at z = 0 and a copy at z = 0.5; a point midway sees both at 0.25.
        let (mut p, mut t) = square();
        p.extend(p.clone().iter().map(|v| *v + Vec3::Z * 0.5));
        t.extend(t.clone().iter().map(|t| t.map(|k| k + 5)));
        let target = DisplacementTarget::new(&p, &t).unwrap();
        let mid = target
            .displacement(Vec3::new(0.3, 0.6, 0.25), Vec3::Z, 1.0)
            .unwrap();
        assert_eq!(mid.h, 0.25);
        let flipped = target
            .displacement(Vec3::new(0.3, 0.6, 0.25), -Vec3::Z, 1.0)
            .unwrap();
        assert_eq!(flipped.h, 0.25);
    }

    #[test]
    fn both_directions_and_the_closest_point_fallback() {
        let (p, t) = square();
        let target = DisplacementTarget::new(&p, &t).unwrap();
        let below = target
            .displacement(Vec3::new(0.3, 0.6, -0.25), Vec3::Z, 1.0)
            .unwrap();
        assert_eq!(below.source, DisplacementSource::Ray);
        assert!((below.h - 0.25).abs() < 1e-6, "{below:?}");
        let above = target
            .displacement(Vec3::new(0.3, 0.6, 0.25), Vec3::Z * 3.0, 1.0)
            .unwrap();
        assert!((above.h + 0.25).abs() < 1e-6, "{above:?}");
        // Past the square's edge: closest point is on the edge x = 1.
        let off = target
            .displacement(Vec3::new(1.5, 0.5, 0.5), Vec3::new(-1.0, 0.0, -1.0), 0.1)
            .unwrap();
        assert_eq!(off.source, DisplacementSource::Closest);
        let expected = (Vec3::new(1.0, 0.5, 0.0) - Vec3::new(1.5, 0.5, 0.5))
            .dot(Vec3::new(-1.0, 0.0, -1.0).normalize());
        assert!((off.h - expected).abs() < 1e-6, "{off:?} vs {expected}");
    }

    #[test]
    fn bad_input_is_named() {
        let (p, t) = square();
        let mut bad = p.clone();
        bad[3].y = f32::INFINITY;
        assert_eq!(
            DisplacementTarget::new(&bad, &t).unwrap_err(),
            DetailError::NotFinite {
                what: "target vertex",
                index: 3
            }
        );
        let err = DisplacementTarget::new(&p, &[[0, 1, 9]]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "target triangle 0 uses vertex 9, but the target has 5 vertices"
        );
        assert_eq!(
            DisplacementTarget::new(&[], &[]).unwrap_err(),
            DetailError::EmptyTarget("vertices")
        );
        let target = DisplacementTarget::new(&p, &t).unwrap();
        let mut out = [0.0; 2];
        let err = target
            .displacements(&[Vec3::ZERO; 2], &[Vec3::Z, Vec3::ZERO], 1.0, &mut out)
            .unwrap_err();
        assert_eq!(err, DetailError::ZeroNormal { index: 1 });
        let err = target
            .displacements(&[Vec3::ZERO; 2], &[Vec3::Z], 1.0, &mut out)
            .unwrap_err();
        assert_eq!(err.to_string(), "normals vs points: expected 2, got 1");
        assert_eq!(
            target.displacement(Vec3::ZERO, Vec3::Z, -1.0).unwrap_err(),
            DetailError::MaxDistance(-1.0)
        );
    }
}

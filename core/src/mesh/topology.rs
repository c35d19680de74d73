//! Vertex normals, unique edges and vertex adjacency.
//!
//! These assume indices are in range (readers guarantee it; check in-memory meshes with
//! [`Mesh::validate`]) and panic otherwise.

use glam::{Vec3, Vec3A};

use super::Mesh;

impl Mesh {
    /// Area-weighted vertex normals, normalised. See [`compute_vertex_normals`].
    ///
    /// # Panics
    /// If a triangle index is out of range.
    pub fn vertex_normals(&self) -> Vec<Vec3> {
        let mut normals = Vec::new();
        compute_vertex_normals(&self.positions, &self.triangles, &mut normals);
        normals
    }

    /// Unique undirected edges `[a, b]` with `a < b`, sorted (by `a`, then `b`). Self-loops of
    /// degenerate triangles (`[a, a, b]`) are left out.
    ///
    /// # Panics
    /// Never; indices are not looked up.
    pub fn edges(&self) -> Vec<[u32; 2]> {
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(self.triangles.len() * 3);
        for t in &self.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                if a != b {
                    edges.push([a.min(b), a.max(b)]);
                }
            }
        }
        edges.sort_unstable();
        edges.dedup();
        edges
    }

    /// Vertex adjacency through triangle edges: for each vertex its neighbours, sorted and
    /// unique. Isolated vertices have none.
    ///
    /// # Panics
    /// If a triangle index is out of range.
    pub fn vertex_adjacency(&self) -> Adjacency {
        Adjacency::from_edges(self.vertex_count(), &self.edges())
    }
}

/// Area-weighted vertex normals into `out` (cleared and resized to `positions.len()`), so a
/// per-frame caller reuses one buffer.
///
/// Each triangle adds its unnormalised face normal `(b - a) × (c - a)`, whose length is twice its
/// area, to its three corners; the sums are then normalised. A degenerate triangle (zero area,
/// or a repeated index) adds nothing. A vertex no triangle with area touches (isolated, or only
/// on degenerate triangles) gets `Vec3::ZERO`: a displacement along it is no displacement, which
/// is safer than an arbitrary direction.
///
/// # Panics
/// If a triangle index is out of range.
pub fn compute_vertex_normals(positions: &[Vec3], triangles: &[[u32; 3]], out: &mut Vec<Vec3>) {
    out.clear();
    out.resize(positions.len(), Vec3::ZERO);
    accumulate_face_normals(positions, triangles, out);
    for n in out.iter_mut() {
        *n = n.normalize_or_zero();
    }
}

/// The un-normalised half of [`compute_vertex_normals`]: `acc` (one entry per vertex) is
/// zeroed, then every triangle adds its cross product (twice its area times its unit normal)
/// to its three corners. Allocates nothing (the per-frame normal passes use it).
///
/// # Panics
/// If a triangle index is out of range of `positions` or `acc`.
pub fn accumulate_face_normals(positions: &[Vec3], triangles: &[[u32; 3]], acc: &mut [Vec3]) {
    acc.fill(Vec3::ZERO);
    for t in triangles {
        let [a, b, c] = t.map(|i| i as usize);
        let pa = Vec3A::from(positions[a]);
        let n = Vec3::from((Vec3A::from(positions[b]) - pa).cross(Vec3A::from(positions[c]) - pa));
        acc[a] += n;
        acc[b] += n;
        acc[c] += n;
    }
}

/// Vertex adjacency in compressed sparse row form: the neighbours of vertex `v` are
/// `neighbors[offsets[v]..offsets[v + 1]]`, sorted and unique.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Adjacency {
    /// `vertex_count + 1` offsets into [`Adjacency::neighbors`], non-decreasing, starting at 0.
    pub offsets: Vec<u32>,
    /// All neighbour lists, concatenated in vertex order.
    pub neighbors: Vec<u32>,
}

impl Adjacency {
    /// Builds the adjacency of `vertex_count` vertices from unique edges `[a, b]`, `a < b`,
    /// sorted (as [`Mesh::edges`] returns them).
    ///
    /// # Panics
    /// If an edge names a vertex `>= vertex_count`.
    pub fn from_edges(vertex_count: usize, edges: &[[u32; 2]]) -> Adjacency {
        let mut offsets = vec![0u32; vertex_count + 1];
        for &[a, b] in edges {
            offsets[a as usize + 1] += 1;
            offsets[b as usize + 1] += 1;
        }
        for v in 0..vertex_count {
            offsets[v + 1] += offsets[v];
        }
        let mut fill: Vec<u32> = offsets[..vertex_count].to_vec();
        let mut neighbors = vec![0u32; edges.len() * 2];
        // With edges sorted by (a, b), vertex v first receives every u < v (edges (u, v), in
        // increasing u) and then every w > v (edges (v, w), in increasing w): each list comes
        // out sorted without a sort.
        for &[a, b] in edges {
            neighbors[fill[a as usize] as usize] = b;
            fill[a as usize] += 1;
            neighbors[fill[b as usize] as usize] = a;
            fill[b as usize] += 1;
        }
        Adjacency { offsets, neighbors }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// The neighbours of `v`, sorted ascending.
    ///
    /// # Panics
    /// If `v >= vertex_count()`.
    pub fn neighbors(&self, v: usize) -> &[u32] {
        &self.neighbors[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }

    /// Number of neighbours of `v`.
    ///
    /// # Panics
    /// If `v >= vertex_count()`.
    pub fn degree(&self, v: usize) -> usize {
        (self.offsets[v + 1] - self.offsets[v]) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::test_meshes::{grid, tetrahedron};

    /// An n x n grid of quads in the z = 0 plane, with uneven spacing so the area weights
    /// differ, split into counter-clockwise (seen from +Z) triangles.
    fn uneven_grid(n: u32) -> Mesh {
        grid(n + 1, n + 1, |i, j| {
            Vec3::new((i as f32).powf(1.5), (j as f32).powf(1.3), 0.0)
        })
    }

    #[test]
    fn flat_grid_normals_are_plus_z() {
        for n in uneven_grid(4).vertex_normals() {
            assert!((n - Vec3::Z).length() < 1e-6, "{n}");
        }
    }

    #[test]
    fn tetrahedron_normals_point_away_from_the_centre() {
        // By symmetry each vertex normal of a regular tetrahedron centred at the origin is its
        // position direction: the three faces at a corner are rotations of each other about it.
        let m = tetrahedron();
        for (n, p) in m.vertex_normals().iter().zip(&m.positions) {
            assert!((*n - p.normalize()).length() < 1e-6, "{n} vs {p}");
        }
    }

    #[test]
    fn normals_are_area_weighted() {
        // Two triangles at vertex 0: a big one in the z = 0 plane (area 2) and a small one in the
        // x = 0 plane (area 0.5). Expected: normalize(2 * Z + 0.5 * X).
        let m = Mesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(0.0, 2.0, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [0, 4, 3]],
        };
        let n = m.vertex_normals()[0];
        let want = Vec3::new(0.5, 0.0, 2.0).normalize();
        assert!((n - want).length() < 1e-6, "{n} vs {want}");
    }

    #[test]
    fn degenerate_and_isolated_vertices_get_zero() {
        let m = Mesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::new(5.0, 5.0, 5.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(3.0, 0.0, 0.0),
            ],
            // Triangle 1 is collinear, triangle 2 repeats an index; vertex 3 is isolated.
            triangles: vec![[0, 1, 2], [1, 4, 5], [4, 4, 5]],
        };
        let n = m.vertex_normals();
        assert!((n[0] - Vec3::Z).length() < 1e-6);
        assert!(
            (n[1] - Vec3::Z).length() < 1e-6,
            "degenerate neighbour changed it"
        );
        assert_eq!(n[3], Vec3::ZERO);
        assert_eq!(n[4], Vec3::ZERO);
        assert_eq!(n[5], Vec3::ZERO);
        assert!(n.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn compute_into_reuses_and_resizes_the_buffer() {
        let m = tetrahedron();
        let mut out = vec![Vec3::splat(9.0); 10];
        compute_vertex_normals(&m.positions, &m.triangles, &mut out);
        assert_eq!(out, m.vertex_normals());
    }

    #[test]
    fn tetrahedron_has_six_edges_and_full_adjacency() {
        let m = tetrahedron();
        assert_eq!(
            m.edges(),
            vec![[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]
        );
        let adj = m.vertex_adjacency();
        assert_eq!(adj.vertex_count(), 4);
        assert_eq!(adj.neighbors(0), &[1, 2, 3]);
        assert_eq!(adj.neighbors(2), &[0, 1, 3]);
        assert_eq!(adj.degree(3), 3);
    }

    #[test]
    fn grid_edges_match_a_count_and_adjacency_is_symmetric_sorted_unique() {
        let n = 5;
        let m = uneven_grid(n);
        // Horizontal + vertical + one diagonal per quad.
        let expected = 2 * n * (n + 1) + n * n;
        assert_eq!(m.edges().len(), expected as usize);
        let adj = m.vertex_adjacency();
        for v in 0..adj.vertex_count() {
            let nb = adj.neighbors(v);
            assert!(nb.windows(2).all(|w| w[0] < w[1]), "vertex {v}: {nb:?}");
            for &w in nb {
                assert_ne!(w as usize, v);
                assert!(adj.neighbors(w as usize).contains(&(v as u32)));
            }
        }
        // An interior vertex of this triangulation has 6 neighbours, a corner 2 or 3.
        assert_eq!(adj.degree(((n + 1) * 2 + 2) as usize), 6);
        assert_eq!(adj.degree(0), 3);
        assert_eq!(adj.degree(n as usize), 2);
    }

    #[test]
    fn isolated_vertices_and_self_loops() {
        let m = Mesh {
            positions: vec![Vec3::ZERO; 5],
            triangles: vec![[0, 0, 1], [1, 2, 0]],
        };
        assert_eq!(m.edges(), vec![[0, 1], [0, 2], [1, 2]]);
        let adj = m.vertex_adjacency();
        assert_eq!(adj.offsets.len(), 6);
        assert_eq!(adj.neighbors(3), &[] as &[u32]);
        assert_eq!(adj.neighbors(4), &[] as &[u32]);
        assert_eq!(Mesh::default().vertex_adjacency().vertex_count(), 0);
    }
}

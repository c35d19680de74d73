//! Checks on subdivided meshes shared by core's subdivision tests and the hand's
//! (`hand/tests/subdivision_hand.rs` includes this folder by path): unique edges, the Euler
//! characteristic, closed oriented manifolds, f64 reference normals by a plain loop.

use std::collections::{BTreeSet, HashMap};

use crease_core::glam::{DVec3, Vec3};
use crease_core::mesh::Mesh;
use crease_core::mesh::subdivision::LoopSubdivision;
use crease_core::runtime::detail::NormalsMethod;

/// Unique undirected edges `(a, b)`, `a < b`, sorted.
pub(crate) fn sorted_edges(triangles: &[[u32; 3]]) -> Vec<(u32, u32)> {
    let mut set = BTreeSet::new();
    for t in triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            set.insert((a.min(b), a.max(b)));
        }
    }
    set.into_iter().collect()
}

pub(crate) fn subdivided(mesh: &Mesh, levels: u32) -> (LoopSubdivision, Vec<Vec3>) {
    let s = LoopSubdivision::new(mesh, levels).expect("manifold input");
    let p = s.mesh(&mesh.positions).expect("sizes match").positions;
    (s, p)
}

pub(crate) fn assert_close(got: Vec3, want: DVec3, tol: f64, what: &str) {
    let d = (got.as_dvec3() - want).length();
    assert!(d < tol, "{what}: got {got}, expected {want} (|d| = {d:e})");
}

/// Every directed edge exactly once and its reverse exactly once: closed, edge-manifold and
/// consistently oriented.
pub(crate) fn assert_closed_oriented_manifold(triangles: &[[u32; 3]]) {
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new();
    for t in triangles {
        assert!(t[0] != t[1] && t[1] != t[2] && t[2] != t[0], "{t:?}");
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &c) in &directed {
        assert_eq!(c, 1, "directed edge ({a}, {b}) used {c} times");
        assert_eq!(
            directed.get(&(b, a)),
            Some(&1),
            "edge ({a}, {b}) has no twin"
        );
    }
}

pub(crate) fn euler(vertices: usize, triangles: &[[u32; 3]]) -> i64 {
    vertices as i64 - sorted_edges(triangles).len() as i64 + triangles.len() as i64
}

/// Area-weighted unit normals in f64, by a plain loop over the triangles.
pub(crate) fn reference_normals(p: &[Vec3], triangles: &[[u32; 3]]) -> Vec<DVec3> {
    let mut n = vec![DVec3::ZERO; p.len()];
    for t in triangles {
        let [a, b, c] = t.map(|i| p[i as usize].as_dvec3());
        let fnorm = (b - a).cross(c - a);
        for &i in t {
            n[i as usize] += fnorm;
        }
    }
    n.into_iter().map(|x| x.normalize_or_zero()).collect()
}

pub(crate) const METHODS: [NormalsMethod; 3] = [
    NormalsMethod::Auto,
    NormalsMethod::Scatter,
    NormalsMethod::Gather,
];

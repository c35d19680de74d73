//! Geodesic distances on the mesh edge graph, and bone centre vertices (HZY11 §5.1.1).
//!
//! HZY11 §5.1.1 gives each bone the `k_c` control points nearest to it "measured by the geodesic
//! distance" from the bone's centre vertex: the mesh vertex nearest to the centre of the vertices
//! the bone controls. Geodesics here are shortest paths along mesh edges (Dijkstra, each edge
//! weighted by its rest-pose length): an upper bound on the true surface geodesic, within a few
//! percent on a reasonable triangulation, and what ranking control points needs (distances
//! through the body, like Euclidean ones, would couple a finger to its neighbour).

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_core::runtime::skin::SkinWeights;

use crate::par;

/// Edge-graph geodesic distance from each source vertex to every vertex (HZY11 §5.1.1):
/// `result[s][v]`, `f32::INFINITY` where `v` is not connected to `sources[s]`. One Dijkstra run
/// per source over edges weighted by rest-pose length, in parallel over sources.
///
/// # Panics
/// If a source or a triangle index is out of range.
pub fn distances_from(mesh: &Mesh, sources: &[u32]) -> Vec<Vec<f32>> {
    let nv = mesh.vertex_count();
    for &s in sources {
        assert!(
            (s as usize) < nv,
            "source vertex {s} out of range ({nv} vertices)"
        );
    }
    let adjacency = mesh.vertex_adjacency();
    // Edge lengths per adjacency slot, in f64 so long paths accumulate no visible rounding.
    let mut lengths = Vec::with_capacity(adjacency.neighbors.len());
    for v in 0..nv {
        let p = mesh.positions[v];
        for &u in adjacency.neighbors(v) {
            lengths.push(p.as_dvec3().distance(mesh.positions[u as usize].as_dvec3()));
        }
    }
    par::map_range(
        sources.len(),
        || (BinaryHeap::new(), Vec::new()),
        |(heap, dist): &mut (BinaryHeap<Reverse<HeapEntry>>, Vec<f64>), s| {
            dijkstra(&adjacency, &lengths, sources[s], heap, dist);
            dist.iter().map(|&d| d as f32).collect()
        },
    )
}

/// Indices of the `k` sources nearest to `vertex` by `dist[s][vertex]` (as returned by
/// [`distances_from`]), nearest first, ties by source index, unreachable sources last (HZY11
/// §5.1.1: a bone's `k_c` influence control points). Returns all sources when `k` exceeds them.
///
/// # Panics
/// If `vertex` is out of range of a distance array.
pub fn nearest_sources(dist: &[Vec<f32>], vertex: u32, k: usize) -> Vec<usize> {
    let mut order: Vec<usize> = (0..dist.len()).collect();
    // total_cmp puts +inf after every finite distance.
    order.sort_by(|&a, &b| {
        dist[a][vertex as usize]
            .total_cmp(&dist[b][vertex as usize])
            .then(a.cmp(&b))
    });
    order.truncate(k);
    order
}

/// The centre vertex of one bone (HZY11 §5.1.1): the mesh vertex nearest (Euclidean, ties by
/// index) to the skin-weighted centre `sum_v w_vb p_v / sum_v w_vb` of the vertices the bone
/// influences. `None` when no vertex has a positive weight for it. For many bones prefer
/// [`bone_centre_vertices`], which makes one pass over the weights.
///
/// # Panics
/// If `skin` has more vertices than `rest`.
pub fn bone_centre_vertex(rest: &Mesh, skin: &SkinWeights, bone: u32) -> Option<u32> {
    let (mut sum, mut weight) = (Vec3::ZERO.as_dvec3(), 0.0f64);
    for v in 0..skin.vertex_count() {
        let (bones, weights) = skin.vertex(v);
        for (&b, &w) in bones.iter().zip(weights) {
            if b == bone && w > 0.0 {
                sum += rest.positions[v].as_dvec3() * f64::from(w);
                weight += f64::from(w);
            }
        }
    }
    (weight > 0.0).then(|| nearest_vertex(&rest.positions, (sum / weight).as_vec3()))
}

/// [`bone_centre_vertex`] for bones `0..bone_count` in one pass over the weights (HZY11
/// §5.1.1). Bones at or beyond `bone_count` in `skin` are ignored.
///
/// # Panics
/// If `skin` has more vertices than `rest`.
pub fn bone_centre_vertices(
    rest: &Mesh,
    skin: &SkinWeights,
    bone_count: usize,
) -> Vec<Option<u32>> {
    let mut sums = vec![(Vec3::ZERO.as_dvec3(), 0.0f64); bone_count];
    for v in 0..skin.vertex_count() {
        let (bones, weights) = skin.vertex(v);
        let p = rest.positions[v].as_dvec3();
        for (&b, &w) in bones.iter().zip(weights) {
            if let Some(s) = sums.get_mut(b as usize).filter(|_| w > 0.0) {
                s.0 += p * f64::from(w);
                s.1 += f64::from(w);
            }
        }
    }
    par::map_range(
        bone_count,
        || (),
        |_, b| {
            let (sum, weight) = sums[b];
            (weight > 0.0).then(|| nearest_vertex(&rest.positions, (sum / weight).as_vec3()))
        },
    )
}

/// Index of the position nearest to `target` (first on ties). `positions` must be non-empty.
fn nearest_vertex(positions: &[Vec3], target: Vec3) -> u32 {
    let mut best = (f32::INFINITY, 0usize);
    for (i, p) in positions.iter().enumerate() {
        let d = p.distance_squared(target);
        if d < best.0 {
            best = (d, i);
        }
    }
    best.1 as u32
}

/// A heap entry ordered by distance (then vertex, for a total order).
#[derive(Clone, Copy, Debug, PartialEq)]
struct HeapEntry {
    dist: f64,
    vertex: u32,
}

impl Eq for HeapEntry {}

impl PartialOrd for HeapEntry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for HeapEntry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.dist
            .total_cmp(&other.dist)
            .then(self.vertex.cmp(&other.vertex))
    }
}

/// Dijkstra from `source` into `dist` (resized, `INFINITY` where unreachable), reusing `heap`.
fn dijkstra(
    adjacency: &crease_core::mesh::Adjacency,
    lengths: &[f64],
    source: u32,
    heap: &mut BinaryHeap<Reverse<HeapEntry>>,
    dist: &mut Vec<f64>,
) {
    dist.clear();
    dist.resize(adjacency.vertex_count(), f64::INFINITY);
    heap.clear();
    dist[source as usize] = 0.0;
    heap.push(Reverse(HeapEntry {
        dist: 0.0,
        vertex: source,
    }));
    while let Some(Reverse(HeapEntry { dist: d, vertex })) = heap.pop() {
        let v = vertex as usize;
        if d > dist[v] {
            continue; // stale entry
        }
        let start = adjacency.offsets[v] as usize;
        for (&u, &len) in adjacency.neighbors(v).iter().zip(&lengths[start..]) {
            let nd = d + len;
            if nd < dist[u as usize] {
                dist[u as usize] = nd;
                heap.push(Reverse(HeapEntry {
                    dist: nd,
                    vertex: u,
                }));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_sources_orders_by_distance_then_index_with_unreachable_last() {
        let dist = vec![
            vec![f32::INFINITY, 0.0],
            vec![2.0, 0.0],
            vec![1.0, 0.0],
            vec![2.0, 0.0],
        ];
        assert_eq!(nearest_sources(&dist, 0, 3), vec![2, 1, 3]);
        assert_eq!(nearest_sources(&dist, 0, 10), vec![2, 1, 3, 0]);
        assert_eq!(nearest_sources(&dist, 1, 2), vec![0, 1]);
        assert!(nearest_sources(&dist, 0, 0).is_empty());
    }

    #[test]
    fn bone_centres_weighted_and_missing() {
        // Four vertices on a line; bone 0 owns 0 and 1 equally, bone 1 weighs 3 at v3, 1 at v2.
        let rest = Mesh {
            positions: (0..4).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect(),
            triangles: vec![],
        };
        let skin = SkinWeights::new(
            2,
            vec![0, 1, 0, 1, 1, 0, 1, 0],
            vec![1.0, 0.0, 1.0, 0.0, 0.25, 0.75, 1.0, 0.0],
        )
        .unwrap();
        // Bone 0: v0 (1), v1 (1), v2 (0.75): centre (0 + 1 + 1.5) / 2.75 = 0.909 -> v1.
        // Bone 1: v2 (0.25), v3 (1): centre (0.5 + 3) / 1.25 = 2.8 -> v3. Bone 2: nothing.
        let all = bone_centre_vertices(&rest, &skin, 3);
        assert_eq!(all, vec![Some(1), Some(3), None]);
        for b in 0..3 {
            assert_eq!(bone_centre_vertex(&rest, &skin, b), all[b as usize]);
        }
    }
}

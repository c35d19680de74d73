//! Edge-graph geodesics (HZY11 §5.1.1) against independent computations: Floyd–Warshall on a
//! random mesh, the Euclidean length of a straight path, and a disconnected piece.

use crease_core::glam::Vec3;
use crease_core::mesh::Mesh;
use crease_train::geodesic::{distances_from, nearest_sources};
use rand::{Rng, SeedableRng, rngs::StdRng};

/// A `w x h` grid with jittered positions and random heights, some triangles left out so the
/// graph is irregular (and may have holes).
fn random_mesh(rng: &mut StdRng, w: usize, h: usize) -> Mesh {
    let positions = (0..w * h)
        .map(|i| {
            Vec3::new(
                (i % w) as f32 + rng.random_range(-0.3..0.3),
                (i / w) as f32 + rng.random_range(-0.3..0.3),
                rng.random_range(-0.5..0.5),
            )
        })
        .collect();
    let mut triangles = Vec::new();
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let i = (y * w + x) as u32;
            let (r, d, rd) = (i + 1, i + w as u32, i + w as u32 + 1);
            for t in [[i, r, rd], [i, rd, d]] {
                if rng.random_bool(0.8) {
                    triangles.push(t);
                }
            }
        }
    }
    Mesh {
        positions,
        triangles,
    }
}

/// All-pairs shortest paths by Floyd–Warshall over the triangles' edges, in f64.
fn floyd_warshall(mesh: &Mesh) -> Vec<Vec<f64>> {
    let n = mesh.vertex_count();
    let mut d = vec![vec![f64::INFINITY; n]; n];
    for (i, row) in d.iter_mut().enumerate() {
        row[i] = 0.0;
    }
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k] as usize, t[(k + 1) % 3] as usize);
            let len = mesh.positions[a]
                .as_dvec3()
                .distance(mesh.positions[b].as_dvec3());
            d[a][b] = d[a][b].min(len);
            d[b][a] = d[b][a].min(len);
        }
    }
    for k in 0..n {
        for i in 0..n {
            for j in 0..n {
                let via = d[i][k] + d[k][j];
                if via < d[i][j] {
                    d[i][j] = via;
                }
            }
        }
    }
    d
}

#[test]
fn dijkstra_equals_floyd_warshall_on_a_random_mesh() {
    let mut rng = StdRng::seed_from_u64(23);
    for _ in 0..3 {
        let mesh = random_mesh(&mut rng, 7, 6);
        let all: Vec<u32> = (0..mesh.vertex_count() as u32).collect();
        let got = distances_from(&mesh, &all);
        let want = floyd_warshall(&mesh);
        let mut unreachable = 0;
        for (s, row) in got.iter().enumerate() {
            for (v, &g) in row.iter().enumerate() {
                let w = want[s][v];
                if w.is_infinite() {
                    assert_eq!(g, f32::INFINITY, "{s} -> {v}");
                    unreachable += 1;
                } else {
                    assert!(
                        (f64::from(g) - w).abs() <= 1e-5 * (1.0 + w),
                        "{s} -> {v}: {g} vs {w}"
                    );
                }
            }
        }
        println!(
            "checked {} pairs, {unreachable} unreachable",
            got.len() * got.len()
        );
    }
}

#[test]
fn straight_path_on_a_flat_strip_is_euclidean() {
    // Two rows of 20 vertices, spacing 0.37 along x, 1 apart in y.
    let n = 20;
    let positions = (0..2 * n)
        .map(|i| Vec3::new((i % n) as f32 * 0.37, (i / n) as f32, 0.0))
        .collect();
    let triangles = (0..n as u32 - 1)
        .flat_map(|i| {
            [
                [i, i + 1, i + n as u32 + 1],
                [i, i + n as u32 + 1, i + n as u32],
            ]
        })
        .collect();
    let mesh = Mesh {
        positions,
        triangles,
    };
    let d = distances_from(&mesh, &[0, n as u32 - 1]);
    for (v, &p) in mesh.positions.iter().enumerate().take(n) {
        assert!(
            (d[0][v] - p.distance(mesh.positions[0])).abs() < 1e-5,
            "{v}"
        );
        assert!(
            (d[1][v] - p.distance(mesh.positions[n - 1])).abs() < 1e-5,
            "{v}"
        );
    }
    // Across the strip from vertex 0 to the far top corner: along the bottom row, then one
    // diagonal (the only diagonals run from (i, 0) to (i + 1, 1)).
    let far = 2 * n - 1;
    let expect = (n - 2) as f32 * 0.37 + (0.37f32 * 0.37 + 1.0).sqrt();
    assert!(
        (d[0][far] - expect).abs() < 1e-5,
        "{} vs {expect}",
        d[0][far]
    );
}

#[test]
fn disconnected_component_is_infinitely_far_and_ranked_last() {
    // Two separate triangles and one isolated vertex.
    let mesh = Mesh {
        positions: vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(0.1, 0.0, 0.0) + Vec3::Z,
            Vec3::new(1.0, 0.0, 1.0),
            Vec3::new(0.0, 1.0, 1.0),
            Vec3::splat(5.0),
        ],
        triangles: vec![[0, 1, 2], [3, 4, 5]],
    };
    let d = distances_from(&mesh, &[3, 0, 6]);
    assert_eq!(d[1][..3], [0.0, 1.0, 1.0]);
    assert!(d[1][3..].iter().all(|x| x.is_infinite()));
    assert!(d[2][..6].iter().all(|x| x.is_infinite()) && d[2][6] == 0.0);
    // From vertex 0 the source at vertex 0 is nearest; 3 and 6 are unreachable, by index.
    assert_eq!(nearest_sources(&d, 0, 3), vec![1, 0, 2]);
    // Vertex 3 is physically near vertex 0 (0.1 + 1 away in space) but ranks it unreachable.
    assert_eq!(nearest_sources(&d, 3, 2), vec![0, 1]);
    assert!(distances_from(&mesh, &[]).is_empty());
}

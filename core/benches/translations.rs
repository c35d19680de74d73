//! The Poisson translation solver (FKY08 §5, eq. 11) at horse size: 8,431 vertices, ~25k edges,
//! 150 bones and 8 control points as in FKY08 Table 1.
//!
//! The rig is synthetic: 150 bone centres at random mesh vertices (seeded), each vertex bound to
//! its 4 nearest centres with inverse-distance weights, each edge to the average of its
//! endpoints' weights (up to 8 bones), 8 random control vertices, `beta = 1`. The mesh is
//! `horse/reference.obj` from the shared data, else `horse/gallop/0001.obj` (same topology),
//! else a 92 x 92 grid (the bench says which).
//!
//! Timed: `solve` per frame (random rotations and controls; the number to compare with the
//! skinning bench), the one-off construction (assembly + symbolic + numeric factorisation) and
//! `set_beta` (numeric refactorisation only). The solver itself is sequential (faer `Par::Seq`).
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p crease-core --bench translations -- --quick`. After
//! criterion's groups it prints a summary line with medians of its own timing loop.

mod common;
use common::timings;
use std::hint::black_box;
use std::time::Duration;

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::runtime::edge_skin::EdgeSkin;
use crease_core::runtime::skin::SkinWeights;
use crease_core::runtime::translations::TranslationSolver;
use criterion::Criterion;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Proxy bones on the horse in FKY08 Table 1.
const BONES: usize = 150;
/// Control points on the horse in FKY08 Table 1.
const CONTROLS: usize = 8;
/// Vertex influences (a GPU vec4).
const K: usize = 4;
/// Frames timed for the summary figure.
const FRAMES: usize = 500;
/// Grid side of the fallback mesh: 92^2 = 8,464 vertices, about the horse's 8,431.
const GRID: usize = 92;

/// The horse, or a grid of about its size when the data is absent.
fn mesh() -> (Mesh, String) {
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../../shared/data/horse");
    for name in ["reference.obj", "gallop/0001.obj"] {
        if let Ok(m) = Mesh::read(format!("{data}/{name}")) {
            return (m, format!("horse/{name}"));
        }
    }
    let mut positions = Vec::new();
    for y in 0..GRID {
        for x in 0..GRID {
            let (u, v) = (x as f32 / GRID as f32, y as f32 / GRID as f32);
            positions.push(Vec3::new(u, v, 0.1 * (6.0 * u).sin() * (4.0 * v).cos()));
        }
    }
    let mut triangles = Vec::new();
    for y in 0..GRID - 1 {
        for x in 0..GRID - 1 {
            let i = (y * GRID + x) as u32;
            let g = GRID as u32;
            triangles.push([i, i + 1, i + g + 1]);
            triangles.push([i, i + g + 1, i + g]);
        }
    }
    (
        Mesh {
            positions,
            triangles,
        },
        format!("a {GRID}x{GRID} grid (horse data not found under {data})"),
    )
}

/// Vertex weights (K nearest of `BONES` centres, inverse distance), edge weights (endpoint
/// average, stride 2K) and control vertices.
fn rig(mesh: &Mesh, edges: &[[u32; 2]]) -> (SkinWeights, EdgeSkin, Vec<u32>) {
    let mut rng = StdRng::seed_from_u64(7);
    let n = mesh.vertex_count();
    let centres: Vec<Vec3> = (0..BONES)
        .map(|_| mesh.positions[rng.random_range(0..n)])
        .collect();
    let scale = mesh.bbox_diagonal_scale().max(1e-6);
    let mut indices = Vec::with_capacity(n * K);
    let mut weights = Vec::with_capacity(n * K);
    let mut d: Vec<(f32, u32)> = Vec::with_capacity(BONES);
    for &p in &mesh.positions {
        d.clear();
        d.extend(
            centres
                .iter()
                .enumerate()
                .map(|(b, &c)| (p.distance(c), b as u32)),
        );
        d.select_nth_unstable_by(K - 1, |a, b| a.0.total_cmp(&b.0));
        let w: Vec<f32> = d[..K].iter().map(|x| 1.0 / (x.0 + 1e-3 * scale)).collect();
        let s: f32 = w.iter().sum();
        indices.extend(d[..K].iter().map(|x| x.1));
        weights.extend(w.iter().map(|x| x / s));
    }
    let skin = SkinWeights::new(K, indices, weights).expect("normalised weights");
    let mut ei = Vec::with_capacity(edges.len() * 2 * K);
    let mut ew = Vec::with_capacity(edges.len() * 2 * K);
    for &[a, b] in edges {
        for v in [a, b] {
            let (idx, w) = skin.vertex(v as usize);
            ei.extend_from_slice(idx);
            ew.extend(w.iter().map(|x| 0.5 * x));
        }
    }
    let edge_skin = SkinWeights::new(2 * K, ei, ew).expect("averaged weights");
    let edge_skin =
        EdgeSkin::from_weights(&mesh.positions, edges, &edge_skin).expect("valid edge skin");
    let controls = (0..CONTROLS)
        .map(|_| rng.random_range(0..n as u32))
        .collect();
    (skin, edge_skin, controls)
}

fn random_rotation(rng: &mut StdRng) -> Quat {
    let axis = Vec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    Quat::from_axis_angle(axis.normalize_or(Vec3::Z), rng.random_range(-1.0..1.0))
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    let (mesh, source) = mesh();
    let edges = mesh.edges();
    let (skin, edge_skin, controls) = rig(&mesh, &edges);
    let build = || {
        TranslationSolver::new(
            &mesh.positions,
            &edges,
            &skin,
            &edge_skin,
            &controls,
            BONES,
            1.0,
        )
        .expect("consistent synthetic rig")
    };
    let mut solver = build();
    println!(
        "translations bench: {} vertices, {} edges from {source}; {BONES} bones, {CONTROLS} \
         controls; K has {} entries, the Cholesky factor {}",
        mesh.vertex_count(),
        edges.len(),
        solver.rotation_operator_len(),
        solver.factor_len(),
    );

    let mut rng = StdRng::seed_from_u64(11);
    let rotations: Vec<Quat> = (0..BONES).map(|_| random_rotation(&mut rng)).collect();
    let targets: Vec<Vec3> = controls
        .iter()
        .map(|&i| mesh.positions[i as usize] + Vec3::new(0.01, -0.02, 0.03))
        .collect();
    let mut scratch = solver.scratch();
    let mut out = vec![Vec3::ZERO; BONES];

    let mut g = c.benchmark_group("translations");
    g.bench_function("solve", |b| {
        b.iter(|| {
            solver
                .solve(
                    black_box(&rotations),
                    black_box(&targets),
                    &mut scratch,
                    &mut out,
                )
                .expect("finite inputs");
            black_box(&out);
        })
    });
    g.sample_size(10);
    g.bench_function("new (assemble + factor)", |b| b.iter(|| black_box(build())));
    g.bench_function("set_beta (refactor)", |b| {
        let mut beta = 1.0;
        b.iter(|| {
            beta = if beta == 1.0 { 2.0 } else { 1.0 };
            solver.set_beta(beta).expect("positive beta");
        })
    });
    g.finish();

    solver.set_beta(1.0).expect("positive beta");
    let solve = timings(FRAMES, || {
        solver
            .solve(
                black_box(&rotations),
                black_box(&targets),
                &mut scratch,
                &mut out,
            )
            .expect("finite inputs");
        black_box(&out);
    });
    let new = timings(10, || {
        black_box(build());
    });
    let mut beta = 1.0;
    let refactor = timings(50, || {
        beta = if beta == 1.0 { 2.0 } else { 1.0 };
        solver.set_beta(beta).expect("positive beta");
    });
    let us = |d: Duration| d.as_secs_f64() * 1e6;
    println!(
        "summary: solve {:.1} µs/frame (min {:.1}); new {:.2} ms (min {:.2}); set_beta {:.1} µs \
         (min {:.1})",
        us(solve.0),
        us(solve.1),
        us(new.0) / 1e3,
        us(new.1) / 1e3,
        us(refactor.0),
        us(refactor.1),
    );
}

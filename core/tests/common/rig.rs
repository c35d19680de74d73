//! A small rig for the solver tests (translations_solver.rs, refine.rs): a tube, random
//! skins and edge skins, random rotations and points, and dense weight rows.
#![allow(clippy::unwrap_used)] // test code: a failed unwrap is a failed check, with its line

use crease_core::glam::{Quat, Vec3};
use crease_core::mesh::Mesh;
use crease_core::mesh::test_meshes::tube;
use crease_core::runtime::edge_skin::EdgeSkin;
use crease_core::runtime::skin::SkinWeights;
use crease_core::runtime::translations::TranslationSolver;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// `n` rows of `k` random bones below `bones` (repeats allowed) with random weights, about one
/// slot in five at zero weight.
pub(crate) fn random_skin(rng: &mut StdRng, n: usize, k: usize, bones: u32) -> SkinWeights {
    let mut indices = Vec::with_capacity(n * k);
    let mut weights = Vec::with_capacity(n * k);
    for _ in 0..n {
        let mut w: Vec<f32> = (0..k)
            .map(|_| {
                if rng.random_range(0..5) == 0 {
                    0.0
                } else {
                    rng.random::<f32>() + 0.05
                }
            })
            .collect();
        if w.iter().all(|&x| x == 0.0) {
            w[0] = 1.0;
        }
        let s: f32 = w.iter().sum();
        weights.extend(w.iter().map(|x| x / s));
        indices.extend((0..k).map(|_| rng.random_range(0..bones)));
    }
    SkinWeights::new(k, indices, weights).unwrap()
}

pub(crate) fn random_rotation(rng: &mut StdRng) -> Quat {
    let axis = Vec3::new(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    Quat::from_axis_angle(
        axis.normalize_or(Vec3::X),
        rng.random_range(-std::f32::consts::PI..std::f32::consts::PI),
    )
}

pub(crate) fn random_point(rng: &mut StdRng, scale: f32) -> Vec3 {
    Vec3::new(
        rng.random_range(-scale..scale),
        rng.random_range(-scale..scale),
        rng.random_range(-scale..scale),
    )
}

/// A vertex's (or edge's) influences as a dense f64 weight vector over `bones`, summing to one
/// in f64 (f32 weights sum to one only within ~1e-7, which would leave the global translation
/// of the `beta = 0` system a tiny non-zero singular value instead of an exact null direction).
pub(crate) fn dense_weights(skin: &SkinWeights, row: usize, bones: usize) -> Vec<f64> {
    let mut w = vec![0.0; bones];
    let (idx, ws) = skin.vertex(row);
    for (&b, &x) in idx.iter().zip(ws) {
        w[b as usize] += x as f64;
    }
    let sum: f64 = w.iter().sum();
    w.iter_mut().for_each(|x| *x /= sum);
    w
}

/// Everything eq. 11 needs.
#[derive(Clone)]
pub(crate) struct Problem {
    pub(crate) mesh: Mesh,
    pub(crate) edges: Vec<[u32; 2]>,
    pub(crate) skin: SkinWeights,
    pub(crate) edge_skin: EdgeSkin,
    pub(crate) controls: Vec<u32>,
    pub(crate) bones: usize,
}

/// The tube with `used` bones carrying weight out of `bones`.
pub(crate) fn problem(seed: u64, bones: usize, used: u32) -> Problem {
    let mut rng = StdRng::seed_from_u64(seed);
    // A closed-ring tube of 10 x 10 vertices, radius 1, length 2, centred on the origin.
    let mut mesh = tube(10, 10, 2.0);
    for p in &mut mesh.positions {
        p.z -= 1.0;
    }
    let edges = mesh.edges();
    let skin = random_skin(&mut rng, mesh.vertex_count(), 3, used);
    // Scalar eq. 10 weights as vectors, then a random vector moved from slot 1 to slot 0 of
    // each edge: a general vector skin whose vectors still sum to the rest edge (so a motion
    // shared by all bones leaves every residual zero, see the rigid test).
    let scalar = random_skin(&mut rng, edges.len(), 2, used);
    let base = EdgeSkin::from_weights(&mesh.positions, &edges, &scalar).unwrap();
    let mut vectors = base.vectors().to_vec();
    for pair in vectors.chunks_exact_mut(2) {
        let d = random_point(&mut rng, 0.3);
        pair[0] += d;
        pair[1] -= d;
    }
    let edge_skin = EdgeSkin::new(2, base.indices().to_vec(), vectors).unwrap();
    Problem {
        mesh,
        edges,
        skin,
        edge_skin,
        controls: vec![3, 27, 55, 71, 98],
        bones,
    }
}

impl Problem {
    /// The eq. 11 solver of this problem at `beta`.
    pub(crate) fn solver(&self, beta: f32) -> TranslationSolver {
        TranslationSolver::new(
            &self.mesh.positions,
            &self.edges,
            &self.skin,
            &self.edge_skin,
            &self.controls,
            self.bones,
            beta,
        )
        .unwrap()
    }
}

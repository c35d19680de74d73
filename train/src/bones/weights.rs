//! Weight update: per vertex, the skinning weights that best reproduce its trajectory given the
//! bone transforms (FKY08 §3: "influence weights ... obtained by minimizing the fitting error of
//! vertex positions in all examples"), as in SSDR (Le & Deng 2012 §3.2):
//!
//! ```text
//! min_w sum_t | sum_j w_j (R_j^t p + T_j^t) - v^t |^2   s.t.  w >= 0, sum w = 1, |w|_0 <= K
//! ```
//!
//! With `a_j` the stacked `R_j^t p + T_j^t` over frames, this is the simplex QP of [`super::qp`]
//! with `G = A^T A`, `g = A^T v`. Candidates are the bones already influencing the vertex or its
//! one-ring neighbours plus the nearest bone centres; the sparsity bound is met by keeping the
//! `K` largest weights and solving again on them.

use crease_core::glam::Vec3A;

use super::kabsch::Rigid;
use super::qp::{MAX_CANDIDATES, SimplexQp};
use super::{FitOptions, Problem, Weights};
use crate::par;

/// Vertices per parallel work item.
const CHUNK: usize = 128;

/// Per-worker buffers, reused across vertices.
struct Scratch {
    qp: SimplexQp,
    cands: Vec<u32>,
    cols: Vec<Vec3A>,
    gram: Vec<f64>,
    rhs: Vec<f64>,
    w: Vec<f64>,
    w0: Vec<f64>,
    allowed: Vec<bool>,
    nearest: Vec<(f32, u32)>,
}

impl Scratch {
    fn new(frames: usize) -> Self {
        Self {
            qp: SimplexQp::default(),
            cands: Vec::with_capacity(MAX_CANDIDATES),
            cols: vec![Vec3A::ZERO; MAX_CANDIDATES * frames],
            gram: vec![0.0; MAX_CANDIDATES * MAX_CANDIDATES],
            rhs: vec![0.0; MAX_CANDIDATES],
            w: vec![0.0; MAX_CANDIDATES],
            w0: vec![0.0; MAX_CANDIDATES],
            allowed: vec![false; MAX_CANDIDATES],
            nearest: Vec::new(),
        }
    }
}

/// The weight step of the alternation.
pub(crate) struct WeightSolver {
    nearest_bones: usize,
}

impl WeightSolver {
    pub(super) fn new(_problem: &Problem, options: &FitOptions) -> Self {
        Self {
            nearest_bones: options.nearest_bones.min(MAX_CANDIDATES / 2),
        }
    }

    /// Replaces `weights` with the per-vertex optimum given transforms `xf` (`[t * bones + b]`).
    pub(super) fn update(
        &mut self,
        problem: &Problem,
        bones: usize,
        xf: &[Rigid],
        weights: &mut Weights,
    ) {
        let k = weights.k;
        let f = problem.f;
        let centres = bone_centres(problem, bones, weights);
        let grid = CentreGrid::new(&centres);
        let old = &*weights;
        let nearest_bones = self.nearest_bones;
        let mut out: Vec<(u32, f32)> = vec![(0, 0.0); problem.n * k];
        par::map_chunks_mut(
            &mut out,
            CHUNK * k,
            || Scratch::new(f),
            |s, c, chunk| {
                for (j, slots) in chunk.chunks_mut(k).enumerate() {
                    let i = c * CHUNK + j;
                    solve_vertex(problem, bones, xf, old, &grid, nearest_bones, i, s, slots);
                }
            },
        );
        for (s, (b, w)) in out.into_iter().enumerate() {
            weights.idx[s] = b;
            weights.w[s] = w;
        }
    }
}

/// Weighted rest-pose centre of each bone's influence (NaN-free: unused bones get `None`).
fn bone_centres(problem: &Problem, bones: usize, weights: &Weights) -> Vec<Option<Vec3A>> {
    let mut sum = vec![(Vec3A::ZERO, 0f32); bones];
    for i in 0..problem.n {
        for s in i * weights.k..(i + 1) * weights.k {
            let w = weights.w[s];
            if w > 0.0 {
                let e = &mut sum[weights.idx[s] as usize];
                e.0 += w * problem.rest[i];
                e.1 += w;
            }
        }
    }
    sum.into_iter()
        .map(|(p, w)| (w > 0.0).then(|| p / w))
        .collect()
}

/// The bone centres in a uniform grid of about two centres per occupied cell, for the nearest
/// centres of every vertex (issue 23): scanning all centres per vertex made the weight step
/// `O(n * bones)`, a quarter of its time at 1,355 bones on 49K vertices.
struct CentreGrid {
    lo: Vec3A,
    inv_cell: f32,
    dims: [usize; 3],
    /// Cell `c`'s centres are `items[start[c]..start[c + 1]]`.
    start: Vec<u32>,
    items: Vec<(Vec3A, u32)>,
}

impl CentreGrid {
    fn new(centres: &[Option<Vec3A>]) -> Self {
        let present: Vec<(Vec3A, u32)> = centres
            .iter()
            .enumerate()
            .filter_map(|(b, c)| c.map(|c| (c, b as u32)))
            .collect();
        let (mut lo, mut hi) = (Vec3A::splat(f32::INFINITY), Vec3A::splat(f32::NEG_INFINITY));
        for &(c, _) in &present {
            lo = lo.min(c);
            hi = hi.max(c);
        }
        if present.is_empty() {
            (lo, hi) = (Vec3A::ZERO, Vec3A::ZERO);
        }
        let extent = (hi - lo).max(Vec3A::splat(1e-6));
        // About two centres per cell of a box-filling layout (a surface fills fewer cells).
        let cell = (extent.x * extent.y * extent.z * 2.0 / present.len().max(1) as f32)
            .cbrt()
            .max(extent.max_element() / 64.0);
        let inv_cell = 1.0 / cell;
        // At most 65 cells an axis (the cell is at least 1/64 of the largest side).
        let dims = [extent.x, extent.y, extent.z].map(|e| (e * inv_cell) as usize + 1);
        let mut grid = Self {
            lo,
            inv_cell,
            dims,
            start: vec![0; dims[0] * dims[1] * dims[2] + 1],
            items: Vec::with_capacity(present.len()),
        };
        let cells: Vec<usize> = present
            .iter()
            .map(|&(c, _)| grid.flat(grid.cell(c)))
            .collect();
        for &c in &cells {
            grid.start[c + 1] += 1;
        }
        for c in 1..grid.start.len() {
            grid.start[c] += grid.start[c - 1];
        }
        let mut fill = grid.start.clone();
        grid.items.resize(present.len(), (Vec3A::ZERO, 0));
        for (&c, &item) in cells.iter().zip(&present) {
            grid.items[fill[c] as usize] = item;
            fill[c] += 1;
        }
        grid
    }

    fn cell(&self, p: Vec3A) -> [usize; 3] {
        let g = (p - self.lo) * self.inv_cell;
        let axis = |g: f32, d: usize| (g.max(0.0) as usize).min(d - 1);
        [
            axis(g.x, self.dims[0]),
            axis(g.y, self.dims[1]),
            axis(g.z, self.dims[2]),
        ]
    }

    fn flat(&self, c: [usize; 3]) -> usize {
        (c[2] * self.dims[1] + c[1]) * self.dims[0] + c[0]
    }

    /// The `m` centres nearest to `p` (exactly: as a scan of all would find them, ties in any
    /// order) in `out[..returned]`, `returned = min(m, centres)`.
    fn nearest(&self, p: Vec3A, m: usize, out: &mut Vec<(f32, u32)>) -> usize {
        out.clear();
        let m = m.min(self.items.len());
        if m == 0 {
            return 0;
        }
        let home = self.cell(p);
        let max_r = self.dims.into_iter().max().unwrap_or(1);
        for r in 0..=max_r {
            // The cells at Chebyshev distance r from home.
            let range = |a: usize| home[a].saturating_sub(r)..=(home[a] + r).min(self.dims[a] - 1);
            for z in range(2) {
                for y in range(1) {
                    for x in range(0) {
                        let shell = [x, y, z]
                            .into_iter()
                            .zip(home)
                            .any(|(c, h)| c.abs_diff(h) == r);
                        if !shell {
                            continue;
                        }
                        let c = self.flat([x, y, z]);
                        out.extend(
                            self.items[self.start[c] as usize..self.start[c + 1] as usize]
                                .iter()
                                .map(|&(q, b)| ((q - p).length_squared(), b)),
                        );
                    }
                }
            }
            if out.len() >= m {
                out.select_nth_unstable_by(m - 1, |a, b| a.0.total_cmp(&b.0));
                // Unvisited centres lie outside the visited block of cells: at least the
                // distance from p to that block's nearest face away.
                let mut reach = f32::INFINITY;
                for a in 0..3 {
                    let cell = 1.0 / self.inv_cell;
                    let lo = self.lo[a] + home[a].saturating_sub(r) as f32 * cell;
                    let hi = self.lo[a] + ((home[a] + r + 1).min(self.dims[a])) as f32 * cell;
                    if home[a] >= r {
                        reach = reach.min(p[a] - lo);
                    }
                    if home[a] + r + 1 < self.dims[a] {
                        reach = reach.min(hi - p[a]);
                    }
                }
                if reach.is_infinite() || out[m - 1].0 <= reach.max(0.0).powi(2) {
                    return m;
                }
            }
        }
        out.select_nth_unstable_by(m - 1, |a, b| a.0.total_cmp(&b.0));
        m
    }
}

#[allow(clippy::too_many_arguments)]
fn solve_vertex(
    problem: &Problem,
    bones: usize,
    xf: &[Rigid],
    old: &Weights,
    grid: &CentreGrid,
    nearest_bones: usize,
    i: usize,
    s: &mut Scratch,
    out: &mut [(u32, f32)],
) {
    let k = old.k;
    let f = problem.f;
    let p = problem.rest[i];
    let traj = &problem.traj[i * f..(i + 1) * f];

    // Candidate bones: own, neighbours', nearest centres (in that priority).
    s.cands.clear();
    let push = |b: u32, cands: &mut Vec<u32>| {
        if cands.len() < MAX_CANDIDATES && !cands.contains(&b) {
            cands.push(b);
        }
    };
    for v in std::iter::once(i as u32).chain(problem.neighbours(i).iter().copied()) {
        let v = v as usize;
        for slot in v * k..(v + 1) * k {
            if old.w[slot] > 0.0 {
                push(old.idx[slot], &mut s.cands);
            }
        }
    }
    if nearest_bones > 0 {
        let m = grid.nearest(p, nearest_bones, &mut s.nearest);
        for &(_, b) in &s.nearest[..m] {
            push(b, &mut s.cands);
        }
    }
    let n = s.cands.len();
    if n == 0 {
        // Only possible with no bones at all; leave the vertex on bone 0.
        out.fill((0, 0.0));
        out[0] = (0, 1.0);
        return;
    }

    // Columns a_j (per frame R_j^t p + T_j^t), Gram matrix and right-hand side.
    for (a, &b) in s.cands.iter().enumerate() {
        for t in 0..f {
            s.cols[a * f + t] = xf[t * bones + b as usize].apply(p);
        }
    }
    for a in 0..n {
        let ca = &s.cols[a * f..(a + 1) * f];
        let mut r = 0.0f64;
        for t in 0..f {
            r += ca[t].dot(traj[t]) as f64;
        }
        s.rhs[a] = r;
        for b in 0..=a {
            let cb = &s.cols[b * f..(b + 1) * f];
            let mut g = 0.0f64;
            for t in 0..f {
                g += ca[t].dot(cb[t]) as f64;
            }
            s.gram[a * n + b] = g;
            s.gram[b * n + a] = g;
        }
    }

    // Warm start from the current weights.
    s.w[..n].fill(0.0);
    for slot in i * k..(i + 1) * k {
        let w = old.w[slot];
        if w > 0.0
            && let Some(a) = s.cands.iter().position(|&b| b == old.idx[slot])
        {
            s.w[a] += w as f64;
        }
    }
    let sum: f64 = s.w[..n].iter().sum();
    if sum > 0.0 {
        s.w[..n].iter_mut().for_each(|w| *w /= sum);
    }
    s.w0[..n].copy_from_slice(&s.w[..n]);
    let f_old = objective(n, &s.gram, &s.rhs, &s.w0);
    s.allowed[..n].fill(true);
    s.qp.solve(n, &s.gram, &s.rhs, &s.allowed, &mut s.w);

    // Sparsity: keep the K largest and re-solve on them.
    let nnz = s.w[..n].iter().filter(|&&w| w > 0.0).count();
    if nnz > k {
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| s.w[b].total_cmp(&s.w[a]));
        s.allowed[..n].fill(false);
        for &a in &order[..k] {
            s.allowed[a] = true;
        }
        for a in 0..n {
            if !s.allowed[a] {
                s.w[a] = 0.0;
            }
        }
        let kept: f64 = s.w[..n].iter().sum();
        s.w[..n].iter_mut().for_each(|w| *w /= kept);
        s.qp.solve(n, &s.gram, &s.rhs, &s.allowed, &mut s.w);
        // Truncating to K can lose to the current (already K-sparse) weights: never go back.
        let old_nnz = s.w0[..n].iter().filter(|&&w| w > 0.0).count();
        if old_nnz > 0 && objective(n, &s.gram, &s.rhs, &s.w) > f_old {
            s.w[..n].copy_from_slice(&s.w0[..n]);
        }
    }

    out.fill((0, 0.0));
    let mut slot = 0;
    for a in 0..n {
        if s.w[a] > 0.0 && slot < k {
            out[slot] = (s.cands[a], s.w[a] as f32);
            slot += 1;
        }
    }
    if slot == 0 {
        out[0] = (s.cands[0], 1.0);
    }
}

/// `1/2 w^T G w - g^T w`.
fn objective(n: usize, gram: &[f64], rhs: &[f64], w: &[f64]) -> f64 {
    let mut f = 0.0;
    for a in 0..n {
        if w[a] == 0.0 {
            continue;
        }
        let mut gw = 0.0;
        for b in 0..n {
            gw += gram[a * n + b] * w[b];
        }
        f += w[a] * (0.5 * gw - rhs[a]);
    }
    f
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    /// The grid's nearest centres are a brute-force scan's, on clustered and spread centres,
    /// queries inside and outside their box, with unused bones among them.
    #[test]
    fn grid_nearest_equals_a_scan() {
        let mut rng = StdRng::seed_from_u64(23);
        for (count, spread) in [
            (0usize, 1.0f32),
            (1, 1.0),
            (5, 1.0),
            (300, 1.0),
            (1355, 0.05),
        ] {
            let centres: Vec<Option<Vec3A>> = (0..count)
                .map(|b| {
                    (b % 7 != 3).then(|| {
                        Vec3A::new(
                            rng.random_range(0.0..1.0),
                            rng.random_range(0.0..spread),
                            rng.random_range(0.0..0.2),
                        )
                    })
                })
                .collect();
            let grid = CentreGrid::new(&centres);
            let mut out = Vec::new();
            for q in 0..200 {
                let p = Vec3A::new(
                    rng.random_range(-0.5..1.5),
                    rng.random_range(-0.5..1.5),
                    rng.random_range(-0.5..0.7),
                );
                let m = 1 + q % 8;
                let got = grid.nearest(p, m, &mut out);
                let mut want: Vec<(f32, u32)> = centres
                    .iter()
                    .enumerate()
                    .filter_map(|(b, c)| c.map(|c| ((c - p).length_squared(), b as u32)))
                    .collect();
                want.sort_by(|a, b| a.0.total_cmp(&b.0));
                assert_eq!(got, m.min(want.len()), "{count} centres, query {q}");
                let mut got_d: Vec<f32> = out[..got].iter().map(|x| x.0).collect();
                got_d.sort_by(f32::total_cmp);
                let want_d: Vec<f32> = want[..got].iter().map(|x| x.0).collect();
                assert_eq!(got_d, want_d, "{count} centres, query {q} at {p}");
            }
        }
    }
}

//! Rigid clustering: the initial bones. Vertices are grouped by similar rigid motion across
//! the examples (FKY08 §3 groups triangles of similar transformation after [JT05]; here
//! vertices, as SSDR's initialisation does).
//!
//! Start from one bone holding every vertex. Each round splits the bones with the largest
//! error: a new bone is seeded at the worst-fitting vertex of the split bone with the rigid
//! motion of that vertex's mesh neighbourhood. Lloyd iterations follow: every vertex moves to
//! the bone whose transforms reproduce its whole trajectory best, then every bone is refit to
//! its vertices by Kabsch. Bones left without vertices are dropped. Rounds double the bone
//! count until the target is reached, so the cost is dominated by the last rounds.

use crease_core::glam::{Mat3A, Vec3A};

use super::kabsch::{PairSums, Rigid};
use super::{FitOptions, Problem};
use crate::par;

/// Vertices a neighbourhood seed uses for the new bone's rigid motion.
const SEED_NEIGHBOURHOOD: usize = 12;
/// A bone needs this many vertices to be split (fewer cannot seed two rigid motions).
const MIN_SPLIT_VERTICES: usize = 6;
/// Consecutive rounds without a new surviving bone before clustering gives up on the target.
const MAX_STALLED_ROUNDS: usize = 3;
/// Vertices per parallel work item in the assignment step.
const ASSIGN_CHUNK: usize = 256;
/// Most distinct candidate bones of one vertex's two-ring kept.
const MAX_CANDIDATES: usize = 32;

/// Result of clustering: `bones` bones, one label per vertex, transforms `[t * bones + b]`.
pub(crate) struct Clustering {
    pub bones: usize,
    pub labels: Vec<u32>,
    pub transforms: Vec<Rigid>,
}

/// Clusters to `options.bones` bones (fewer if the mesh cannot support them). `report` gets
/// `(round, bones, rms_normalized)` after every round.
pub(crate) fn cluster(
    problem: &Problem,
    options: &FitOptions,
    report: &mut dyn FnMut(usize, usize, f64),
) -> Clustering {
    let target = options.bones.min(problem.n).max(1);
    let mut labels = vec![0u32; problem.n];
    let mut bones = 1;
    let mut xf = fit_from_labels(problem, &labels, bones, None);
    let mut errors = vec![0f32; problem.n];
    // Rounds that did not grow the bone count (splits that Lloyd undid): a few are tolerated,
    // then the clustering stops short of the target rather than loop.
    let mut stalled = 0;
    let mut best_bones = 0;
    for round in 1.. {
        for _ in 0..options.cluster_iterations.max(1) {
            let changed = assign(
                problem,
                &xf,
                bones,
                &mut labels,
                options.exhaustive_cluster_bones,
            );
            let (b, kept) = compact(&mut labels, bones);
            xf = select_bones(&xf, bones, &kept, problem.f);
            bones = b;
            xf = fit_from_labels(problem, &labels, bones, Some(&xf));
            if changed == 0 {
                break;
            }
        }
        let rms = own_errors(problem, &xf, bones, &labels, &mut errors);
        report(round, bones, rms);
        if bones > best_bones {
            best_bones = bones;
            stalled = 0;
        } else {
            stalled += 1;
        }
        if bones >= target || stalled >= MAX_STALLED_ROUNDS {
            break;
        }
        let added = split(
            problem,
            &mut xf,
            bones,
            &mut labels,
            &errors,
            target - bones,
        );
        if added == 0 {
            break;
        }
        bones += added;
    }
    Clustering {
        bones,
        labels,
        transforms: xf,
    }
}

/// Sum over frames of `|R p + T - v|^2` for one vertex and bone, giving up once it exceeds
/// `bound` (checked every few frames: most bones lose within the first ones).
#[inline]
fn trajectory_error(
    xf: &[Rigid],
    bones: usize,
    b: usize,
    p: Vec3A,
    traj: &[Vec3A],
    bound: f32,
) -> f32 {
    let mut e = 0.0f32;
    for (t, v) in traj.iter().enumerate() {
        e += (xf[t * bones + b].apply(p) - *v).length_squared();
        if t % 4 == 3 && e > bound {
            return e;
        }
    }
    e
}

/// Lloyd assignment: every vertex takes the bone of least trajectory error. Returns how many
/// vertices changed bone.
///
/// Candidates (issue 23): up to `exhaustive` bones every bone; beyond, the bones that
/// label the vertex's two-ring at the start of the step (Jacobi: all read the same labels).
/// Every bone is then a connected patch grown from a seed, and a vertex's best bone is its own
/// or a neighbouring patch's; weighing all bones made the step `O(n * bones)`, 27 of the
/// 38 s that clustering 1,355 bones on a 49K-vertex hand took, for moves that the candidate
/// set makes within a ring per iteration.
fn assign(
    problem: &Problem,
    xf: &[Rigid],
    bones: usize,
    labels: &mut [u32],
    exhaustive: usize,
) -> usize {
    let f = problem.f;
    let before = labels.to_vec();
    let changed = par::map_chunks_mut(
        labels,
        ASSIGN_CHUNK,
        || (),
        |_, c, chunk| {
            let mut changed = 0;
            for (j, label) in chunk.iter_mut().enumerate() {
                let i = c * ASSIGN_CHUNK + j;
                let (p, traj) = (problem.rest[i], &problem.traj[i * f..(i + 1) * f]);
                let own = before[i] as usize;
                let best = if bones <= exhaustive {
                    best_bone(xf, bones, p, traj, own, 0..bones)
                } else {
                    let (cand, len) = two_ring_bones(problem, &before, i);
                    let others = cand[..len].iter().map(|&b| b as usize);
                    best_bone(xf, bones, p, traj, own, others)
                };
                changed += usize::from(*label != best as u32);
                *label = best as u32;
            }
            changed
        },
    );
    changed.into_iter().sum()
}

/// The bone of least trajectory error among `own` and `others` (`own` wins ties; `others`
/// may name `own` again).
fn best_bone(
    xf: &[Rigid],
    bones: usize,
    p: Vec3A,
    traj: &[Vec3A],
    own: usize,
    others: impl Iterator<Item = usize>,
) -> usize {
    let mut best = own;
    let mut best_e = trajectory_error(xf, bones, own, p, traj, f32::INFINITY);
    for b in others.filter(|&b| b != own) {
        let e = trajectory_error(xf, bones, b, p, traj, best_e);
        if e < best_e {
            best_e = e;
            best = b;
        }
    }
    best
}

/// The distinct bones labelling vertex `i`'s two-ring (its own first), at most
/// [`MAX_CANDIDATES`]: `(bones, count)`.
fn two_ring_bones(problem: &Problem, labels: &[u32], i: usize) -> ([u32; MAX_CANDIDATES], usize) {
    let mut cand = [0u32; MAX_CANDIDATES];
    cand[0] = labels[i];
    let mut len = 1;
    let mut push = |b: u32| {
        if len < MAX_CANDIDATES && !cand[..len].contains(&b) {
            cand[len] = b;
            len += 1;
        }
    };
    for &u in problem.neighbours(i) {
        push(labels[u as usize]);
        for &w in problem.neighbours(u as usize) {
            push(labels[w as usize]);
        }
    }
    (cand, len)
}

/// Renumbers labels so that bones without vertices disappear. Returns the new bone count and,
/// for each new bone, its old index.
fn compact(labels: &mut [u32], bones: usize) -> (usize, Vec<usize>) {
    let mut count = vec![0usize; bones];
    for &l in labels.iter() {
        count[l as usize] += 1;
    }
    let kept: Vec<usize> = (0..bones).filter(|&b| count[b] > 0).collect();
    let mut map = vec![u32::MAX; bones];
    for (new, &old) in kept.iter().enumerate() {
        map[old] = new as u32;
    }
    for l in labels.iter_mut() {
        *l = map[*l as usize];
    }
    (kept.len(), kept)
}

fn select_bones(xf: &[Rigid], bones: usize, kept: &[usize], frames: usize) -> Vec<Rigid> {
    let mut out = Vec::with_capacity(kept.len() * frames);
    for t in 0..frames {
        out.extend(kept.iter().map(|&b| xf[t * bones + b]));
    }
    out
}

/// Per frame, every bone's Kabsch fit to its vertices. A bone without vertices keeps its
/// previous transform (or the identity).
fn fit_from_labels(
    problem: &Problem,
    labels: &[u32],
    bones: usize,
    prev: Option<&[Rigid]>,
) -> Vec<Rigid> {
    let n = problem.n;
    let per_frame = par::map_range(
        problem.f,
        || vec![PairSums::default(); bones],
        |sums, t| {
            sums.iter_mut().for_each(|s| *s = PairSums::default());
            let frame = &problem.frames[t * n..(t + 1) * n];
            for i in 0..n {
                sums[labels[i] as usize].add(1.0, problem.rest[i], frame[i]);
            }
            (0..bones)
                .map(|b| {
                    let old = prev.map_or(Rigid::IDENTITY, |x| x[t * bones + b]);
                    sums[b].solve(old.m).unwrap_or(old)
                })
                .collect::<Vec<_>>()
        },
    );
    per_frame.into_iter().flatten().collect()
}

/// Each vertex's error under its own bone (all frames, for splitting) and the normalised RMS
/// over the counted frames.
fn own_errors(
    problem: &Problem,
    xf: &[Rigid],
    bones: usize,
    labels: &[u32],
    errors: &mut [f32],
) -> f64 {
    let f = problem.f;
    let mut counted_sse = 0.0f64;
    for i in 0..problem.n {
        let b = labels[i] as usize;
        let p = problem.rest[i];
        let mut e_all = 0.0f32;
        for t in 0..f {
            let e = (xf[t * bones + b].apply(p) - problem.traj[i * f + t]).length_squared();
            e_all += e;
            if problem.counted[t] {
                counted_sse += e as f64;
            }
        }
        errors[i] = e_all;
    }
    let frames = problem.counted.iter().filter(|&&c| c).count().max(1);
    (counted_sse * problem.inv_scale2 / (frames * problem.n) as f64).sqrt()
}

/// Splits up to `max_new` bones with the largest total error. Returns how many were added;
/// the new bones' transforms are appended (the layout `[t * bones + b]` is rebuilt) and their
/// seed neighbourhoods relabelled.
fn split(
    problem: &Problem,
    xf: &mut Vec<Rigid>,
    bones: usize,
    labels: &mut [u32],
    errors: &[f32],
    max_new: usize,
) -> usize {
    let mut bone_error = vec![0f64; bones];
    let mut count = vec![0usize; bones];
    let mut worst = vec![(f32::NEG_INFINITY, usize::MAX); bones];
    for i in 0..problem.n {
        let b = labels[i] as usize;
        bone_error[b] += errors[i] as f64;
        count[b] += 1;
        if errors[i] > worst[b].0 {
            worst[b] = (errors[i], i);
        }
    }
    let mut order: Vec<usize> = (0..bones)
        .filter(|&b| count[b] >= MIN_SPLIT_VERTICES && bone_error[b] > 0.0)
        .collect();
    order.sort_by(|&a, &b| bone_error[b].total_cmp(&bone_error[a]).then(a.cmp(&b)));
    order.truncate(max_new);

    let f = problem.f;
    let mut seeds: Vec<Vec<usize>> = Vec::with_capacity(order.len());
    for &b in &order {
        let hood = neighbourhood(problem, worst[b].1, |v| labels[v] as usize == b);
        if hood.len() >= 3 {
            seeds.push(hood);
        }
    }
    if seeds.is_empty() {
        return 0;
    }
    let new_bones = bones + seeds.len();
    let mut out = Vec::with_capacity(new_bones * f);
    for t in 0..f {
        out.extend_from_slice(&xf[t * bones..(t + 1) * bones]);
        for hood in &seeds {
            let mut sums = PairSums::default();
            for &v in hood {
                sums.add(1.0, problem.rest[v], problem.frames[t * problem.n + v]);
            }
            let fallback = xf[t * bones + labels[hood[0]] as usize];
            out.push(sums.solve(Mat3A::IDENTITY).unwrap_or(fallback));
        }
    }
    for (s, hood) in seeds.iter().enumerate() {
        for &v in hood {
            labels[v] = (bones + s) as u32;
        }
    }
    *xf = out;
    seeds.len()
}

/// Breadth-first mesh neighbourhood of `seed` (up to [`SEED_NEIGHBOURHOOD`] vertices),
/// preferring vertices that satisfy `inside`; outside ones are used only to reach three.
fn neighbourhood(problem: &Problem, seed: usize, inside: impl Fn(usize) -> bool) -> Vec<usize> {
    let mut hood = vec![seed];
    let mut outside = Vec::new();
    let mut head = 0;
    while head < hood.len() && hood.len() < SEED_NEIGHBOURHOOD {
        let v = hood[head];
        head += 1;
        for &u in problem.neighbours(v) {
            let u = u as usize;
            if hood.contains(&u) || outside.contains(&u) {
                continue;
            }
            if inside(u) {
                hood.push(u);
                if hood.len() >= SEED_NEIGHBOURHOOD {
                    break;
                }
            } else {
                outside.push(u);
            }
        }
    }
    if hood.len() < 3 {
        hood.extend(outside.into_iter().take(3 - hood.len()));
    }
    hood
}

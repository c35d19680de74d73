//! Proxy bones and skinning weights from example meshes (FKY08 §3, HZY11 §5.1).
//!
//! Given a rest pose `p_i` and example frames `v_i^t` sharing its topology, find `B` rigid bone
//! transforms per frame `(R_j^t, T_j^t)` and per-vertex weights `w_ij` (non-negative, summing to
//! one, at most `K` non-zero) minimising the linear-blend-skinning fit error
//!
//! ```text
//! E = sum_t sum_i | sum_j w_ij (R_j^t p_i + T_j^t) - v_i^t |^2
//! ```
//!
//! This is the smooth skinning decomposition with rigid bones (Le & Deng 2012, "SSDR"), the
//! modern form of the papers' "cluster triangles of similar transformation, then fit weights"
//! (FKY08 §3 after \[JT05\], HZY11 §5.1). Stages, each its own module:
//!
//! 1. `cluster`: rigid clustering. Vertices are grouped by similar rigid motion across the
//!    examples: start from one bone, repeatedly split the bones with the largest error at their
//!    worst vertex (seeded with the rigid motion of that vertex's neighbourhood) and run Lloyd
//!    iterations (assign each vertex to the bone whose transforms reproduce its trajectory best,
//!    refit each bone by Kabsch) until there are `B` bones.
//! 2. Alternation until the relative improvement falls below a tolerance or an iteration cap:
//!    - `weights`: per vertex, a QP on the simplex (`qp`) over a small candidate set of
//!      bones (those of the vertex and its neighbours, plus the nearest bone centres), then the
//!      `K` largest kept and the QP re-solved on them;
//!    - `transforms`: per frame, per bone in turn, the weighted Procrustes update of SSDR
//!      (Le & Deng 2012 eq. 7) against the residual of the other bones (`kabsch`).
//!
//! Every stage is deterministic (no random seeds), parallel over vertices or frames with rayon
//! behind the `parallel` feature, and never produces a non-finite number: a degenerate bone keeps
//! its previous transform.

mod cluster;
mod kabsch;
pub(crate) mod qp;
mod transforms;
mod weights;

use std::time::Instant;

use crease_core::glam::{Mat3A, Quat, Vec3, Vec3A};
use crease_core::mesh::{Adjacency, Mesh, MeshError};
use crease_core::runtime::skin::{RigidTransform, SkinWeights};

use kabsch::Rigid;

/// Options of [`fit`]. Defaults follow the issue's horse setting (150 bones, K = 4).
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Number of proxy bones to fit (FKY08 used 150 on the horse, HZY11 over 1000 on hands).
    pub bones: usize,
    /// Most bones influencing one vertex (K): 1..=8. Four matches a GPU's vec4 skinning layout.
    pub max_influences: usize,
    /// Cap on weight/transform alternations after clustering.
    pub max_iterations: usize,
    /// Stop when an iteration lowers the RMS error by less than this fraction of it.
    pub tolerance: f64,
    /// Most Lloyd iterations after each round of bone splitting (fewer once labels settle).
    pub cluster_iterations: usize,
    /// Sweeps of the per-bone transform update per alternation (Gauss–Seidel passes).
    pub transform_passes: usize,
    /// Nearest bone centres added to each vertex's weight candidates, beyond the bones already
    /// influencing it or its mesh neighbours: lets influence cross cluster borders that the
    /// one-ring does not reach yet.
    pub nearest_bones: usize,
    /// Beyond this many bones, a clustering vertex weighs only the bones of its two-ring
    /// instead of every bone (issue 23: the exhaustive step is `O(vertices * bones)`).
    pub exhaustive_cluster_bones: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            bones: 150,
            max_influences: 4,
            max_iterations: 60,
            tolerance: 1e-3,
            cluster_iterations: 12,
            transform_passes: 2,
            nearest_bones: 6,
            exhaustive_cluster_bones: 256,
        }
    }
}

/// What went wrong before fitting could start.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// Options out of range.
    #[error("invalid option {field}: {reason}")]
    InvalidOption {
        /// Option name as on the command line.
        field: &'static str,
        /// What is wrong with it.
        reason: String,
    },
    /// A frame's vertex count differs from the rest pose.
    #[error("frame {frame}: {got} vertices, the rest pose has {expected}")]
    VertexCount {
        /// Index of the offending frame.
        frame: usize,
        /// Rest-pose vertex count.
        expected: usize,
        /// The frame's vertex count.
        got: usize,
    },
    /// A non-finite coordinate in the input.
    #[error("frame {frame}, vertex {vertex}: non-finite coordinate")]
    NonFinite {
        /// Frame index.
        frame: usize,
        /// Vertex index.
        vertex: usize,
    },
    /// Nothing to fit.
    #[error("need at least one frame and one vertex")]
    Empty,
    /// The rest mesh itself is broken (an index out of range, a non-finite coordinate).
    #[error("rest mesh is invalid")]
    InvalidMesh(#[source] MeshError),
}

/// The examples to fit: a rest pose and frames that share its vertex order.
#[derive(Clone, Copy, Debug)]
pub struct FitInput<'a> {
    /// Rest pose (bind pose) and its triangles (used for neighbourhoods).
    pub rest: &'a Mesh,
    /// All example frames, the rest pose included if it is an example.
    pub frames: &'a [&'a [Vec3]],
    /// Index of the rest pose among `frames`, left out of the reported RMS.
    pub rest_frame: Option<usize>,
}

/// One step of the fit, as reported to the progress callback.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct IterationStat {
    /// Phase: `"cluster"` rounds, then `"fit"` alternations.
    pub phase: &'static str,
    /// 1-based step number within the phase.
    pub iteration: usize,
    /// Bones alive at this step.
    pub bones: usize,
    /// RMS vertex error over the frames (rest frame excluded), bounding box largest side = 1.
    pub rms_normalized: f64,
    /// Seconds since the fit started.
    pub seconds: f64,
}

/// Why the alternation stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum StopReason {
    /// Relative improvement fell below the tolerance.
    Converged,
    /// The iteration cap was reached.
    IterationCap,
}

/// The fitted rig and how the fit went.
#[derive(Clone, Debug)]
pub struct FitResult {
    /// Bones in the result (may be fewer than asked; see `report.warnings`).
    pub bone_count: usize,
    /// Per-vertex influences, stride `max_influences`.
    pub skin: SkinWeights,
    /// Per frame, per bone: the transform taking the rest pose to that frame.
    pub transforms: Vec<Vec<RigidTransform>>,
    /// Timings, errors and warnings.
    pub report: FitReport,
}

/// Summary of a fit.
#[derive(Clone, Debug, serde::Serialize)]
pub struct FitReport {
    /// Bones asked for.
    pub bones_requested: usize,
    /// Bones delivered.
    pub bones: usize,
    /// K.
    pub max_influences: usize,
    /// Alternations run after clustering.
    pub iterations: usize,
    /// Every reported step, clustering rounds included.
    pub history: Vec<IterationStat>,
    /// Final RMS error, bbox largest side = 1, rest frame excluded, evaluated with the returned
    /// (quaternion) transforms and f32 weights.
    pub rms_normalized: f64,
    /// Wall-clock seconds of the whole fit.
    pub seconds: f64,
    /// Why the alternation stopped.
    pub stop: StopReason,
    /// Things the user should know (fewer bones than asked, ...).
    pub warnings: Vec<String>,
}

/// Problem data shared by all stages, in the layouts the hot loops want.
pub(crate) struct Problem {
    pub n: usize,
    pub f: usize,
    /// Rest positions.
    pub rest: Vec<Vec3A>,
    /// Frames, frame-major: `[t * n + i]`.
    pub frames: Vec<Vec3A>,
    /// Frames, vertex-major: `[i * f + t]`.
    pub traj: Vec<Vec3A>,
    /// One-ring neighbours.
    pub ring: Adjacency,
    /// 1 / (largest bbox side)^2, to report normalised errors.
    pub inv_scale2: f64,
    /// Frame mask for the reported RMS.
    pub counted: Vec<bool>,
}

impl Problem {
    fn neighbours(&self, i: usize) -> &[u32] {
        self.ring.neighbors(i)
    }

    /// Normalised RMS from a per-frame sum of squared errors.
    fn rms(&self, frame_sse: &[f64]) -> f64 {
        let (sse, count) = frame_sse
            .iter()
            .zip(&self.counted)
            .filter(|(_, c)| **c)
            .fold((0.0, 0usize), |(s, c), (e, _)| (s + e, c + 1));
        if count == 0 {
            return 0.0;
        }
        (sse * self.inv_scale2 / (count * self.n) as f64).sqrt()
    }
}

/// Current weights: stride `k`, vertex-major, unused slots weight 0.
#[derive(Clone, Debug)]
pub(crate) struct Weights {
    pub k: usize,
    pub idx: Vec<u32>,
    pub w: Vec<f32>,
}

impl Weights {
    fn one_hot(labels: &[u32], k: usize) -> Self {
        let mut idx = vec![0u32; labels.len() * k];
        let mut w = vec![0f32; labels.len() * k];
        for (i, &l) in labels.iter().enumerate() {
            idx[i * k] = l;
            w[i * k] = 1.0;
        }
        Self { k, idx, w }
    }

    /// Per bone, the vertices it influences and with which weight (CSR).
    fn by_bone(&self, bones: usize) -> (Vec<u32>, Vec<(u32, f32)>) {
        let mut counts = vec![0u32; bones + 1];
        for (&b, &w) in self.idx.iter().zip(&self.w) {
            if w > 0.0 {
                counts[b as usize + 1] += 1;
            }
        }
        for b in 0..bones {
            counts[b + 1] += counts[b];
        }
        let mut fill = counts.clone();
        let mut entries = vec![(0u32, 0f32); counts[bones] as usize];
        for (s, (&b, &w)) in self.idx.iter().zip(&self.w).enumerate() {
            if w > 0.0 {
                let slot = &mut fill[b as usize];
                entries[*slot as usize] = ((s / self.k) as u32, w);
                *slot += 1;
            }
        }
        (counts, entries)
    }
}

/// Fits `options.bones` proxy bones and `options.max_influences` weights per vertex to the
/// examples. `progress` sees every clustering round and every alternation.
pub fn fit(
    input: FitInput<'_>,
    options: &FitOptions,
    progress: &mut dyn FnMut(&IterationStat),
) -> Result<FitResult, FitError> {
    let start = Instant::now();
    let problem = prepare(input, options)?;
    let mut history = Vec::new();
    let mut warnings = Vec::new();
    let mut report = |stat: IterationStat, history: &mut Vec<IterationStat>| {
        progress(&stat);
        history.push(stat);
    };

    // 1. Rigid clustering.
    let clustering = cluster::cluster(&problem, options, &mut |round, bones, rms| {
        report(
            IterationStat {
                phase: "cluster",
                iteration: round,
                bones,
                rms_normalized: rms,
                seconds: start.elapsed().as_secs_f64(),
            },
            &mut history,
        )
    });
    let mut bones = clustering.bones;
    let mut xf = clustering.transforms;
    let mut weights = Weights::one_hot(&clustering.labels, options.max_influences);

    // 2. Alternate weights and transforms.
    let mut prev = f64::INFINITY;
    let mut stop = StopReason::IterationCap;
    let mut iterations = 0;
    let mut weight_solver = weights::WeightSolver::new(&problem, options);
    for it in 1..=options.max_iterations {
        weight_solver.update(&problem, bones, &xf, &mut weights);
        let frame_sse =
            transforms::update(&problem, bones, &weights, &mut xf, options.transform_passes);
        let rms = problem.rms(&frame_sse);
        iterations = it;
        report(
            IterationStat {
                phase: "fit",
                iteration: it,
                bones,
                rms_normalized: rms,
                seconds: start.elapsed().as_secs_f64(),
            },
            &mut history,
        );
        if prev.is_finite() && prev - rms < options.tolerance * prev {
            stop = StopReason::Converged;
            break;
        }
        prev = rms;
    }

    // Drop bones that ended with no influence, renumbering the rest.
    let used = {
        let mut used = vec![false; bones];
        for (&b, &w) in weights.idx.iter().zip(&weights.w) {
            if w > 0.0 {
                used[b as usize] = true;
            }
        }
        used
    };
    let alive = used.iter().filter(|&&u| u).count();
    if alive < bones {
        let mut map = vec![u32::MAX; bones];
        let mut next = 0u32;
        for b in 0..bones {
            if used[b] {
                map[b] = next;
                next += 1;
            }
        }
        for (b, &w) in weights.idx.iter_mut().zip(&weights.w) {
            *b = if w > 0.0 { map[*b as usize] } else { 0 };
        }
        let mut kept = Vec::with_capacity(problem.f * alive);
        for t in 0..problem.f {
            for b in 0..bones {
                if used[b] {
                    kept.push(xf[t * bones + b]);
                }
            }
        }
        xf = kept;
        bones = alive;
    }
    if bones < options.bones {
        warnings.push(format!(
            "asked for {} bones, the fit ended with {}: {}",
            options.bones,
            bones,
            if problem.n < options.bones {
                "the mesh has fewer vertices than that".to_string()
            } else {
                "the examples' motion is reproduced without the others (they had no vertices left)"
                    .to_string()
            }
        ));
    }

    let (skin, transforms) = finish(&problem, bones, &weights, &xf);
    let rms_normalized = evaluate(&problem, &skin, &transforms);
    let report = FitReport {
        bones_requested: options.bones,
        bones,
        max_influences: options.max_influences,
        iterations,
        history,
        rms_normalized,
        seconds: start.elapsed().as_secs_f64(),
        stop,
        warnings,
    };
    Ok(FitResult {
        bone_count: bones,
        skin,
        transforms,
        report,
    })
}

fn prepare(input: FitInput<'_>, options: &FitOptions) -> Result<Problem, FitError> {
    if !(1..=8).contains(&options.max_influences) {
        return Err(FitError::InvalidOption {
            field: "max-influences",
            reason: format!("must be 1..=8, got {}", options.max_influences),
        });
    }
    if options.bones == 0 {
        return Err(FitError::InvalidOption {
            field: "bones",
            reason: "must be at least 1".into(),
        });
    }
    if options.tolerance.is_nan() || options.tolerance < 0.0 {
        return Err(FitError::InvalidOption {
            field: "tolerance",
            reason: format!("must be >= 0, got {}", options.tolerance),
        });
    }
    let n = input.rest.vertex_count();
    let f = input.frames.len();
    if n == 0 || f == 0 {
        return Err(FitError::Empty);
    }
    for (t, fr) in input.frames.iter().enumerate() {
        if fr.len() != n {
            return Err(FitError::VertexCount {
                frame: t,
                expected: n,
                got: fr.len(),
            });
        }
        if let Some(v) = fr.iter().position(|p| !p.is_finite()) {
            return Err(FitError::NonFinite {
                frame: t,
                vertex: v,
            });
        }
    }
    let rest: Vec<Vec3A> = input.rest.positions.iter().map(|&p| p.into()).collect();
    let mut frames = Vec::with_capacity(n * f);
    for fr in input.frames {
        frames.extend(fr.iter().map(|&p| Vec3A::from(p)));
    }
    let mut traj = vec![Vec3A::ZERO; n * f];
    for t in 0..f {
        for i in 0..n {
            traj[i * f + t] = frames[t * n + i];
        }
    }
    if let Err(e) = input.rest.validate() {
        return Err(FitError::InvalidMesh(e));
    }
    let ring = input.rest.vertex_adjacency();
    let scale = input.rest.bbox_diagonal_scale() as f64;
    let inv_scale2 = if scale > 0.0 {
        1.0 / (scale * scale)
    } else {
        1.0
    };
    let counted = (0..f)
        .map(|t| Some(t) != input.rest_frame || f == 1)
        .collect();
    Ok(Problem {
        n,
        f,
        rest,
        frames,
        traj,
        ring,
        inv_scale2,
        counted,
    })
}

/// Converts the working state into the public types: weights sorted by decreasing weight and
/// renormalised in f32, transforms as quaternion + translation.
fn finish(
    problem: &Problem,
    bones: usize,
    weights: &Weights,
    xf: &[Rigid],
) -> (SkinWeights, Vec<Vec<RigidTransform>>) {
    let k = weights.k;
    let mut idx = weights.idx.clone();
    let mut w = weights.w.clone();
    for i in 0..problem.n {
        let s = i * k..(i + 1) * k;
        let mut pairs: Vec<(u32, f32)> = idx[s.clone()]
            .iter()
            .copied()
            .zip(w[s.clone()].iter().copied())
            .collect();
        pairs.sort_by(|a, b| b.1.total_cmp(&a.1));
        let sum: f32 = pairs.iter().map(|p| p.1).sum();
        for (slot, (b, x)) in pairs.into_iter().enumerate() {
            idx[i * k + slot] = if x > 0.0 { b } else { 0 };
            w[i * k + slot] = if x > 0.0 { x / sum } else { 0.0 };
        }
    }
    let skin = SkinWeights::new(k, idx, w).expect("fitter weights are non-negative and normalised");
    let transforms = (0..problem.f)
        .map(|t| {
            (0..bones)
                .map(|b| {
                    let r = &xf[t * bones + b];
                    RigidTransform {
                        rotation: Quat::from_mat3a(&r.m).normalize(),
                        translation: Vec3::from(r.t),
                    }
                })
                .collect()
        })
        .collect();
    (skin, transforms)
}

/// RMS of the public result, computed from scratch (rest frame excluded, bbox side = 1).
fn evaluate(problem: &Problem, skin: &SkinWeights, transforms: &[Vec<RigidTransform>]) -> f64 {
    let frame_sse: Vec<f64> = transforms
        .iter()
        .enumerate()
        .map(|(t, bones)| {
            let mats: Vec<Rigid> = bones
                .iter()
                .map(|b| Rigid {
                    m: Mat3A::from_quat(b.rotation),
                    t: b.translation.into(),
                })
                .collect();
            (0..problem.n)
                .map(|i| {
                    let (bi, bw) = skin.vertex(i);
                    let p = problem.rest[i];
                    let mut v = Vec3A::ZERO;
                    for (&b, &w) in bi.iter().zip(bw) {
                        if w > 0.0 {
                            v += w * mats[b as usize].apply(p);
                        }
                    }
                    (v - problem.frames[t * problem.n + i]).length_squared() as f64
                })
                .sum()
        })
        .collect();
    problem.rms(&frame_sse)
}

/// Bone transforms fitted to one new frame with the rig's weights fixed: the SSDR transform
/// update (Le & Deng 2012 eq. 7) alone, `passes` Gauss–Seidel sweeps from `init`. This is the
/// "oracle" of the evaluation: the best the bone layer can do for a pose when the transforms
/// are known. `frame` must have the rest mesh's vertex count.
pub fn fit_frame_transforms(
    rest: &Mesh,
    skin: &SkinWeights,
    init: &[RigidTransform],
    frame: &[Vec3],
    passes: usize,
) -> Result<Vec<RigidTransform>, FitError> {
    let n = rest.vertex_count();
    if frame.len() != n {
        return Err(FitError::VertexCount {
            frame: 0,
            expected: n,
            got: frame.len(),
        });
    }
    if let Some(v) = frame.iter().position(|p| !p.is_finite()) {
        return Err(FitError::NonFinite {
            frame: 0,
            vertex: v,
        });
    }
    let bones = init.len();
    let problem = Problem {
        n,
        f: 1,
        rest: rest.positions.iter().map(|&p| p.into()).collect(),
        frames: frame.iter().map(|&p| p.into()).collect(),
        traj: frame.iter().map(|&p| p.into()).collect(),
        ring: Adjacency::default(),
        inv_scale2: 1.0,
        counted: vec![true],
    };
    let weights = Weights {
        k: skin.k(),
        idx: skin.indices().to_vec(),
        w: skin.weights().to_vec(),
    };
    let mut xf: Vec<Rigid> = init
        .iter()
        .map(|t| Rigid {
            m: Mat3A::from_quat(t.rotation),
            t: t.translation.into(),
        })
        .collect();
    transforms::update(&problem, bones, &weights, &mut xf, passes);
    Ok(xf
        .iter()
        .map(|r| RigidTransform {
            rotation: Quat::from_mat3a(&r.m).normalize(),
            translation: Vec3::from(r.t),
        })
        .collect())
}

/// Per bone, the rigid transform that best maps the rest positions of the vertices it
/// influences onto `frame`, each vertex weighted by its skin weight (Kabsch). A cheap,
/// independent-per-bone starting point for [`fit_frame_transforms`]; a bone without vertices
/// gets the identity.
pub fn weighted_kabsch_per_bone(
    rest: &Mesh,
    skin: &SkinWeights,
    bone_count: usize,
    frame: &[Vec3],
) -> Vec<RigidTransform> {
    let mut sums = vec![kabsch::PairSums::default(); bone_count];
    for (v, (idx, w)) in skin.iter().enumerate() {
        for (&b, &w) in idx.iter().zip(w) {
            if w > 0.0 && (b as usize) < bone_count {
                sums[b as usize].add(w as f64, rest.positions[v].into(), frame[v].into());
            }
        }
    }
    sums.iter()
        .map(|s| match s.solve(Mat3A::IDENTITY) {
            Some(r) => RigidTransform {
                rotation: Quat::from_mat3a(&r.m).normalize(),
                translation: Vec3::from(r.t),
            },
            None => RigidTransform::IDENTITY,
        })
        .collect()
}

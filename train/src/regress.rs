//! Rotation regressors from control points (FKY08 §4, HZY11 §5.1): builds the
//! [`RotationModel`] the runtime evaluates, for each of the predictor variants.
//!
//! | method | geometry space | pose space |
//! |---|---|---|
//! | `global` (FKY08) | every bone sees all control points | one model over all examples |
//! | `local-geometry` | bone sees its `k_c` geodesically nearest control points | one model |
//! | `local-pose` | all control points | one model per example pose, on its `k_p` nearest |
//! | `local` (HZY11) | `k_c` nearest | per pose |
//! | `rbf` (FKY08 Fig. 3 baseline) | all | direct kernel ridge regression, no CCA |

use crease_core::glam::{Quat, Vec3, Vec4};
use crease_core::mesh::Mesh;
use crease_core::runtime::kernel::Kernel;
use crease_core::runtime::predict::{
    ControlGroup, GroupRegression, LinearOperator, PoseModel, RotationModel,
};
use crease_core::runtime::skin::SkinWeights;

use crate::geodesic;
use crate::group_rig::GroupRig;
use crate::kcca::{self, KccaOptions, LinearModel};

/// The predictor variants.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// FKY08: all control points, all examples.
    Global,
    /// HZY11 §5.1.1: each bone sees its `k_c` nearest control points.
    LocalGeometry,
    /// HZY11 §5.1.2: one model per example pose, blended by a heat kernel.
    LocalPose,
    /// HZY11: both.
    Local,
    /// Direct RBF (kernel ridge) regression, the FKY08 Fig. 3 baseline.
    Rbf,
}

impl Method {
    /// Every variant, in the order evaluation tables list them.
    pub const ALL: [Method; 5] = [
        Method::Rbf,
        Method::Global,
        Method::LocalGeometry,
        Method::LocalPose,
        Method::Local,
    ];

    /// The command-line / JSON name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Global => "global",
            Method::LocalGeometry => "local-geometry",
            Method::LocalPose => "local-pose",
            Method::Local => "local",
            Method::Rbf => "rbf",
        }
    }

    /// Parses [`Method::name`].
    pub fn parse(s: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == s)
    }

    /// Whether each bone sees only its nearest control points (HZY11 §5.1.1).
    pub fn geometry_local(self) -> bool {
        matches!(self, Method::LocalGeometry | Method::Local)
    }

    fn pose_local(self) -> bool {
        matches!(self, Method::LocalPose | Method::Local)
    }
}

/// Which kernel the regression uses (its width is set from the data).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum KernelChoice {
    /// Gaussian with `sigma = scale * default_sigma(inputs)` (FKY08 §7: used for all but faces).
    Gaussian {
        /// Multiplier of the data-derived width.
        scale: f32,
    },
    /// Gaussian plus a linear part of weight `gamma` (`Kernel::GaussianLinear`), width as for
    /// `Gaussian`.
    GaussianLinear {
        /// Multiplier of the data-derived width.
        scale: f32,
        /// Weight of the linear part.
        gamma: f32,
    },
    /// Inhomogeneous polynomial `(x.y + c)^degree` (FKY08 §7, faces), on inputs scaled by the
    /// data-derived width so `c` is dimensionless.
    Polynomial {
        /// Offset `c`.
        c: f32,
        /// Degree.
        degree: u32,
    },
}

/// Options of [`build_rotation_model`].
#[derive(Clone, Debug)]
pub struct RegressOptions {
    /// Predictor variant.
    pub method: Method,
    /// Control points per bone for geometry-local methods (HZY11: 7).
    pub kc: usize,
    /// Neighbouring poses per local model and blended at run time (HZY11: 7).
    pub kp: usize,
    /// Kernel.
    pub kernel: KernelChoice,
    /// KCCA settings (bases, regularisation).
    pub kcca: KccaOptions,
    /// Ridge of the RBF baseline.
    pub rbf_ridge: f64,
}

impl Default for RegressOptions {
    fn default() -> Self {
        Self {
            method: Method::Global,
            kc: 7,
            kp: 7,
            kernel: KernelChoice::Gaussian { scale: 1.0 },
            kcca: KccaOptions::default(),
            rbf_ridge: 1e-6,
        }
    }
}

/// Training data of the regression.
#[derive(Clone, Copy, Debug)]
pub struct RegressInput<'a> {
    /// Rest mesh (geodesics).
    pub rest: &'a Mesh,
    /// Vertex weights of the rig (bone centres).
    pub skin: &'a SkinWeights,
    /// Bones of the rig.
    pub bone_count: usize,
    /// Mesh vertex of each control point.
    pub control_vertices: &'a [u32],
    /// Per example, the control point positions.
    pub controls: &'a [Vec<Vec3>],
    /// Per example, each bone's rotation relative to the rest pose.
    pub rotations: &'a [Vec<Quat>],
    /// For the geometry-local methods: group the bones by this coarse rig's bones' control
    /// points instead of each bone's own ([`crate::group_rig`]).
    pub group_rig: Option<&'a GroupRig>,
}

/// Fits the rotation regressors of `options.method`.
pub fn build_rotation_model(input: RegressInput<'_>, options: &RegressOptions) -> RotationModel {
    let n = input.controls.len();
    let nc = input.control_vertices.len();
    let rotations = align_signs(input.rotations, input.bone_count);
    let groups = if options.method.geometry_local() {
        geometry_groups(input, options.kc)
    } else {
        vec![(
            (0..nc as u32).collect(),
            (0..input.bone_count as u32).collect(),
        )]
    };
    let groups = groups
        .into_iter()
        .map(|(controls, bones)| fit_group(input, &rotations, controls, bones, options))
        .collect();
    RotationModel {
        control_count: nc,
        bone_count: input.bone_count,
        example_count: n,
        blend_poses: options.kp.clamp(1, n.max(1)),
        groups,
    }
}

/// Groups bones by their `k_c` geodesically nearest control points (HZY11 §5.1.1): the
/// bone's centre vertex is the vertex nearest to the weighted centre of what it moves. With a
/// [`GroupRig`], the points are those nearest to the centre of the coarse bone each bone
/// belongs to.
fn geometry_groups(input: RegressInput<'_>, kc: usize) -> Vec<(Vec<u32>, Vec<u32>)> {
    let dist = geodesic::distances_from(input.rest, input.control_vertices);
    let (skin, placed) = match input.group_rig {
        Some(g) => (&g.skin, g.bone_count),
        None => (input.skin, input.bone_count),
    };
    let sets: Vec<Vec<u32>> = geodesic::bone_centre_vertices(input.rest, skin, placed)
        .into_iter()
        .map(|centre| {
            let mut set: Vec<u32> = match centre {
                Some(v) => geodesic::nearest_sources(&dist, v, kc)
                    .into_iter()
                    .map(|c| c as u32)
                    .collect(),
                None => (0..input.control_vertices.len().min(kc) as u32).collect(),
            };
            set.sort_unstable();
            set
        })
        .collect();
    let mut groups: Vec<(Vec<u32>, Vec<u32>)> = Vec::new();
    for b in 0..input.bone_count {
        let set = match input.group_rig {
            Some(g) => &sets[g.of_bone[b] as usize],
            None => &sets[b],
        };
        match groups.iter_mut().find(|(s, _)| s == set) {
            Some((_, bones)) => bones.push(b as u32),
            None => groups.push((set.clone(), vec![b as u32])),
        }
    }
    groups
}

fn fit_group(
    input: RegressInput<'_>,
    rotations: &[Vec<Quat>],
    controls: Vec<u32>,
    bones: Vec<u32>,
    options: &RegressOptions,
) -> ControlGroup {
    let n = input.controls.len();
    let dim = 3 * controls.len();
    let mut x = Vec::with_capacity(n * dim);
    for example in input.controls {
        for &c in &controls {
            let p = example[c as usize];
            x.extend_from_slice(&[p.x, p.y, p.z]);
        }
    }
    let sigma = kcca::default_sigma(&x, dim).max(1e-12);
    let kernel = match options.kernel {
        KernelChoice::Gaussian { scale } => Kernel::Gaussian {
            sigma: sigma * scale,
        },
        KernelChoice::GaussianLinear { scale, gamma } => Kernel::GaussianLinear {
            sigma: sigma * scale,
            gamma,
        },
        KernelChoice::Polynomial { c, degree } => Kernel::Polynomial {
            c: c * sigma * sigma,
            degree,
        },
    };
    let quat_rows = |examples: &[usize], relative_to: Option<usize>| -> Vec<f32> {
        let mut y = Vec::with_capacity(examples.len() * 4 * bones.len());
        for &e in examples {
            for &b in &bones {
                let q = rotations[e][b as usize];
                let q = match relative_to {
                    // Rotation from pose i's bone orientation to example e's (HZY11 §5.1.2),
                    // on the hemisphere of the identity.
                    Some(i) => {
                        let r = q * rotations[i][b as usize].inverse();
                        if r.w < 0.0 { -r } else { r }
                    }
                    None => q,
                };
                y.extend_from_slice(&Vec4::from(q).to_array());
            }
        }
        y
    };
    let regression = if options.method.pose_local() {
        let poses = (0..n)
            .map(|i| {
                let neighbours = nearest_examples(&x, dim, i, options.kp.clamp(1, n));
                let xs: Vec<f32> = neighbours
                    .iter()
                    .flat_map(|&l| x[l * dim..(l + 1) * dim].iter().copied())
                    .collect();
                let y = quat_rows(&neighbours, Some(i));
                let model = kcca::fit_kcca_per_block(&xs, dim, &y, 4, kernel, &options.kcca);
                PoseModel {
                    neighbours: neighbours.iter().map(|&l| l as u32).collect(),
                    operator: to_operator(model),
                    base: bones.iter().map(|&b| rotations[i][b as usize]).collect(),
                }
            })
            .collect();
        GroupRegression::PoseLocal(poses)
    } else {
        let all: Vec<usize> = (0..n).collect();
        let y = quat_rows(&all, None);
        let model = match options.method {
            Method::Rbf => kcca::fit_rbf(&x, dim, &y, 4 * bones.len(), kernel, options.rbf_ridge),
            _ => kcca::fit_kcca_per_block(&x, dim, &y, 4, kernel, &options.kcca),
        };
        GroupRegression::Global(to_operator(model))
    };
    ControlGroup {
        controls,
        bones,
        kernel,
        heat_sigma: heat_sigma(&x, dim, sigma),
        inputs: x,
        regression,
    }
}

fn to_operator(model: LinearModel) -> LinearOperator {
    LinearOperator {
        rows: model.d_out,
        cols: model.n,
        m: model.m,
        b: model.b,
    }
}

/// The `k` examples nearest to example `i` in input space (itself first).
fn nearest_examples(x: &[f32], dim: usize, i: usize, k: usize) -> Vec<usize> {
    let n = x.len() / dim;
    let xi = &x[i * dim..(i + 1) * dim];
    let mut d: Vec<(f32, usize)> = (0..n)
        .map(|l| {
            (
                x[l * dim..(l + 1) * dim]
                    .iter()
                    .zip(xi)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f32>(),
                l,
            )
        })
        .collect();
    d.sort_by(|a, b| {
        a.0.total_cmp(&b.0)
            .then((a.1 != i).cmp(&(b.1 != i)))
            .then(a.1.cmp(&b.1))
    });
    d.into_iter().take(k).map(|(_, l)| l).collect()
}

/// Puts every bone's quaternions on one hemisphere (q and -q are one rotation; regression
/// needs one continuous representative): the hemisphere of their average direction, the
/// principal eigenvector of `sum q q^T` (Markley et al. 2007).
pub fn align_signs(rotations: &[Vec<Quat>], bones: usize) -> Vec<Vec<Quat>> {
    let mut out = rotations.to_vec();
    for b in 0..bones {
        let mut s = nalgebra::Matrix4::<f64>::zeros();
        for frame in rotations {
            let q = frame[b];
            let v = nalgebra::Vector4::new(q.x as f64, q.y as f64, q.z as f64, q.w as f64);
            s += v * v.transpose();
        }
        let eig = s.symmetric_eigen();
        let (k, _) =
            eig.eigenvalues
                .iter()
                .enumerate()
                .fold(
                    (0, f64::NEG_INFINITY),
                    |acc, (i, &l)| if l > acc.1 { (i, l) } else { acc },
                );
        let axis = eig.eigenvectors.column(k);
        let mut axis = Vec4::new(
            axis[0] as f32,
            axis[1] as f32,
            axis[2] as f32,
            axis[3] as f32,
        );
        // Prefer the identity's hemisphere for the axis itself (rest-relative rotations).
        if axis.w < 0.0 {
            axis = -axis;
        }
        for frame in out.iter_mut() {
            if Vec4::from(frame[b]).dot(axis) < 0.0 {
                frame[b] = -frame[b];
            }
        }
    }
    out
}

/// Width of the pose-space heat kernel (HZY11 eq. 2, where sigma is left open): the RMS
/// distance from each example to its nearest other example. On the scale of the gaps between
/// poses, a frame equal to an example is dominated by that example's own model (which was
/// trained on it), while frames between poses still blend their neighbours smoothly. The
/// regression width `fallback` (spread of all examples) is used when examples coincide.
fn heat_sigma(x: &[f32], dim: usize, fallback: f32) -> f32 {
    let n = x.len() / dim;
    if n < 2 {
        return fallback;
    }
    let mut sum = 0.0f64;
    for i in 0..n {
        let xi = &x[i * dim..(i + 1) * dim];
        let nearest = (0..n)
            .filter(|&l| l != i)
            .map(|l| {
                x[l * dim..(l + 1) * dim]
                    .iter()
                    .zip(xi)
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum::<f32>()
            })
            .fold(f32::INFINITY, f32::min);
        sum += nearest as f64;
    }
    let s = (sum / n as f64).sqrt() as f32;
    if s > 0.0 && s.is_finite() {
        s
    } else {
        fallback
    }
}

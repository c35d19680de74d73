//! Bone-level refinement (issue 20): the control points as constraints, the regression as a
//! prior. After the regression predicts the bone rotations `R^_b` (FKY08 §4) and eq. 11 places
//! the translations, a few local-global iterations lower
//!
//! ```text
//! E(R, t) = sum_k |(v_k0 - v_k1) - e_k|^2 + beta sum_l |v_{i_l} - c_l|^2 + sum_b lambda_b |R_b - R^_b|_F^2
//!   v_i = sum_b w_ib (R_b v_i^0 + t_b),   e_k = sum_b R_b a_kb          (FKY08 eq. 11's terms)
//! ```
//!
//! - **global** (translations, rotations fixed): eq. 11 itself, the prefactored
//!   [`TranslationSolver`] (the prior does not involve `t`), its exact minimiser;
//! - **local** (rotations, each bone turning about its own pivot): a bone's transform is
//!   written `x -> R_b (x - p_b) + s_b`, so `t_b = s_b - R_b p_b`, with `p_b` the bone's
//!   weighted centroid in the rest pose (`sum_i w_ib v_i^0 / sum_i w_ib`), and the local step
//!   holds every `s_b` (where the pivot goes) while it turns the rotations. Every residual of
//!   eq. 11 is linear in the rotations, `u = sum_b R_b x_b + sum_b d_b s_b + y` with
//!   `x_b = (the rest-pose coefficient of R_b) - d_b p_b` (`d_b` the residual's translation
//!   coefficient), and `|R_b x_b| = |x_b|` whatever `R_b`, so with the other bones fixed the
//!   energy of one bone's rotation is a Procrustes problem: maximise `tr(R_b^T M_b)`,
//!   `M_b = - sum_{a != b} R_a G_ab - sum_c s_c H_cb^T + beta sum_l c_l q_lb^T + lambda_b R^_b`
//!   with `G_ab = sum x_a x_b^T` (pairs of bones sharing a residual), `H_cb = sum d_c x_b`
//!   and `q_lb = w_{i_l} b (v_{i_l}^0 - p_b)`, weighted 1 for edges and `beta` for controls,
//!   all precomputed here. The bones are visited in turn, each seeing the others' latest
//!   rotations (block coordinate descent, Gauss-Seidel order), so a local step costs one 3x3
//!   product per bone pair of the eq. 11 pattern, independent of the vertex and edge counts
//!   (like the solve itself).
//!
//! *Why the pivots* (issue 42): the energy is the same whatever point a bone turns about, but
//! the descent is not. Turning a bone about the origin with its translation held swings its
//! vertices by `|R - I| |v|`, far from where its neighbours and the control points hold them,
//! so each local step could only turn bones a little, and 20 iterations left the horse's
//! far-from-the-examples poses almost where the regression put them (LOO of the horse's
//! `poses/` with 8 control points: refined 0.0581 against the regression's 0.0582, from rest
//! 0.1251). Turning about the centroid moves the bone's vertices least for a given turn, the
//! split of a rigid motion into a rotation about the centroid and a translation that makes
//! the least-squares fits of Kabsch and of ARAP's local step (Sorkine and Alexa, "As-rigid-
//! as-possible surface modeling", SGP 2007) decouple; with it the same 20 iterations reach
//! 0.0507 (from rest 0.0767), BENCHMARKS.md "Poses far from few examples". It also makes the
//! iterates independent of where the mesh lies (tested): moving the mesh and its controls
//! moves the result and turns no rotation.
//!
//! Each bone's rotation is the polar factor of `M_b`, found by Müller et al.'s iteration
//! ("A robust method to extract the rotational part of deformations", MIG 2016) warm-started
//! at the current one, and kept only where it does not lower `tr(R^T M_b)`. So no bone's
//! update raises the energy, and the global step is exact: `E` falls monotonically (tested
//! against a dense evaluation of `E`).
//!
//! `lambda_b = strength * tr(G_bb) / 3`: the prior is measured against the bone's own data
//! term, so one `strength` means the same on every bone and mesh.

use std::collections::BTreeMap;

use glam::{DMat3, DQuat, DVec3, Mat3A, Quat, Vec3, Vec3A};

use super::edge_skin::EdgeSkin;
use super::skin::SkinWeights;
use super::translations::{TranslationError, TranslationScratch, TranslationSolver, influences};

/// Column-compressed per-bone lists.
#[derive(Clone, Debug, Default)]
struct Cols<T> {
    ptr: Vec<usize>,
    idx: Vec<u32>,
    val: Vec<T>,
}

impl<T: Copy> Cols<T> {
    fn from_map(bones: usize, map: &BTreeMap<(u32, u32), T>) -> Self {
        // Keys are (column b, row a): sorted by column.
        let mut c = Cols {
            ptr: vec![0],
            idx: Vec::with_capacity(map.len()),
            val: Vec::with_capacity(map.len()),
        };
        let mut it = map.iter().peekable();
        for b in 0..bones as u32 {
            while let Some(&(&(col, a), &v)) = it.peek() {
                if col != b {
                    break;
                }
                c.idx.push(a);
                c.val.push(v);
                it.next();
            }
            c.ptr.push(c.idx.len());
        }
        c
    }

    /// The same lists with every value converted by `f`.
    fn map<U>(self, f: impl Fn(T) -> U) -> Cols<U> {
        Cols {
            ptr: self.ptr,
            idx: self.idx,
            val: self.val.into_iter().map(f).collect(),
        }
    }

    fn col(&self, b: usize) -> impl Iterator<Item = (usize, &T)> {
        let r = self.ptr[b]..self.ptr[b + 1];
        self.idx[r.clone()]
            .iter()
            .map(|&i| i as usize)
            .zip(&self.val[r])
    }
}

/// The precomputed local step of one mesh, rig, edge skin, controls and `beta` (module docs).
#[derive(Clone, Debug)]
pub struct BoneRefiner {
    bones: usize,
    /// `(G_ab, H_ab)` by column `b`, one entry per bone pair sharing a residual (`G_bb` is
    /// kept but unused: a bone's own term cancels in `M_b`). Accumulated in f64, stored in
    /// f32 SIMD form: the 3x3 products of the local step are its cost (module docs).
    pairs: Cols<(Mat3A, Vec3A)>,
    /// `q_lb`, by column `b` (rows: control points).
    q: Cols<Vec3A>,
    /// `tr(G_bb) / 3`.
    scale: Vec<f64>,
    /// `p_b`, each bone's pivot: its weighted centroid in the rest pose (module docs).
    pivots: Vec<Vec3A>,
}

/// One residual's bones: `(bone, x_b, d_b)`.
type Residual = Vec<(u32, DVec3, f64)>;

fn add(r: &mut Residual, b: u32, x: DVec3, d: f64) {
    match r.iter_mut().find(|e| e.0 == b) {
        Some(e) => {
            e.1 += x;
            e.2 += d;
        }
        None => r.push((b, x, d)),
    }
}

impl BoneRefiner {
    /// Precomputes the local step for the same inputs as [`TranslationSolver::new`] (which
    /// checks them; build that first).
    pub fn new(
        rest: &[Vec3],
        edges: &[[u32; 2]],
        vertex_skin: &SkinWeights,
        edge_skin: &EdgeSkin,
        control_vertices: &[u32],
        bone_count: usize,
        beta: f32,
    ) -> BoneRefiner {
        let beta = beta as f64;
        let pivots = pivots(rest, vertex_skin, bone_count);
        let mut pairs: BTreeMap<(u32, u32), (DMat3, DVec3)> = BTreeMap::new();
        let mut q: BTreeMap<(u32, u32), DVec3> = BTreeMap::new();
        let mut r: Residual = Vec::new();
        let mut accumulate = |r: &mut Residual, weight: f64| {
            // The rest-pose coefficients turned about the pivots: x_b - d_b p_b.
            for (b, x, d) in r.iter_mut() {
                *x -= pivots[*b as usize] * *d;
            }
            for &(b, xb, _) in r.iter() {
                if xb == DVec3::ZERO {
                    continue;
                }
                for &(a, xa, da) in r.iter() {
                    let e = pairs.entry((b, a)).or_insert((DMat3::ZERO, DVec3::ZERO));
                    e.0 += outer(xa, xb) * weight;
                    e.1 += xb * (da * weight);
                }
            }
        };
        for (k, &[i0, i1]) in edges.iter().enumerate() {
            r.clear();
            let (v0, v1) = (rest[i0 as usize].as_dvec3(), rest[i1 as usize].as_dvec3());
            // (v_k0 - v_k1) - e_k = sum_b R_b (w_k0b v0 - w_k1b v1 - a_kb) + sum_b d_kb t_b.
            for (b, w) in influences(vertex_skin, i0 as usize) {
                add(&mut r, b, v0 * w, w);
            }
            for (b, w) in influences(vertex_skin, i1 as usize) {
                add(&mut r, b, -v1 * w, -w);
            }
            let (bones, vectors) = edge_skin.edge(k);
            for (&b, a) in bones.iter().zip(vectors) {
                if *a != Vec3::ZERO {
                    add(&mut r, b, -a.as_dvec3(), 0.0);
                }
            }
            accumulate(&mut r, 1.0);
        }
        for (l, &i) in control_vertices.iter().enumerate() {
            r.clear();
            let v = rest[i as usize].as_dvec3();
            // v_i - c_l = sum_b R_b (w_ib v_i^0) + sum_b w_ib t_b - c_l.
            for (b, w) in influences(vertex_skin, i as usize) {
                add(&mut r, b, v * w, w);
                *q.entry((b, l as u32)).or_insert(DVec3::ZERO) +=
                    (v - pivots[b as usize]) * (w * beta);
            }
            accumulate(&mut r, beta);
        }
        let scale = (0..bone_count as u32)
            .map(|b| {
                pairs
                    .get(&(b, b))
                    .map_or(0.0, |(c, _)| (c.x_axis.x + c.y_axis.y + c.z_axis.z) / 3.0)
            })
            .collect();
        BoneRefiner {
            bones: bone_count,
            pairs: Cols::from_map(bone_count, &pairs)
                .map(|(g, h)| (Mat3A::from(g.as_mat3()), Vec3A::from(h.as_vec3()))),
            q: Cols::from_map(bone_count, &q).map(|v| Vec3A::from(v.as_vec3())),
            scale,
            pivots: pivots.iter().map(|p| Vec3A::from(p.as_vec3())).collect(),
        }
    }

    /// Number of bones.
    pub fn bone_count(&self) -> usize {
        self.bones
    }

    /// The prior weight of bone `b` for `strength` (module docs).
    pub fn prior_weight(&self, b: usize, strength: f64) -> f64 {
        strength * self.scale[b]
    }

    /// One local step: every bone's rotation in turn, in place in `r` (f64, and its f32
    /// copy `r32`, which the products read), with the pivots' places `s` held and the prior
    /// `r_hat` at `strength` (module docs).
    fn local_step(
        &self,
        r: &mut [DMat3],
        r32: &mut [Mat3A],
        s: &[Vec3A],
        controls: &[Vec3],
        r_hat: &[DMat3],
        strength: f64,
    ) {
        for b in 0..self.bones {
            let mut m = Mat3A::ZERO;
            for (a, (gab, hab)) in self.pairs.col(b) {
                if a != b {
                    m -= r32[a] * *gab;
                }
                m -= outer32(s[a], *hab);
            }
            for (l, qlb) in self.q.col(b) {
                m += outer32(Vec3A::from(controls[l]), *qlb);
            }
            let mut m = m.as_dmat3();
            if strength > 0.0 {
                m += r_hat[b] * self.prior_weight(b, strength);
            }
            r[b] = best_rotation(&m, r[b]);
            r32[b] = Mat3A::from(r[b].as_mat3());
        }
    }

    /// `iterations` local-global rounds from `rotations` (the regression's, also the prior
    /// `R^` unless `prior` is given), with the controls; writes the refined rotations back into
    /// `rotations` and the translations into `translations`. With `iterations == 0` this is
    /// eq. 11 on `rotations`. Allocation-free with a [`RefineScratch`] sized for the rig.
    ///
    /// # Errors
    /// The translation solve's; `rotations` and `translations` are then untouched.
    #[allow(clippy::too_many_arguments)]
    pub fn refine(
        &self,
        solver: &TranslationSolver,
        rotations: &mut [Quat],
        prior: Option<&[Quat]>,
        strength: f64,
        controls: &[Vec3],
        iterations: usize,
        scratch: &mut RefineScratch,
        translations: &mut [Vec3],
    ) -> Result<(), TranslationError> {
        scratch.prepare(self.bones);
        let RefineScratch {
            r,
            r32,
            r_hat,
            t32,
            s32,
            q32,
            solve,
        } = scratch;
        for ((m, m32), q) in r.iter_mut().zip(r32.iter_mut()).zip(rotations.iter()) {
            *m = DMat3::from_quat(q.as_dquat().normalize());
            *m32 = Mat3A::from(m.as_mat3());
        }
        match prior {
            Some(p) => {
                for (m, q) in r_hat.iter_mut().zip(p) {
                    *m = DMat3::from_quat(q.as_dquat().normalize());
                }
            }
            None => r_hat.copy_from_slice(r),
        }
        q32.copy_from_slice(rotations);
        solver.solve(q32, controls, solve, t32)?;
        for _ in 0..iterations {
            // Where the pivots are now: s_b = t_b + R_b p_b.
            for (((s, t), m), p) in s32
                .iter_mut()
                .zip(t32.iter())
                .zip(r32.iter())
                .zip(&self.pivots)
            {
                *s = Vec3A::from(*t) + *m * *p;
            }
            self.local_step(r, r32, s32, controls, r_hat, strength);
            for (q, m) in q32.iter_mut().zip(r.iter()) {
                *q = DQuat::from_mat3(m).normalize().as_quat();
            }
            solver.solve(q32, controls, solve, t32)?;
        }
        rotations.copy_from_slice(q32);
        translations.copy_from_slice(t32);
        Ok(())
    }

    /// A scratch sized for this refiner.
    pub fn scratch(&self) -> RefineScratch {
        let mut s = RefineScratch::default();
        s.prepare(self.bones);
        s
    }
}

/// Per-stream buffers of [`BoneRefiner::refine`].
#[derive(Clone, Debug, Default)]
pub struct RefineScratch {
    r: Vec<DMat3>,
    r32: Vec<Mat3A>,
    r_hat: Vec<DMat3>,
    t32: Vec<Vec3>,
    s32: Vec<Vec3A>,
    q32: Vec<Quat>,
    solve: TranslationScratch,
}

impl RefineScratch {
    fn prepare(&mut self, bones: usize) {
        if self.r.len() != bones {
            self.r = vec![DMat3::IDENTITY; bones];
            self.r32 = vec![Mat3A::IDENTITY; bones];
            self.r_hat = vec![DMat3::IDENTITY; bones];
            self.t32 = vec![Vec3::ZERO; bones];
            self.s32 = vec![Vec3A::ZERO; bones];
            self.q32 = vec![Quat::IDENTITY; bones];
        }
    }
}

/// Each bone's weighted centroid in the rest pose, `sum_i w_ib v_i^0 / sum_i w_ib` (the
/// origin for a bone no vertex uses).
fn pivots(rest: &[Vec3], skin: &SkinWeights, bones: usize) -> Vec<DVec3> {
    let mut sum = vec![(DVec3::ZERO, 0.0f64); bones];
    for (i, v) in rest.iter().enumerate() {
        for (b, w) in influences(skin, i) {
            let e = &mut sum[b as usize];
            e.0 += v.as_dvec3() * w;
            e.1 += w;
        }
    }
    sum.into_iter()
        .map(|(p, w)| if w > 0.0 { p / w } else { DVec3::ZERO })
        .collect()
}

fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn outer32(a: Vec3A, b: Vec3A) -> Mat3A {
    Mat3A::from_cols(a * b.x, a * b.y, a * b.z)
}

/// `tr(R^T M)`.
fn alignment(r: &DMat3, m: &DMat3) -> f64 {
    r.x_axis.dot(m.x_axis) + r.y_axis.dot(m.y_axis) + r.z_axis.dot(m.z_axis)
}

/// Most iterations of the polar-factor search per bone and local step (warm-started at the
/// current rotation, which a local step moves little, it converges in a few).
const POLAR_ITERATIONS: usize = 4;
/// The search stops when its step is below this angle (radians).
const POLAR_TOLERANCE: f64 = 1e-7;

/// The rotation maximising `tr(R^T m)` near `start` (Müller et al. 2016), or `start` when the
/// search does not improve on it (module docs: this keeps the descent monotone).
fn best_rotation(m: &DMat3, start: DMat3) -> DMat3 {
    let mut q = DQuat::from_mat3(&start).normalize();
    for _ in 0..POLAR_ITERATIONS {
        let r = DMat3::from_quat(q);
        let omega = r.x_axis.cross(m.x_axis) + r.y_axis.cross(m.y_axis) + r.z_axis.cross(m.z_axis);
        let denom = alignment(&r, m).abs() + 1e-12;
        let omega = omega / denom;
        let w = omega.length();
        if w < 1e-12 {
            break;
        }
        q = (DQuat::from_axis_angle(omega / w, w) * q).normalize();
        if w < POLAR_TOLERANCE {
            break;
        }
    }
    let r = DMat3::from_quat(q);
    if alignment(&r, m) >= alignment(&start, m) {
        r
    } else {
        start
    }
}

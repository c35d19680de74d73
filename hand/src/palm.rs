//! The palm-control surface of LYK06 §3 ("Palm deformation"): a bicubic B-spline surface
//! that interpolates a grid of palmar skin vertices after the sweep deformation, with a few
//! of those vertices rising as the MCP joints and the thumb's CMC bend, and the palm's skin
//! bound to the surface by `(u, v, d)` (LYK06 eq. 2).
//!
//! # The interpolation grid
//!
//! The palm's parameter domain is a quadrilateral in the flat hand's `xy` plane: `u` runs
//! across the palm from the radial (index, `u = 0`) to the ulnar (little, `u = 1`) side, `v`
//! from the wrist (`v = 0`) to just proximal of the knuckles (`v = 1`); its corners are
//! placed from the skeleton's index and little MCP joints ([`PalmSurface::bind`]). At the
//! [`GRID_U`] × [`GRID_V`] = 54 nodes of a regular grid in that domain (LYK06 used 54 palm
//! vertices) the palmar skin vertex nearest in `xy` (among vertices whose normal faces
//! palmar) is the node's *interpolation vertex*. Every frame those vertices come from the
//! sweep deformation, except that the *moving* ones (LYK06 Fig. 2, red) — the row under the
//! metacarpal heads and three nodes on the thenar side, 10 in all — are also pushed palmar,
//! along the grid's local normal, by [`BULGE_HEIGHT`] × smoothstep(flexion / limit) of the
//! MCP of the finger above them (thenar: the thumb's CMC flexion). That is the palm's bulge.
//!
//! # The surface
//!
//! Uniform cubic B-spline in each direction with natural end conditions: with the data
//! `P_0..P_{n-1}` at the integer parameters, the `n + 2` control points satisfy
//! `P_k = (C_k + 4 C_{k+1} + C_{k+2}) / 6` and `C_0 - 2C_1 + C_2 = 0` at both ends, a linear
//! map `C = G P` precomputed once per direction. The surface's control net is
//! `C = G_u P G_vᵀ` (LYK06: "a set of cubic B-spline curves by interpolating these vertices
//! and then ... the palm-control surface by interpolating these curves"), 88 points, ~5 µs.
//!
//! # Binding and reconstruction (LYK06 eq. 2)
//!
//! Palm vertices are the rest vertices inside the domain with a palmar-facing normal within
//! [`PALM_DEPTH`] of the rest surface. Each is projected orthogonally onto the rest surface
//! (Gauss-Newton from the domain's bilinear inverse), giving `(u, v)`, and its offset is kept
//! in the surface frame `(T, B, N)` at `(u, v)` (`T = S_u / |S_u|`, `N` the palmar unit
//! normal, `B = N × T`): `V = S(u, v) + a T + b B + d N`. Eq. 2 is the case `a = b = 0`;
//! keeping the two tangential components makes the rest pose reconstruct exactly even where
//! the projection is clamped to the domain's border. The 16 B-spline basis values of `S`, and
//! of `S_u` and `S_v`, are precomputed per vertex (LYK06 §6: "we precompute values of the
//! B-spline basis functions for the surface parameters (u, v) of each palm vertex").
//!
//! The paper needs no blend because its surface covers exactly the palm; ours is a
//! parameter rectangle over a mesh that continues into the fingers, thenar and hypothenar,
//! so the surface result is blended with the sweep result by a weight that falls from 1 to 0
//! over the outer [`BORDER`] of the domain, hiding any seam.

use super::smoothstep;
use glam::{Vec2, Vec3};

use super::skeleton::{Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, JointLimits};
use crease_core::mesh::Mesh;

/// Interpolation nodes across the palm (radial to ulnar).
pub const GRID_U: usize = 9;
/// Interpolation nodes along the palm (wrist to knuckles).
pub const GRID_V: usize = 6;
/// How far a palm vertex may lie from the palm-control surface (metres): the palmar soft
/// tissue, not the dorsal side of the hand.
pub const PALM_DEPTH: f32 = 0.008;
/// Height of the bulge at full flexion (metres), for the row under the metacarpal heads and
/// for the thenar nodes.
pub const BULGE_HEIGHT: f32 = 0.004;
/// Width of the blend between surface and sweep result at the domain's border (parameter
/// units).
pub const BORDER: f32 = 0.15;

/// Control points per direction.
const CU: usize = GRID_U + 2;
const CV: usize = GRID_V + 2;
/// Gauss-Newton steps of the binding projection.
const PROJECTION_STEPS: usize = 8;
/// Row of the moving nodes under the metacarpal heads.
const BULGE_ROW: usize = GRID_V - 2;
/// Thenar moving nodes: column 0, these rows.
const THENAR_ROWS: [usize; 3] = [1, 2, 3];

/// Uniform cubic B-spline basis at local parameter `t` in `[0, 1]`, and its derivative.
fn basis(t: f32) -> ([f32; 4], [f32; 4]) {
    let (t2, t3) = (t * t, t * t * t);
    let s = 1.0 - t;
    (
        [
            s * s * s / 6.0,
            (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0,
            (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
            t3 / 6.0,
        ],
        [
            -s * s / 2.0,
            (3.0 * t2 - 4.0 * t) / 2.0,
            (-3.0 * t2 + 2.0 * t + 1.0) / 2.0,
            t2 / 2.0,
        ],
    )
}

/// Span and local parameter of domain parameter `u` in `[0, 1]` on a grid of `n` nodes.
fn span(u: f32, n: usize) -> (usize, f32) {
    let x = u.clamp(0.0, 1.0) * (n - 1) as f32;
    let s = (x.floor() as usize).min(n - 2);
    (s, x - s as f32)
}

/// The interpolation map `G` ((n + 2) × n, row-major) of a natural uniform cubic B-spline
/// through `n` points at the integer parameters (module docs), by Gauss-Jordan elimination
/// of the (n + 2)-square system in f64.
fn interpolation_map(n: usize) -> Vec<f32> {
    let m = n + 2;
    // Rows: end condition, n interpolation rows, end condition. Augmented with [0 | I_n | 0].
    let mut a = vec![0.0f64; m * (m + n)];
    let w = m + n;
    a[0] = 1.0;
    a[1] = -2.0;
    a[2] = 1.0;
    for k in 0..n {
        let r = k + 1;
        a[r * w + k] = 1.0 / 6.0;
        a[r * w + k + 1] = 4.0 / 6.0;
        a[r * w + k + 2] = 1.0 / 6.0;
        a[r * w + m + k] = 1.0;
    }
    let r = m - 1;
    a[r * w + n - 1] = 1.0;
    a[r * w + n] = -2.0;
    a[r * w + n + 1] = 1.0;
    for col in 0..m {
        let pivot = (col..m)
            .max_by(|&x, &y| a[x * w + col].abs().total_cmp(&a[y * w + col].abs()))
            .expect("rows");
        for j in 0..w {
            a.swap(col * w + j, pivot * w + j);
        }
        let p = a[col * w + col];
        for j in 0..w {
            a[col * w + j] /= p;
        }
        for row in 0..m {
            if row != col {
                let f = a[row * w + col];
                if f != 0.0 {
                    for j in 0..w {
                        a[row * w + j] -= f * a[col * w + j];
                    }
                }
            }
        }
    }
    (0..m)
        .flat_map(|i| (0..n).map(move |k| (i, k)))
        .map(|(i, k)| a[i * w + m + k] as f32)
        .collect()
}

/// One palm vertex bound to the surface.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PalmVertex {
    vertex: u32,
    /// First control point of the 4 × 4 support (`su`, `sv`).
    su: u8,
    sv: u8,
    bu: [f32; 4],
    dbu: [f32; 4],
    bv: [f32; 4],
    dbv: [f32; 4],
    /// Offset in the surface frame `(T, B, N)`.
    offset: Vec3,
    /// Blend weight of the surface result against the sweep result.
    weight: f32,
}

/// A moving interpolation node: which node, which degree of freedom raises it and how far.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Mover {
    node: u8,
    dof: Dof,
    /// `1 / (upper flexion limit)`.
    scale: f32,
}

/// The palm-control surface bound to a rest mesh (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PalmSurface {
    /// Interpolation vertices, node `a + GRID_U * b` at `(u_a, v_b)`.
    nodes: [u32; GRID_U * GRID_V],
    movers: Vec<Mover>,
    /// `G_u` ((GRID_U + 2) × GRID_U) and `G_v`, row-major.
    gu: Vec<f32>,
    gv: Vec<f32>,
    /// `+1` or `-1` so that `sign * (S_u × S_v)` points palmar (out of the palm).
    sign: f32,
    vertices: Vec<PalmVertex>,
}

/// The surface's control net and evaluation at one parameter.
struct Net([Vec3; CU * CV]);

impl Net {
    /// `C = G_u P G_vᵀ` from the node positions.
    fn interpolate(p: &[Vec3; GRID_U * GRID_V], gu: &[f32], gv: &[f32]) -> Net {
        let mut tmp = [Vec3::ZERO; CU * GRID_V];
        for i in 0..CU {
            for b in 0..GRID_V {
                let mut acc = Vec3::ZERO;
                for a in 0..GRID_U {
                    acc += gu[i * GRID_U + a] * p[a + GRID_U * b];
                }
                tmp[i + CU * b] = acc;
            }
        }
        let mut c = [Vec3::ZERO; CU * CV];
        for i in 0..CU {
            for j in 0..CV {
                let mut acc = Vec3::ZERO;
                for b in 0..GRID_V {
                    acc += gv[j * GRID_V + b] * tmp[i + CU * b];
                }
                c[i + CU * j] = acc;
            }
        }
        Net(c)
    }

    /// `S`, `S_u`, `S_v` (derivatives per grid step) from precomputed basis values.
    #[inline]
    fn eval(&self, pv: &PalmVertex) -> (Vec3, Vec3, Vec3) {
        let (mut s, mut su, mut sv) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
        for j in 0..4 {
            let start = pv.su as usize + CU * (pv.sv as usize + j);
            let (mut r, mut ru) = (Vec3::ZERO, Vec3::ZERO);
            for ((&c, &b), &db) in self.0[start..start + 4].iter().zip(&pv.bu).zip(&pv.dbu) {
                r += b * c;
                ru += db * c;
            }
            s += pv.bv[j] * r;
            su += pv.bv[j] * ru;
            sv += pv.dbv[j] * r;
        }
        (s, su, sv)
    }

    /// `S`, `S_u`, `S_v` at domain parameters `(u, v)`.
    fn eval_at(&self, uv: Vec2) -> (Vec3, Vec3, Vec3) {
        self.eval(&basis_vertex(uv))
    }
}

/// Basis values of domain parameters `(u, v)` (offset and weight left zero).
fn basis_vertex(uv: Vec2) -> PalmVertex {
    let (su, tu) = span(uv.x, GRID_U);
    let (sv, tv) = span(uv.y, GRID_V);
    let (bu, dbu) = basis(tu);
    let (bv, dbv) = basis(tv);
    PalmVertex {
        vertex: 0,
        su: su as u8,
        sv: sv as u8,
        bu,
        dbu,
        bv,
        dbv,
        offset: Vec3::ZERO,
        weight: 0.0,
    }
}

/// The surface frame `(T, B, N)` from the partial derivatives (`N` palmar via `sign`).
fn frame(su: Vec3, sv: Vec3, sign: f32) -> (Vec3, Vec3, Vec3) {
    let n = (sign * su.cross(sv)).normalize_or_zero();
    let t = su.normalize_or_zero();
    (t, n.cross(t), n)
}

/// The palm domain: a quadrilateral in the flat hand's `xy` plane, corners at
/// `(u, v) = (0, 0), (1, 0), (1, 1), (0, 1)`.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Domain([Vec2; 4]);

impl Domain {
    /// The palm domain of `skeleton` (module docs).
    pub(crate) fn of(skeleton: &HandSkeleton) -> Domain {
        let posed = skeleton.pose(&HandPose::FLAT);
        let xy = |j: Joint| posed.joint(j).position.truncate();
        let (index, little) = (xy(Joint::IndexMcp), xy(Joint::LittleMcp));
        let across = little - index;
        // Just proximal of the knuckles, a little inside the outer fingers' centre lines.
        let back = Vec2::new(across.y, -across.x).normalize() * (0.04 * across.length());
        let k_r = index + back + 0.04 * across;
        let k_u = little + back - 0.04 * across;
        let y0 = 0.05 * k_r.y.min(k_u.y);
        Domain([
            Vec2::new(0.7 * k_r.x, y0),
            Vec2::new(0.45 * k_u.x, y0),
            k_u,
            k_r,
        ])
    }

    /// The point of the plane at `(u, v)`.
    pub(crate) fn at(&self, uv: Vec2) -> Vec2 {
        let [a, b, c, d] = self.0;
        let bottom = a.lerp(b, uv.x);
        let top = d.lerp(c, uv.x);
        bottom.lerp(top, uv.y)
    }

    /// `(u, v)` of a point of the plane (Newton on the bilinear map; may leave `[0, 1]²`).
    fn inverse(&self, p: Vec2) -> Vec2 {
        let [a, b, c, d] = self.0;
        let mut uv = Vec2::splat(0.5);
        for _ in 0..10 {
            let r = self.at(uv) - p;
            let du = (b - a).lerp(c - d, uv.y);
            let dv = (d - a).lerp(c - b, uv.x);
            let det = du.perp_dot(dv);
            if det.abs() < 1e-12 {
                break;
            }
            uv -= Vec2::new(r.perp_dot(dv), du.perp_dot(r)) / det;
        }
        uv
    }
}

impl PalmSurface {
    /// Binds the palm of `rest` (the flat pose of `skeleton`, with its vertex normals
    /// `normals`) to a palm-control surface (module docs). Returns `None` when the mesh has
    /// no palmar vertices in the palm domain (not a hand in the skeleton's frame).
    pub fn bind(skeleton: &HandSkeleton, rest: &Mesh, normals: &[Vec3]) -> Option<PalmSurface> {
        let domain = Domain::of(skeleton);
        let palmar: Vec<usize> = (0..rest.positions.len())
            .filter(|&i| normals[i].z < -0.3)
            .collect();
        if palmar.is_empty() {
            return None;
        }
        let mut nodes = [0u32; GRID_U * GRID_V];
        for b in 0..GRID_V {
            for a in 0..GRID_U {
                let uv = Vec2::new(
                    a as f32 / (GRID_U - 1) as f32,
                    b as f32 / (GRID_V - 1) as f32,
                );
                let target = domain.at(uv);
                let best = palmar
                    .iter()
                    .copied()
                    .min_by(|&x, &y| {
                        let dx = rest.positions[x].truncate().distance_squared(target);
                        let dy = rest.positions[y].truncate().distance_squared(target);
                        dx.total_cmp(&dy)
                    })
                    .expect("non-empty");
                nodes[a + GRID_U * b] = best as u32;
            }
        }
        let gu = interpolation_map(GRID_U);
        let gv = interpolation_map(GRID_V);
        let p = nodes.map(|i| rest.positions[i as usize]);
        let net = Net::interpolate(&p, &gu, &gv);
        // Orientation: the rest palm's outward normal points to -Z.
        let (_, su, sv) = net.eval_at(Vec2::splat(0.5));
        let sign = if su.cross(sv).z < 0.0 { 1.0 } else { -1.0 };

        let limits = JointLimits::adult();
        let mut movers = Vec::new();
        let fingers = Digit::FINGERS.map(|d| skeleton.pose(&HandPose::FLAT).chain(d)[2].position);
        for a in 1..GRID_U - 1 {
            let node = a + GRID_U * BULGE_ROW;
            let x = rest.positions[nodes[node] as usize].x;
            let finger = fingers
                .iter()
                .enumerate()
                .min_by(|l, r| (l.1.x - x).abs().total_cmp(&(r.1.x - x).abs()))
                .map(|(k, _)| Digit::FINGERS[k])
                .expect("four fingers");
            let joint = finger.joints()[1];
            let dof = Dof::new(joint, DofKind::Flexion).expect("MCP flexes");
            movers.push(Mover {
                node: node as u8,
                dof,
                scale: 1.0 / limits.range(dof).1,
            });
        }
        for b in THENAR_ROWS {
            let dof = Dof::new(Joint::ThumbCmc, DofKind::Flexion).expect("CMC flexes");
            movers.push(Mover {
                node: (GRID_U * b) as u8,
                dof,
                scale: 1.0 / limits.range(dof).1,
            });
        }

        let mut vertices = Vec::new();
        for &i in &palmar {
            let v = rest.positions[i];
            let uv0 = domain.inverse(v.truncate());
            if !(0.0..=1.0).contains(&uv0.x) || !(0.0..=1.0).contains(&uv0.y) {
                continue;
            }
            // Gauss-Newton on |S(u, v) - V|² (parameters in grid steps inside eval).
            let mut uv = uv0;
            let steps = Vec2::new((GRID_U - 1) as f32, (GRID_V - 1) as f32);
            for _ in 0..PROJECTION_STEPS {
                let (s, su, sv) = net.eval_at(uv);
                let r = v - s;
                let (a11, a12, a22) = (su.dot(su), su.dot(sv), sv.dot(sv));
                let (g1, g2) = (su.dot(r), sv.dot(r));
                let det = a11 * a22 - a12 * a12;
                if det.abs() < 1e-20 {
                    break;
                }
                let delta = Vec2::new(a22 * g1 - a12 * g2, a11 * g2 - a12 * g1) / det;
                uv = (uv + delta / steps).clamp(Vec2::ZERO, Vec2::ONE);
            }
            let mut pv = basis_vertex(uv);
            let (s, su, sv) = net.eval(&pv);
            let (t, bt, n) = frame(su, sv, sign);
            let r = v - s;
            if r.dot(n).abs() > PALM_DEPTH {
                continue;
            }
            let ramp = |x: f32| smoothstep(x / BORDER);
            pv.vertex = i as u32;
            pv.offset = Vec3::new(r.dot(t), r.dot(bt), r.dot(n));
            pv.weight = ramp(uv.x) * ramp(1.0 - uv.x) * ramp(uv.y) * ramp(1.0 - uv.y);
            if pv.weight > 0.0 {
                vertices.push(pv);
            }
        }
        Some(PalmSurface {
            nodes,
            movers,
            gu,
            gv,
            sign,
            vertices,
        })
    }

    /// The interpolation vertices (mesh indices), node `a + GRID_U * b`.
    pub fn nodes(&self) -> &[u32; GRID_U * GRID_V] {
        &self.nodes
    }

    /// The moving interpolation vertices (mesh indices).
    pub fn moving_nodes(&self) -> impl Iterator<Item = u32> + '_ {
        self.movers.iter().map(|m| self.nodes[m.node as usize])
    }

    /// Mesh indices of the vertices bound to the surface.
    pub fn palm_vertices(&self) -> impl Iterator<Item = u32> + '_ {
        self.vertices.iter().map(|v| v.vertex)
    }

    /// The control net through the node positions of the sweep-deformed `positions`, the
    /// moving nodes raised for `pose` (module docs).
    fn net(&self, pose: &HandPose, positions: &[Vec3]) -> Net {
        let mut p = self.nodes.map(|i| positions[i as usize]);
        // Moving interpolation vertices rise along the grid's local palmar normal.
        let mut lift = [Vec3::ZERO; GRID_U * GRID_V];
        for m in &self.movers {
            let node = m.node as usize;
            let (a, b) = (node % GRID_U, node / GRID_U);
            let at = |a: usize, b: usize| p[a + GRID_U * b];
            let du = at((a + 1).min(GRID_U - 1), b) - at(a.saturating_sub(1), b);
            let dv = at(a, (b + 1).min(GRID_V - 1)) - at(a, b.saturating_sub(1));
            let n = (self.sign * du.cross(dv)).normalize_or_zero();
            let h = BULGE_HEIGHT * smoothstep(pose.get(m.dof) * m.scale);
            lift[node] = h * n;
        }
        for (q, l) in p.iter_mut().zip(&lift) {
            *q += *l;
        }
        Net::interpolate(&p, &self.gu, &self.gv)
    }

    /// The palm-control surface point `S(u, v)` and its palmar unit normal `N(u, v)` for the
    /// sweep-deformed `positions` posed to `pose` (before [`PalmSurface::apply`] changed
    /// them); `(u, v)` in `[0, 1]²`.
    pub fn surface_at(&self, pose: &HandPose, positions: &[Vec3], uv: Vec2) -> (Vec3, Vec3) {
        let (s, su, sv) = self.net(pose, positions).eval_at(uv);
        (s, frame(su, sv, self.sign).2)
    }

    /// Replaces the palm vertices of a sweep-deformed mesh `positions` (posed to `pose`) by
    /// the palm-control surface reconstruction, blended at the border (module docs).
    /// Allocates nothing.
    pub fn apply(&self, pose: &HandPose, positions: &mut [Vec3]) {
        let net = self.net(pose, positions);
        for pv in &self.vertices {
            let (s, su, sv) = net.eval(pv);
            let (t, b, n) = frame(su, sv, self.sign);
            // LYK06 eq. 2 (with the tangential part of the offset; module docs)
            let on_surface = s + pv.offset.x * t + pv.offset.y * b + pv.offset.z * n;
            let out = &mut positions[pv.vertex as usize];
            *out = out.lerp(on_surface, pv.weight);
        }
    }
}

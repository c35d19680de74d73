//! The control sweeps of LYK06 §2 ("Control sweeps", "Binding the skin mesh vertices",
//! "Blending sweeps"): one sweep per digit from the wrist to the tip, the rest skin bound to
//! them, and the per-frame deformation.
//!
//! # A sweep ([`Sweep`])
//!
//! A continuously moving frame built from one digit's posed joint chain (wrist, CMC, MCP, PIP,
//! DIP | IP, tip; see [`super::skeleton`]). Key frames: the wrist, the tip, and around every
//! interior joint three keys `B` (on the incoming bone, `h` before the joint), `J` (the joint
//! centre) and `A` (on the outgoing bone, `h` after it), `h` = [`KNUCKLE_HALF_WIDTH`] capped at
//! [`KNUCKLE_MAX_FRACTION`] of the shorter bone. These are LYK06's "additional frames to smooth
//! the sharp change of orientation over the knuckles": the bend stays inside `[B, A]`.
//!
//! - Trajectory `T(s)`: a C1 cubic Hermite spline through the key positions with
//!   Catmull-Rom (finite-difference) tangents on chord-length knots. The key positions lie on
//!   rigid bones at fixed distances from the joints, so the knots are the same in every pose.
//! - Orientation `Q(s)`: constant (the bone's rotation) between `A` of one joint and `B` of the
//!   next; across a knuckle window `[B, A]` one slerp from the incoming to the outgoing bone
//!   rotation at constant angular speed (so `Q` is continuous, its angular velocity piecewise
//!   constant). Smoothstep easing would make `Q` C1 but raises the peak angular speed 1.5x,
//!   which folds the palmar skin of a sharply bent knuckle (measured: the section through a
//!   90° PIP grew 34%; with the plain slerp it stays within 1%).
//! - Parameter: `s` is the chord length along the keys in metres (`0` at the wrist, [`Sweep::length`]
//!   at the tip); [`Sweep::frame_at`] takes the normalised `t = s / length` in `[0, 1]`.
//!
//! # Binding (LYK06 eq. 1)
//!
//! A rest vertex `v` is projected onto the rest sweep (closest point: dense sampling, then
//! guarded Newton steps on `(T(s) - v)·T'(s) = 0`), which gives `t`. Instead of the polar
//! coordinates `(θ, d)` in the cross-section plane we store the offset `o = R(t)⁻¹ (v - T(t))`
//! in the sweep frame: inside the sweep its axial component is ~0 and `(θ, d)` are the polar
//! coordinates of its two other components (`local X, Z`; the sweep runs along local `+Y`);
//! keeping the (small) axial component too makes vertices beyond the tip or behind the wrist,
//! where the projection is clamped, reconstruct exactly. Reconstruction: `V = R'(t) o + T'(t)`.
//!
//! # Blending
//!
//! Every vertex is bound to all five sweeps and weighted by a relative-distance fall-off
//! (LYK06: "weights initialized to correspond to the relative distances between a vertex and
//! its controlling sweeps"): with `d*` the distance to the nearest sweep, a sweep at distance
//! `d` gets weight 1 inside the cylinder `d - d* <= a`, 0 beyond `d - d* >= a + w`, and a
//! smoothstep fall-off between ([`BAND_INNER`], [`BAND_WIDTH`]). Where the nearest sweep's
//! projection lies beyond its MCP joint the band shrinks to zero over [`FINGER_RAMP`], so
//! finger and thumb vertices are bound to their own sweep only, while palm and back vertices
//! blend several. Weights are normalised to sum to one; influences of weight 0 are dropped.
//! (LYK06's cylinder/cone radii are absolute; a relative band needs no per-digit radii.)

use glam::{Quat, Vec3};

use super::skeleton::{Digit, HandPose, HandSkeleton, JointFrame, MAX_CHAIN, PosedSkeleton};
use crate::mesh::Mesh;

/// Most key frames of one sweep: wrist, tip, and three around each interior joint.
pub const MAX_KEYS: usize = 2 + 3 * (MAX_CHAIN - 2);
/// Half-width of a knuckle window (metres): the `B` and `A` keys sit this far from the joint.
/// About a finger's radius: the palmar skin (at about that radius from the sweep) then turns
/// slower than the sweep advances even at a 90° bend, so it compresses instead of folding.
pub const KNUCKLE_HALF_WIDTH: f32 = 0.010;
/// Cap of the knuckle half-width as a fraction of the shorter adjacent bone (below 0.5 so
/// the windows of the two ends of a bone never overlap).
pub const KNUCKLE_MAX_FRACTION: f32 = 0.45;
/// Full-weight band of the relative-distance fall-off (metres beyond the nearest sweep).
pub const BAND_INNER: f32 = 0.003;
/// Width of the smooth fall-off beyond [`BAND_INNER`] (metres).
pub const BAND_WIDTH: f32 = 0.015;
/// Fall-off width kept on the digits (metres): only vertices nearly equidistant from two
/// sweeps, i.e. in the webs between fused digits, blend both; this keeps the weights
/// continuous across a web instead of tearing it where the nearest sweep changes.
pub const WEB_WIDTH: f32 = 0.002;
/// Arc length past the MCP centre over which a vertex becomes exclusive to its digit (metres).
pub const FINGER_RAMP: f32 = 0.015;
/// Chain index of the MCP joint (wrist 0, CMC 1, MCP 2) for every digit.
const MCP_CHAIN_INDEX: usize = 2;
/// Samples per key interval for the initial closest-point search.
const PROJECTION_SAMPLES: usize = 8;
/// Newton refinement steps of the closest-point search.
const NEWTON_STEPS: usize = 6;

/// A position and orientation on a sweep (local `+Y` along the sweep, `+Z` dorsal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SweepFrame {
    /// `T(t)`, metres.
    pub position: Vec3,
    /// `Q(t)`, a unit quaternion.
    pub rotation: Quat,
}

/// One control sweep (module docs): key positions, Hermite tangents, chord-length knots and the
/// bone rotations. Plain data, `Copy`, built and evaluated without allocation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sweep {
    positions: [Vec3; MAX_KEYS],
    tangents: [Vec3; MAX_KEYS],
    knots: [f32; MAX_KEYS],
    bones: [Quat; MAX_CHAIN - 1],
    keys: usize,
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Sweep {
    /// The sweep through a joint chain (wrist first, tip last; 2..=[`MAX_CHAIN`] frames).
    ///
    /// # Panics
    /// If the chain has fewer than 2 or more than [`MAX_CHAIN`] frames.
    pub fn from_chain(chain: &[JointFrame]) -> Sweep {
        let n = chain.len();
        assert!((2..=MAX_CHAIN).contains(&n), "chain of {n} frames");
        let mut s = Sweep {
            positions: [Vec3::ZERO; MAX_KEYS],
            tangents: [Vec3::ZERO; MAX_KEYS],
            knots: [0.0; MAX_KEYS],
            bones: [Quat::IDENTITY; MAX_CHAIN - 1],
            keys: 0,
        };
        for (bone, frame) in s.bones.iter_mut().zip(&chain[..n - 1]) {
            *bone = frame.rotation;
        }
        let push = |s: &mut Sweep, p: Vec3| {
            s.positions[s.keys] = p;
            s.keys += 1;
        };
        push(&mut s, chain[0].position);
        for j in 1..n - 1 {
            let p = chain[j].position;
            let incoming = p - chain[j - 1].position;
            let outgoing = chain[j + 1].position - p;
            let h = KNUCKLE_HALF_WIDTH
                .min(KNUCKLE_MAX_FRACTION * incoming.length().min(outgoing.length()));
            push(&mut s, p - h * incoming.normalize_or_zero());
            push(&mut s, p);
            push(&mut s, p + h * outgoing.normalize_or_zero());
        }
        push(&mut s, chain[n - 1].position);
        // Chord-length knots, kept strictly increasing for degenerate (zero-length) bones.
        for k in 1..s.keys {
            let d = (s.positions[k] - s.positions[k - 1]).length().max(1e-6);
            s.knots[k] = s.knots[k - 1] + d;
        }
        // Catmull-Rom tangents (d/ds), one-sided at the ends.
        for k in 0..s.keys {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(s.keys - 1));
            s.tangents[k] = (s.positions[b] - s.positions[a]) / (s.knots[b] - s.knots[a]);
        }
        s
    }

    /// The sweep of `digit` in a posed skeleton.
    pub fn of_digit(posed: &PosedSkeleton, digit: Digit) -> Sweep {
        Sweep::from_chain(posed.chain(digit))
    }

    /// Total parameter length (chord length of the keys, metres).
    pub fn length(&self) -> f32 {
        self.knots[self.keys - 1]
    }

    /// Arc-length parameter of chain joint `j` (0 = wrist, 1 = CMC, 2 = MCP, ..., last = tip):
    /// the `t_J * length` of LYK06's joint tests.
    pub fn joint_arc(&self, j: usize) -> f32 {
        if j == 0 {
            0.0
        } else {
            self.knots[(3 * j - 1).min(self.keys - 1)]
        }
    }

    /// Key interval containing arc length `s` (clamped).
    fn segment(&self, s: f32) -> usize {
        let last = self.keys - 2;
        (0..last).find(|&i| s < self.knots[i + 1]).unwrap_or(last)
    }

    /// Position, first and second derivative (d/ds) at arc length `s` in interval `i`.
    fn trajectory(&self, i: usize, s: f32) -> (Vec3, Vec3, Vec3) {
        let (k0, k1) = (self.knots[i], self.knots[i + 1]);
        let dt = k1 - k0;
        let u = (s - k0) / dt;
        let (p0, p1) = (self.positions[i], self.positions[i + 1]);
        let (m0, m1) = (self.tangents[i] * dt, self.tangents[i + 1] * dt);
        let (u2, u3) = (u * u, u * u * u);
        let p = (2.0 * u3 - 3.0 * u2 + 1.0) * p0
            + (u3 - 2.0 * u2 + u) * m0
            + (-2.0 * u3 + 3.0 * u2) * p1
            + (u3 - u2) * m1;
        let d1 = ((6.0 * u2 - 6.0 * u) * (p0 - p1)
            + (3.0 * u2 - 4.0 * u + 1.0) * m0
            + (3.0 * u2 - 2.0 * u) * m1)
            / dt;
        let d2 = ((12.0 * u - 6.0) * (p0 - p1) + (6.0 * u - 4.0) * m0 + (6.0 * u - 2.0) * m1)
            / (dt * dt);
        (p, d1, d2)
    }

    /// Orientation at arc length `s` in interval `i` (module docs).
    fn orientation(&self, i: usize, s: f32) -> Quat {
        if i == 0 {
            return self.bones[0];
        }
        let (j, r) = (i.div_ceil(3), (i + 2) % 3);
        if r == 2 {
            return self.bones[j];
        }
        // Interval starts at B_j (r == 0) or J_j (r == 1): inside the knuckle window of joint j.
        let (kb, ka) = (self.knots[3 * j - 2], self.knots[3 * j]);
        let u = ((s - kb) / (ka - kb)).clamp(0.0, 1.0);
        self.bones[j - 1].slerp(self.bones[j], u)
    }

    /// Frame at arc length `s` (clamped to `[0, length]`).
    pub fn frame_at_arc(&self, s: f32) -> SweepFrame {
        let s = s.clamp(0.0, self.length());
        self.frame_in(self.segment(s), s)
    }

    /// Frame at arc length `s` known to lie in key interval `i`.
    fn frame_in(&self, i: usize, s: f32) -> SweepFrame {
        SweepFrame {
            position: self.trajectory(i, s).0,
            rotation: self.orientation(i, s),
        }
    }

    /// Frame at normalised parameter `t` in `[0, 1]` (wrist to tip).
    pub fn frame_at(&self, t: f32) -> SweepFrame {
        self.frame_at_arc(t * self.length())
    }

    /// Arc length of the point of the sweep closest to `v`, and that distance.
    pub fn project(&self, v: Vec3) -> (f32, f32) {
        let mut best_s = 0.0;
        let mut best_d2 = f32::INFINITY;
        for i in 0..self.keys - 1 {
            for k in 0..PROJECTION_SAMPLES {
                let s = self.knots[i]
                    + (self.knots[i + 1] - self.knots[i]) * k as f32 / PROJECTION_SAMPLES as f32;
                let d2 = (self.trajectory(i, s).0 - v).length_squared();
                if d2 < best_d2 {
                    (best_s, best_d2) = (s, d2);
                }
            }
        }
        let end = self.length();
        let d2 = (self.positions[self.keys - 1] - v).length_squared();
        if d2 < best_d2 {
            (best_s, best_d2) = (end, d2);
        }
        for _ in 0..NEWTON_STEPS {
            let (p, d1, d2) = self.trajectory(self.segment(best_s), best_s);
            let f = (p - v).dot(d1);
            let df = d1.length_squared() + (p - v).dot(d2);
            if df <= 0.0 {
                break;
            }
            let s = (best_s - f / df).clamp(0.0, end);
            let dist2 = (self.trajectory(self.segment(s), s).0 - v).length_squared();
            if dist2 >= best_d2 {
                break;
            }
            (best_s, best_d2) = (s, dist2);
        }
        (best_s, best_d2.sqrt())
    }
}

/// One sweep's hold on a vertex: LYK06 eq. 1 parameters and the blend weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Influence {
    /// The digit whose sweep this is.
    pub digit: Digit,
    /// Normalised blend weight (a vertex's weights sum to one).
    pub weight: f32,
    /// Sweep parameter `t` in `[0, 1]`.
    pub t: f32,
    /// Offset of the vertex in the rest sweep frame at `t` (stands for `(θ, d)`; module docs).
    pub offset: Vec3,
}

/// A vertex's influences: `count` used entries of fixed arrays (no per-vertex allocation).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Binding {
    count: u8,
    digit: [u8; 5],
    weight: [f32; 5],
    /// Arc length on the rest sweep (knots are the same in every pose; module docs).
    arc: [f32; 5],
    /// Key interval containing `arc`.
    segment: [u8; 5],
    offset: [Vec3; 5],
}

/// A rest skin bound to the five control sweeps of a skeleton (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct SweepHand {
    skeleton: HandSkeleton,
    /// Rest length of each digit's sweep (for the normalised `t`).
    lengths: [f32; 5],
    bindings: Vec<Binding>,
}

impl SweepHand {
    /// Binds every vertex of `rest` (in the skeleton's flat rest pose) to the sweeps of
    /// `skeleton` (LYK06 eq. 1 and the blending weights; module docs).
    pub fn bind(skeleton: &HandSkeleton, rest: &Mesh) -> SweepHand {
        let posed = skeleton.pose(&HandPose::FLAT);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        let mcp = sweeps.map(|s| s.joint_arc(MCP_CHAIN_INDEX));
        let bindings = rest
            .positions
            .iter()
            .map(|&v| {
                let proj = sweeps.map(|s| s.project(v));
                let (nearest, &(s_near, d_near)) = proj
                    .iter()
                    .enumerate()
                    .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
                    .expect("five sweeps");
                let open = 1.0 - smoothstep((s_near - mcp[nearest]) / FINGER_RAMP);
                let inner = BAND_INNER * open;
                let width = WEB_WIDTH + (BAND_WIDTH - WEB_WIDTH) * open;
                let mut b = Binding {
                    count: 0,
                    digit: [0; 5],
                    weight: [0.0; 5],
                    arc: [0.0; 5],
                    segment: [0; 5],
                    offset: [Vec3::ZERO; 5],
                };
                let mut total = 0.0;
                for (k, (sweep, &(s, d))) in sweeps.iter().zip(&proj).enumerate() {
                    let x = d - d_near;
                    let w = if k == nearest || x <= inner {
                        1.0
                    } else if x >= inner + width {
                        0.0
                    } else {
                        1.0 - smoothstep((x - inner) / width)
                    };
                    if w <= 0.0 {
                        continue;
                    }
                    let segment = sweep.segment(s);
                    let frame = sweep.frame_in(segment, s);
                    let c = b.count as usize;
                    b.digit[c] = k as u8;
                    b.weight[c] = w;
                    b.arc[c] = s;
                    b.segment[c] = segment as u8;
                    b.offset[c] = frame.rotation.inverse() * (v - frame.position);
                    b.count += 1;
                    total += w;
                }
                for w in &mut b.weight[..b.count as usize] {
                    *w /= total;
                }
                b
            })
            .collect();
        SweepHand {
            skeleton: skeleton.clone(),
            lengths: sweeps.map(|s| s.length()),
            bindings,
        }
    }

    /// Number of bound vertices.
    pub fn vertex_count(&self) -> usize {
        self.bindings.len()
    }

    /// The skeleton the skin is bound to.
    pub fn skeleton(&self) -> &HandSkeleton {
        &self.skeleton
    }

    /// The influences of vertex `i` (weights normalised, non-zero).
    pub fn influences(&self, i: usize) -> impl Iterator<Item = Influence> + '_ {
        let b = &self.bindings[i];
        (0..b.count as usize).map(move |k| Influence {
            digit: Digit::ALL[b.digit[k] as usize],
            weight: b.weight[k],
            t: b.arc[k] / self.lengths[b.digit[k] as usize],
            offset: b.offset[k],
        })
    }

    /// Deforms the bound skin to `pose`, writing one position per vertex into `out`:
    /// `V = Σ_k w_k (R_k(t_k) o_k + T_k(t_k))` (LYK06 eq. 1, blended). Allocates nothing.
    ///
    /// # Panics
    /// If `out.len()` differs from [`SweepHand::vertex_count`].
    pub fn deform_into(&self, pose: &HandPose, out: &mut [Vec3]) {
        assert_eq!(out.len(), self.bindings.len(), "output length");
        let mut posed = PosedSkeleton::default();
        self.skeleton.pose_into(pose, &mut posed);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        for (o, b) in out.iter_mut().zip(&self.bindings) {
            let mut v = Vec3::ZERO;
            for k in 0..b.count as usize {
                let sweep = &sweeps[b.digit[k] as usize];
                // LYK06 eq. 1
                let f = sweep.frame_in(b.segment[k] as usize, b.arc[k]);
                v += b.weight[k] * (f.rotation * b.offset[k] + f.position);
            }
            *o = v;
        }
    }
}

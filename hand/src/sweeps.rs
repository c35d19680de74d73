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
//! # Evaluation
//!
//! Evaluating the Hermite trajectory and the slerp per vertex and influence cost ~0.8 ms per
//! frame on the 8K-vertex base hand. Instead, every frame samples each posed sweep once at
//! [`SWEEP_SAMPLES`] uniformly spaced arc lengths into affine frames `M_i` ([`SweepSamples`]),
//! and a vertex at arc `s` between samples `i` and `i + 1` (fraction `f`) uses the blended
//! frame `(1 - f) M_i + f M_{i+1}`; its offset is taken in the same blended frame of the rest
//! sweep, so the rest pose still reconstructs exactly. At 160 samples (spacing ~1.2 mm) the
//! linear blend of two frames at most ~6° apart (a 90° knuckle spread over 20 mm) shortens a
//! radius of 1 cm by < 0.02 mm. [`SweepHand::influences`] still reports the exact `(t, o)`.
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

use super::smoothstep;
use glam::{Affine3A, Quat, Vec3, Vec3A};

use super::skeleton::{Digit, HandPose, HandSkeleton, JointFrame, MAX_CHAIN, PosedSkeleton};
use crease_core::mesh::Mesh;

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
/// Bound on how far a sweep's curve strays from the polyline through its keys (metres; the
/// Hermite spans bulge by well under a millimetre between keys at most ~4 cm apart).
const POLYLINE_SLACK: f32 = 0.003;
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

    /// Distance from `v` to the polyline through the key positions (within
    /// [`POLYLINE_SLACK`] of the distance to the curve).
    fn polyline_distance(&self, v: Vec3) -> f32 {
        let mut best = f32::INFINITY;
        for w in self.positions[..self.keys].windows(2) {
            let e = w[1] - w[0];
            let t = ((v - w[0]).dot(e) / e.length_squared().max(1e-12)).clamp(0.0, 1.0);
            best = best.min((w[0] + e * t - v).length());
        }
        best
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

/// A vertex's hold by one sweep in the sampled representation: the two sweep samples that
/// bracket its arc, their blend weights (already multiplied by the influence's weight), and
/// the offset in the blended rest frame.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Hold {
    /// Global index of the lower sample (`digit * SWEEP_SAMPLES + i`).
    sample: u32,
    /// `w (1 - f)` for the lower sample and `w f` for the upper one.
    a: f32,
    b: f32,
    /// `M_rest(s)^-1 v` with `M_rest(s) = (1 - f) M_i + f M_{i+1}` (module docs).
    offset: Vec3,
}

/// What [`SweepHand::influences`] reports of one hold (kept for inspection and for the
/// layers bound on top of the sweeps).
#[derive(Clone, Copy, Debug, PartialEq)]
struct HoldInfo {
    digit: u8,
    weight: f32,
    arc: f32,
    offset: Vec3,
}

/// One vertex's holds while binding.
#[derive(Clone, Copy, Debug)]
struct VertexHolds {
    count: usize,
    holds: [Hold; 5],
    info: [HoldInfo; 5],
}

impl Default for VertexHolds {
    fn default() -> Self {
        VertexHolds {
            count: 0,
            holds: [Hold {
                sample: 0,
                a: 0.0,
                b: 0.0,
                offset: Vec3::ZERO,
            }; 5],
            info: [HoldInfo {
                digit: 0,
                weight: 0.0,
                arc: 0.0,
                offset: Vec3::ZERO,
            }; 5],
        }
    }
}

/// Samples per sweep of the per-frame sampled representation (module docs, "Evaluation").
pub const SWEEP_SAMPLES: usize = 160;

/// The five posed sweeps sampled at [`SWEEP_SAMPLES`] arc lengths each, as affine frames:
/// the per-frame state every bound layer reads. Reused across frames (no allocation after
/// [`SweepSamples::new`]).
#[derive(Clone, Debug)]
pub struct SweepSamples {
    frames: Vec<Affine3A>,
    posed: PosedSkeleton,
}

impl Default for SweepSamples {
    fn default() -> Self {
        SweepSamples::new()
    }
}

impl SweepSamples {
    /// An empty buffer (identity frames) of the right size.
    pub fn new() -> Self {
        SweepSamples {
            frames: vec![Affine3A::IDENTITY; 5 * SWEEP_SAMPLES],
            posed: PosedSkeleton::default(),
        }
    }

    /// The posed skeleton these samples were taken from.
    pub fn posed(&self) -> &PosedSkeleton {
        &self.posed
    }

    /// Sample `i` of `digit`'s sweep.
    pub fn frame(&self, digit: Digit, i: usize) -> Affine3A {
        self.frames[digit.index() * SWEEP_SAMPLES + i]
    }

    /// The blended frame `(1 - f) M_i + f M_{i+1}` applied to `p` (global sample index).
    #[inline]
    fn apply(&self, sample: u32, a: f32, b: f32, p: Vec3A) -> Vec3A {
        let i = sample as usize;
        a * self.frames[i].transform_point3a(p) + b * self.frames[i + 1].transform_point3a(p)
    }

    /// The blended linear part applied to a direction `d` (no translation).
    #[inline]
    fn apply_vector(&self, sample: u32, a: f32, b: f32, d: Vec3A) -> Vec3A {
        let i = sample as usize;
        a * self.frames[i].transform_vector3a(d) + b * self.frames[i + 1].transform_vector3a(d)
    }
}

/// Where an arc length `s` of a sweep of length `len` falls among the samples: the lower
/// sample index (never the last) and the fraction towards the next.
fn sample_of(s: f32, len: f32) -> (usize, f32) {
    let x = (s / len).clamp(0.0, 1.0) * (SWEEP_SAMPLES - 1) as f32;
    let i = (x.floor() as usize).min(SWEEP_SAMPLES - 2);
    (i, x - i as f32)
}

/// A rest skin bound to the five control sweeps of a skeleton (module docs).
#[derive(Clone, Debug)]
pub struct SweepHand {
    skeleton: HandSkeleton,
    /// Rest length of each digit's sweep (for the normalised `t`).
    lengths: [f32; 5],
    /// `start[i]..start[i + 1]` are vertex `i`'s holds.
    start: Vec<u32>,
    holds: Vec<Hold>,
    info: Vec<HoldInfo>,
    /// The flat pose's samples (for carrying rest directions, [`SweepHand::local_direction`]).
    rest_samples: SweepSamples,
}

impl SweepHand {
    /// Binds every vertex of `rest` (in the skeleton's flat rest pose) to the sweeps of
    /// `skeleton` (LYK06 eq. 1 and the blending weights; module docs).
    pub fn bind(skeleton: &HandSkeleton, rest: &Mesh) -> SweepHand {
        let posed = skeleton.pose(&HandPose::FLAT);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        let lengths = sweeps.map(|s| s.length());
        let mut rest_samples = SweepSamples::new();
        sample_sweeps(&sweeps, &posed, &mut rest_samples);
        let mcp = sweeps.map(|s| s.joint_arc(MCP_CHAIN_INDEX));
        let bind_vertex = |v: Vec3| -> VertexHolds {
            // Exact projections only onto the sweeps that can get a weight: a sweep's key
            // polyline is within POLYLINE_SLACK of its curve, so one whose polyline is farther
            // than the nearest polyline + the widest band + twice the slack gets weight 0.
            let rough = sweeps.map(|s| s.polyline_distance(v));
            let nearest_rough = rough.iter().copied().fold(f32::INFINITY, f32::min);
            let reach = nearest_rough + BAND_INNER + BAND_WIDTH + 2.0 * POLYLINE_SLACK;
            let proj: [(f32, f32); 5] = std::array::from_fn(|k| {
                if rough[k] <= reach {
                    sweeps[k].project(v)
                } else {
                    (0.0, f32::INFINITY)
                }
            });
            let (nearest, &(s_near, d_near)) = proj
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.1.total_cmp(&b.1.1))
                .expect("five sweeps");
            let open = 1.0 - smoothstep((s_near - mcp[nearest]) / FINGER_RAMP);
            let inner = BAND_INNER * open;
            let width = WEB_WIDTH + (BAND_WIDTH - WEB_WIDTH) * open;
            let mut out = VertexHolds::default();
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
                let frame = sweep.frame_at_arc(s);
                let (i, f) = sample_of(s, lengths[k]);
                let sample = k * SWEEP_SAMPLES + i;
                let m0 = rest_samples.frames[sample];
                let m1 = rest_samples.frames[sample + 1];
                let blended = Affine3A {
                    matrix3: m0.matrix3 * (1.0 - f) + m1.matrix3 * f,
                    translation: m0.translation * (1.0 - f) + m1.translation * f,
                };
                let c = out.count;
                out.info[c] = HoldInfo {
                    digit: k as u8,
                    weight: w,
                    arc: s,
                    offset: frame.rotation.inverse() * (v - frame.position),
                };
                out.holds[c] = Hold {
                    sample: sample as u32,
                    a: w * (1.0 - f),
                    b: w * f,
                    offset: blended.inverse().transform_point3(v),
                };
                out.count += 1;
                total += w;
            }
            for (h, i) in out.holds[..out.count].iter_mut().zip(&mut out.info) {
                h.a /= total;
                h.b /= total;
                i.weight /= total;
            }
            out
        };
        #[cfg(feature = "parallel")]
        let per_vertex: Vec<VertexHolds> = {
            use rayon::prelude::*;
            rest.positions.par_iter().map(|&v| bind_vertex(v)).collect()
        };
        #[cfg(not(feature = "parallel"))]
        let per_vertex: Vec<VertexHolds> = rest.positions.iter().map(|&v| bind_vertex(v)).collect();
        let mut start = Vec::with_capacity(rest.positions.len() + 1);
        let mut holds = Vec::new();
        let mut info = Vec::new();
        start.push(0);
        for vh in &per_vertex {
            holds.extend_from_slice(&vh.holds[..vh.count]);
            info.extend_from_slice(&vh.info[..vh.count]);
            start.push(holds.len() as u32);
        }
        SweepHand {
            skeleton: skeleton.clone(),
            lengths,
            start,
            holds,
            info,
            rest_samples,
        }
    }

    /// Number of bound vertices.
    pub fn vertex_count(&self) -> usize {
        self.start.len() - 1
    }

    /// The skeleton the skin is bound to.
    pub fn skeleton(&self) -> &HandSkeleton {
        &self.skeleton
    }

    /// The influences of vertex `i` (weights normalised, non-zero).
    pub fn influences(&self, i: usize) -> impl Iterator<Item = Influence> + '_ {
        let range = self.start[i] as usize..self.start[i + 1] as usize;
        self.info[range].iter().map(move |h| Influence {
            digit: Digit::ALL[h.digit as usize],
            weight: h.weight,
            t: h.arc / self.lengths[h.digit as usize],
            offset: h.offset,
        })
    }

    /// Poses the skeleton and samples its five sweeps into `samples` (allocation-free).
    pub fn sample(&self, pose: &HandPose, samples: &mut SweepSamples) {
        let mut posed = PosedSkeleton::default();
        self.skeleton.pose_into(pose, &mut posed);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        sample_sweeps(&sweeps, &posed, samples);
    }

    /// Reconstructs every vertex from sampled sweeps: `V = Σ_k w_k M_k(t_k) o_k` (LYK06 eq. 1,
    /// blended; `M_k(t)` the frame of sweep `k` at `t`, linearly interpolated between its two
    /// nearest samples). Allocates nothing.
    ///
    /// # Panics
    /// If `out.len()` differs from [`SweepHand::vertex_count`].
    pub fn skin_into(&self, samples: &SweepSamples, out: &mut [Vec3]) {
        assert_eq!(out.len(), self.vertex_count(), "output length");
        for (o, w) in out.iter_mut().zip(self.start.windows(2)) {
            let mut v = Vec3A::ZERO;
            for h in &self.holds[w[0] as usize..w[1] as usize] {
                // LYK06 eq. 1
                v += samples.apply(h.sample, h.a, h.b, Vec3A::from(h.offset));
            }
            *o = Vec3::from(v);
        }
    }

    /// A rest-space direction `d` at vertex `i` expressed in the rest frame of the vertex's
    /// first hold, for [`SweepHand::rotate_local`].
    pub fn local_direction(&self, i: usize, d: Vec3) -> Vec3 {
        let h = &self.holds[self.start[i] as usize];
        let w = h.a + h.b;
        let m = |k: usize| self.rest_samples.frames[h.sample as usize + k].matrix3;
        let blended = m(0) * (h.a / w) + m(1) * (h.b / w);
        Vec3::from(blended.inverse() * Vec3A::from(d))
    }

    /// Carries a direction from [`SweepHand::local_direction`] to the posed frame of the
    /// same hold: the rest direction rotated as the skin around vertex `i` rotated (for the
    /// normal displacements of creases).
    #[inline]
    pub fn rotate_local(&self, samples: &SweepSamples, i: usize, local: Vec3) -> Vec3 {
        let h = &self.holds[self.start[i] as usize];
        let w = h.a + h.b;
        Vec3::from(samples.apply_vector(h.sample, h.a / w, h.b / w, Vec3A::from(local)))
    }

    /// Deforms the bound skin to `pose`, writing one position per vertex into `out`:
    /// [`SweepHand::sample`] then [`SweepHand::skin_into`]. Allocates the sample buffer; a
    /// caller deforming every frame keeps a [`SweepSamples`] and calls those two.
    ///
    /// # Panics
    /// If `out.len()` differs from [`SweepHand::vertex_count`].
    pub fn deform_into(&self, pose: &HandPose, out: &mut [Vec3]) {
        let mut samples = SweepSamples::new();
        self.sample(pose, &mut samples);
        self.skin_into(&samples, out);
    }
}

/// Samples each sweep at [`SWEEP_SAMPLES`] uniformly spaced arc lengths (the knots are the
/// same in every pose, so sample `i` is the same material point in every pose).
fn sample_sweeps(sweeps: &[Sweep; 5], posed: &PosedSkeleton, out: &mut SweepSamples) {
    out.posed = *posed;
    for (k, sweep) in sweeps.iter().enumerate() {
        let len = sweep.length();
        let mut seg = 0;
        let frames = &mut out.frames[k * SWEEP_SAMPLES..(k + 1) * SWEEP_SAMPLES];
        for (i, m) in frames.iter_mut().enumerate() {
            let s = len * i as f32 / (SWEEP_SAMPLES - 1) as f32;
            while seg + 2 < sweep.keys && s >= sweep.knots[seg + 1] {
                seg += 1;
            }
            let f = sweep.frame_in(seg, s);
            *m = Affine3A::from_rotation_translation(f.rotation, f.position);
        }
    }
}

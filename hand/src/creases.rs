//! Pose-dependent creases of the detailed sweep hand: the palm lines of LYK06 §3 ("Palm
//! Lines": "offsetting the vertices on a palm line ... into the hand", depth following "the
//! angles of joints that contribute to forming palm lines"), the palmar flexion creases of the
//! finger joints, the dorsal knuckle wrinkles, and a fine static skin texture. They are what
//! the detail layer (HZY11) has to learn, so each is driven by named joints.
//!
//! # Creases ([`CreaseDef`])
//!
//! Each crease is a groove: every vertex near its line moves into the hand along its (posed)
//! normal by `depth(pose) * g(x)`, with `x` the vertex's rest distance to the line and
//! `g(x) = exp(-(x / width)²)`, tapered at the line's ends. The depth of a crease is
//! `max_depth * smoothstep(a)` with the activation `a` the mean of its driving joints'
//! flexion over their upper limit; dorsal wrinkles use `max_depth * (1 - smoothstep(2a))`:
//! deep on the straight finger, smoothed out by half flexion. So a palmar crease's depth never
//! decreases as its joint flexes, and a dorsal wrinkle's never increases.
//!
//! - Palm lines, as polylines in the palm domain's `(u, v)` ([`super::palm`]): the thenar
//!   crease (thumb CMC flexion), the proximal transverse crease (index and middle MCP), the
//!   distal transverse crease (ring and little MCP). Only palmar-facing vertices.
//! - Palmar flexion creases: a line around the palmar half of the digit at the joint (the
//!   finger MCP crease sits at the finger's base, 12 mm distal of the joint centre, where the
//!   palmar digital crease is), for every MCP, PIP, DIP and the thumb's MCP and IP. `x` is the
//!   arc-length distance along the digit's sweep; the angular extent is ±75° around palmar.
//! - Dorsal knuckle wrinkles: three lines 2.5 mm apart over each PIP, DIP and the thumb IP,
//!   on the dorsal ±60°.
//!
//! # Evaluation
//!
//! Binding lists `(vertex, crease, g, local normal)` entries; each frame computes the ~30
//! depths and moves each entry's vertex by `-depth * g * R n` with `R` the rotation of the
//! vertex's sweep frame since the rest pose ([`SweepHand::rotate_local`]). Allocation-free.
//!
//! # Skin texture ([`skin_texture`])
//!
//! A static displacement along the rest normal from two octaves of smooth 3-D value noise
//! (cells of 1.2 and 0.6 mm, amplitude [`TEXTURE_AMPLITUDE`]), baked into the detailed rest
//! mesh before binding so that it deforms with the skin.

use super::smoothstep;
use glam::{Vec2, Vec3};

use super::palm::Domain;
use super::skeleton::{
    Digit, Dof, DofKind, HandPose, HandSkeleton, Joint, JointLimits, PosedSkeleton,
};
use super::sweeps::{Sweep, SweepHand, SweepSamples};
use crease_core::mesh::Mesh;

/// Amplitude of the static skin texture (metres).
pub const TEXTURE_AMPLITUDE: f32 = 0.00006;
/// Most creases a [`Creases`] can hold (the per-frame depths live on the stack).
pub const MAX_CREASES: usize = 40;
/// Distal offset of a finger's MCP flexion crease from the joint centre (metres).
pub const MCP_CREASE_OFFSET: f32 = 0.012;
/// Spacing of the dorsal wrinkle lines (metres).
const DORSAL_SPACING: f32 = 0.0025;
/// Entries with a profile below this are dropped.
const MIN_PROFILE: f32 = 0.01;

/// What kind of crease, which decides where it lies and how its depth follows its joints.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CreaseKind {
    /// A palm line on the palmar surface.
    PalmLine,
    /// A palmar flexion crease across a digit joint.
    Flexion,
    /// Dorsal knuckle wrinkles over a digit joint (deepest when straight).
    Dorsal,
}

/// One crease: where, how deep, and which joints drive it (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct CreaseDef {
    /// A stable name, e.g. `thenar`, `index_pip_flexion`, `index_pip_dorsal`.
    pub name: String,
    /// The kind.
    pub kind: CreaseKind,
    /// Maximum depth (metres).
    pub max_depth: f32,
    /// Half-width of the groove profile (metres).
    pub width: f32,
    /// The driving flexion degrees of freedom (averaged, each over its upper limit).
    pub drivers: Vec<Dof>,
    /// Where: the palm polyline in `(u, v)`, or the digit and chain index of the joint.
    place: Place,
}

#[derive(Clone, Debug, PartialEq)]
enum Place {
    Palm(Vec<Vec2>),
    Joint { digit: Digit, chain: usize },
}

fn flexion(joint: Joint) -> Dof {
    Dof::new(joint, DofKind::Flexion).expect("every digit joint flexes")
}

impl CreaseDef {
    /// The activation in `[0, 1]`: mean driving flexion over the upper limits.
    pub fn activation(&self, pose: &HandPose, limits: &JointLimits) -> f32 {
        let sum: f32 = self
            .drivers
            .iter()
            .map(|&d| pose.get(d) / limits.range(d).1)
            .sum();
        (sum / self.drivers.len() as f32).clamp(0.0, 1.0)
    }

    /// The digit a joint crease lies on (`None` for palm lines).
    pub fn digit(&self) -> Option<Digit> {
        match self.place {
            Place::Joint { digit, .. } => Some(digit),
            Place::Palm(_) => None,
        }
    }

    /// The point of a posed skeleton a digit crease wraps around: the joint centre (a finger's
    /// MCP flexion crease: [`MCP_CREASE_OFFSET`] along the proximal phalanx). `None` for palm
    /// lines.
    pub fn centre(&self, posed: &PosedSkeleton) -> Option<Vec3> {
        let Place::Joint { digit, chain } = self.place else {
            return None;
        };
        let frames = posed.chain(digit);
        let mut p = frames[chain].position;
        if self.kind == CreaseKind::Flexion && digit != Digit::Thumb && chain == 2 {
            p += frames[chain].axis() * MCP_CREASE_OFFSET;
        }
        Some(p)
    }

    /// The crease's depth in `pose` (metres; module docs).
    pub fn depth(&self, pose: &HandPose, limits: &JointLimits) -> f32 {
        let a = self.activation(pose, limits);
        match self.kind {
            CreaseKind::Dorsal => self.max_depth * (1.0 - smoothstep(2.0 * a)),
            _ => self.max_depth * smoothstep(a),
        }
    }
}

/// The hand's crease set (module docs).
pub fn standard_creases() -> Vec<CreaseDef> {
    let uv = |p: &[[f32; 2]]| Place::Palm(p.iter().map(|&q| Vec2::from(q)).collect());
    let mut out = vec![
        CreaseDef {
            name: "thenar".into(),
            kind: CreaseKind::PalmLine,
            max_depth: 0.0010,
            width: 0.0008,
            drivers: vec![flexion(Joint::ThumbCmc)],
            place: uv(&[
                [0.02, 0.80],
                [0.16, 0.64],
                [0.26, 0.42],
                [0.30, 0.20],
                [0.33, 0.02],
            ]),
        },
        CreaseDef {
            name: "proximal_transverse".into(),
            kind: CreaseKind::PalmLine,
            max_depth: 0.0009,
            width: 0.0008,
            drivers: vec![flexion(Joint::IndexMcp), flexion(Joint::MiddleMcp)],
            place: uv(&[[0.02, 0.80], [0.30, 0.71], [0.58, 0.62], [0.80, 0.56]]),
        },
        CreaseDef {
            name: "distal_transverse".into(),
            kind: CreaseKind::PalmLine,
            max_depth: 0.0009,
            width: 0.0008,
            drivers: vec![flexion(Joint::RingMcp), flexion(Joint::LittleMcp)],
            place: uv(&[[0.98, 0.80], [0.72, 0.85], [0.48, 0.91], [0.30, 0.97]]),
        },
    ];
    for digit in Digit::ALL {
        let joints = digit.joints();
        // chain index of joint k is k + 1 (wrist 0).
        for (k, &joint) in joints.iter().enumerate().skip(1) {
            let chain = k + 1;
            let dof = flexion(joint);
            out.push(CreaseDef {
                name: format!("{}_flexion", joint.name()),
                kind: CreaseKind::Flexion,
                max_depth: 0.0010,
                width: 0.0007,
                drivers: vec![dof],
                place: Place::Joint { digit, chain },
            });
            if k >= 2 {
                out.push(CreaseDef {
                    name: format!("{}_dorsal", joint.name()),
                    kind: CreaseKind::Dorsal,
                    max_depth: 0.00035,
                    width: 0.0005,
                    drivers: vec![dof],
                    place: Place::Joint { digit, chain },
                });
            }
        }
    }
    out
}

/// One vertex's share of one crease.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Entry {
    vertex: u32,
    crease: u16,
    /// Profile `g` times the inward unit normal in the vertex's first hold's rest frame.
    direction: Vec3,
}

/// Creases bound to a rest mesh (module docs).
#[derive(Clone, Debug)]
pub struct Creases {
    defs: Vec<CreaseDef>,
    limits: JointLimits,
    entries: Vec<Entry>,
}

/// Distance from `p` to a polyline and the normalised arc position of the closest point.
fn polyline_distance(p: Vec2, line: &[Vec2]) -> (f32, f32) {
    let total: f32 = line.windows(2).map(|w| w[0].distance(w[1])).sum();
    let mut best = (f32::INFINITY, 0.0);
    let mut run = 0.0;
    for w in line.windows(2) {
        let e = w[1] - w[0];
        let len = e.length();
        let t = ((p - w[0]).dot(e) / (len * len)).clamp(0.0, 1.0);
        let d = p.distance(w[0] + e * t);
        if d < best.0 {
            best = (d, (run + t * len) / total);
        }
        run += len;
    }
    best
}

impl Creases {
    /// Binds `defs` to the rest mesh `rest` (flat pose of `skeleton`, vertex normals
    /// `normals`) already bound to the sweeps as `hand`.
    ///
    /// # Panics
    /// If there are more than [`MAX_CREASES`] creases.
    pub fn bind(
        skeleton: &HandSkeleton,
        hand: &SweepHand,
        rest: &Mesh,
        normals: &[Vec3],
        defs: Vec<CreaseDef>,
    ) -> Creases {
        assert!(defs.len() <= MAX_CREASES, "{} creases", defs.len());
        let domain = Domain::of(skeleton);
        let posed = skeleton.pose(&HandPose::FLAT);
        let sweeps = Digit::ALL.map(|d| Sweep::of_digit(&posed, d));
        let palm_lines: Vec<(usize, Vec<Vec2>)> = defs
            .iter()
            .enumerate()
            .filter_map(|(c, d)| match &d.place {
                Place::Palm(uv) => Some((c, uv.iter().map(|&q| domain.at(q)).collect())),
                Place::Joint { .. } => None,
            })
            .collect();
        let mut entries = Vec::new();
        for (i, (&v, &n)) in rest.positions.iter().zip(normals).enumerate() {
            let mut push = |c: usize, g: f32| {
                if g >= MIN_PROFILE {
                    entries.push(Entry {
                        vertex: i as u32,
                        crease: c as u16,
                        direction: hand.local_direction(i, -n) * g,
                    });
                }
            };
            if n.z < -0.3 {
                for (c, line) in &palm_lines {
                    let (x, along) = polyline_distance(v.truncate(), line);
                    let taper = smoothstep(along / 0.12) * smoothstep((1.0 - along) / 0.12);
                    let w = defs[*c].width;
                    push(*c, taper * (-(x / w) * (x / w)).exp());
                }
            }
            let Some(main) = hand
                .influences(i)
                .max_by(|a, b| a.weight.total_cmp(&b.weight))
            else {
                continue;
            };
            if main.weight < 0.5 {
                continue;
            }
            let radial = Vec2::new(main.offset.x, main.offset.z);
            if radial.length() < 1e-6 {
                continue;
            }
            // Cosine of the angle from the dorsal direction (local +Z) around the sweep.
            let cos_dorsal = main.offset.z / radial.length();
            let sweep = &sweeps[main.digit.index()];
            let arc = main.t * sweep.length();
            for (c, def) in defs.iter().enumerate() {
                let Place::Joint { digit, chain } = def.place else {
                    continue;
                };
                if digit != main.digit {
                    continue;
                }
                let mut at = sweep.joint_arc(chain);
                let w = def.width;
                let g = match def.kind {
                    CreaseKind::Flexion => {
                        if digit != Digit::Thumb && chain == 2 {
                            at += MCP_CREASE_OFFSET;
                        }
                        let x = arc - at;
                        let side = smoothstep((-cos_dorsal - 0.26) / 0.4);
                        side * (-(x / w) * (x / w)).exp()
                    }
                    CreaseKind::Dorsal => {
                        let side = smoothstep((cos_dorsal - 0.5) / 0.3);
                        let g = [-DORSAL_SPACING, 0.0, DORSAL_SPACING]
                            .iter()
                            .map(|o| {
                                let x = arc - at - o;
                                (-(x / w) * (x / w)).exp()
                            })
                            .fold(0.0f32, f32::max);
                        side * g
                    }
                    CreaseKind::PalmLine => 0.0,
                };
                push(c, g);
            }
        }
        Creases {
            defs,
            limits: JointLimits::adult(),
            entries,
        }
    }

    /// The creases.
    pub fn defs(&self) -> &[CreaseDef] {
        &self.defs
    }

    /// The vertices of crease `c` with their profile weight `g` (in `(0, 1]`).
    pub fn vertices(&self, c: usize) -> impl Iterator<Item = (u32, f32)> + '_ {
        self.entries
            .iter()
            .filter(move |e| e.crease as usize == c)
            .map(|e| (e.vertex, e.direction.length()))
    }

    /// Number of (vertex, crease) entries.
    pub fn entry_count(&self) -> usize {
        self.entries.len()
    }

    /// Pushes the crease vertices of a deformed mesh into the hand by each crease's depth in
    /// `pose` (module docs). `samples` are the sweep samples `positions` were skinned from.
    /// Allocates nothing.
    pub fn apply(
        &self,
        pose: &HandPose,
        hand: &SweepHand,
        samples: &SweepSamples,
        positions: &mut [Vec3],
    ) {
        let mut depth = [0.0f32; MAX_CREASES];
        for (d, def) in depth.iter_mut().zip(&self.defs) {
            *d = def.depth(pose, &self.limits);
        }
        for e in &self.entries {
            let d = depth[e.crease as usize];
            if d != 0.0 {
                let i = e.vertex as usize;
                positions[i] += d * hand.rotate_local(samples, i, e.direction);
            }
        }
    }
}

/// Smooth value noise in `[-1, 1]` on a unit lattice (hashed corners, quintic fade).
fn value_noise(p: Vec3, seed: u32) -> f32 {
    let cell = p.floor();
    let f = p - cell;
    let fade = f * f * f * (f * (f * 6.0 - 15.0) + 10.0);
    let (x0, y0, z0) = (cell.x as i32, cell.y as i32, cell.z as i32);
    let corner = |dx: i32, dy: i32, dz: i32| {
        let mut h = (x0 + dx) as u32;
        h = h.wrapping_mul(0x8da6_b343) ^ ((y0 + dy) as u32).wrapping_mul(0xd816_3841);
        h ^= ((z0 + dz) as u32).wrapping_mul(0xcb1a_b31f) ^ seed.wrapping_mul(0x9e37_79b9);
        h ^= h >> 15;
        h = h.wrapping_mul(0x2c1b_3c6d);
        h ^= h >> 12;
        h as f32 / u32::MAX as f32 * 2.0 - 1.0
    };
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let x00 = lerp(corner(0, 0, 0), corner(1, 0, 0), fade.x);
    let x10 = lerp(corner(0, 1, 0), corner(1, 1, 0), fade.x);
    let x01 = lerp(corner(0, 0, 1), corner(1, 0, 1), fade.x);
    let x11 = lerp(corner(0, 1, 1), corner(1, 1, 1), fade.x);
    lerp(lerp(x00, x10, fade.y), lerp(x01, x11, fade.y), fade.z)
}

/// Bakes the static skin texture into a rest mesh: each vertex moves along its normal by
/// [`TEXTURE_AMPLITUDE`] × (two octaves of value noise, cells 1.2 and 0.6 mm).
pub fn skin_texture(mesh: &mut Mesh, normals: &[Vec3], seed: u32) {
    for (p, n) in mesh.positions.iter_mut().zip(normals) {
        let q = *p / 0.0012;
        let h = 0.67 * value_noise(q, seed) + 0.33 * value_noise(q * 2.0, seed ^ 0x5bd1_e995);
        *p += *n * (TEXTURE_AMPLITUDE * h);
    }
}

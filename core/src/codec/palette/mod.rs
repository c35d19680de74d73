//! Palette streams (issue 18): a frame of a skinned mesh as its bone transforms, not its
//! vertices. The base mesh is a fixed linear function of the bones' rigid transforms (linear
//! blend skinning, FKY08 eq. 1: `v = sum_k w_k (R_k p + t_k)`), and the detail layer a fixed
//! linear function of the detail kernel vector (HZY11 eq. 4: `h = D xi + b`), so a viewer that
//! holds the rest mesh, the skin and `D` once ([`PaletteHeader`]) needs per frame only the
//! bones and `xi`.
//!
//! # Frames: codec frames of lanes
//!
//! A palette frame is a `core::codec` frame ([`super::FrameEncoder`], keyframe or delta, no
//! normals) whose "vertices" are four 16-bit lanes that hold, instead of positions:
//!
//! ```text
//! lane vertex 2k       [a, b, c, i]    bone k's rotation, smallest three: i (0..=3) is the
//!                                      index of the largest component of the unit quaternion
//!                                      (made positive and dropped), a, b, c the other three
//!                                      in order, each (x sqrt 2 + 1) / 2 * 65535 rounded
//! lane vertex 2k + 1   [x, y, z, 0]    bone k's translation, quantised in the frame's box
//!                                      (the codec header's min and step, decoded as a
//!                                      position: min + q * step)
//! lane vertex 2B + j   [lo, hi, lo, hi] xi[2j] and xi[2j + 1] as the low and high halves of
//!                                      their f32 bit patterns (the last one 0 when N is odd)
//! ```
//!
//! B bones and N kernel values make [`palette_vertex_count`]`(B, N) = 2B + ceil(N/2)` lane
//! vertices. The codec's deltas and keyframes, its on-demand keyframes for a joining viewer
//! and its decoders (the Rust one, the viewer's meshopt one) serve palette streams unchanged;
//! at 60 Hz the bones move little from frame to frame, so a delta costs a few bytes per bone
//! (figures in BENCHMARKS.md). The translation box is the stream's, fixed
//! ([`translation_box`]), so that unchanged translations give zero deltas.
//!
//! # Error bounds
//!
//! The three stored quaternion components lie in `[-1/sqrt 2, 1/sqrt 2]` and are quantised to
//! 16 bits, so each is within `h = 1 / (sqrt 2 * 65535)` of the input. The dropped component is
//! rebuilt as `sqrt(1 - sum of squares)`, the quaternion normalised: `|q' - q| <= 4 h` (a
//! conservative bound, [`ROTATION_ERROR`]). Rotating a point `p` by two unit quaternions
//! differs by at most `2 |q' - q| |p|`. A translation is within half a step per axis of the box
//! ([`PaletteFrame::translation_error`]), if it lies in the box (outside, it is clamped, as a
//! vertex stream clamps vertices). So a skinned vertex moves by at most
//! `sum_k w_k (2 ROTATION_ERROR |p| + |translation error|)` ([`vertex_error_bound`]), plus
//! `f32` rounding. `xi` travels exactly.

use glam::{Quat, Vec3};

use super::QuantBox;
use crate::runtime::skin::RigidTransform;

pub mod header;
pub mod synth;

pub use header::{
    PaletteDetail, PaletteHeader, PaletteHeaderError, PaletteSkin, detail_quantum, quantise_weights,
};
pub use synth::{PaletteSynth, PaletteSynthError};

/// The palette format version (`PaletteTopology.version`): how the lanes are laid out.
pub const PALETTE_VERSION: u8 = 1;

/// Half the quantisation step of a stored quaternion component.
const COMPONENT_HALF_STEP: f32 = std::f32::consts::FRAC_1_SQRT_2 / 65535.0;
/// A bound on `|q' - q|` for a stored unit quaternion (module docs).
pub const ROTATION_ERROR: f32 = 4.0 * COMPONENT_HALF_STEP;

/// Why palette lanes could not be read or written.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PaletteError {
    /// A frame whose lane count does not fit the stream's bones and kernel values.
    #[error(
        "palette frame: {got} lane vertices, expected {expected} ({bones} bones, {xi} xi values)"
    )]
    Count {
        /// Lane vertices in the frame.
        got: usize,
        /// What the stream's counts need.
        expected: usize,
        /// The stream's bones.
        bones: usize,
        /// The stream's kernel values.
        xi: usize,
    },
    /// A quaternion's largest-component index above 3.
    #[error("palette frame: bone {bone}: quaternion index {index}, expected 0..=3")]
    QuatIndex {
        /// The bone.
        bone: usize,
        /// The index lane.
        index: u16,
    },
    /// A non-finite value to encode (a transform or an `xi`), or a stored `xi`.
    #[error("palette frame: {what} {index} is not finite")]
    NotFinite {
        /// `bone` or `xi`.
        what: &'static str,
        /// Its index.
        index: usize,
    },
}

/// A decoded palette frame: the bones' rigid transforms and the detail kernel vector.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PaletteFrame {
    /// One transform per bone (rest space -> posed space).
    pub bones: Vec<RigidTransform>,
    /// The detail kernel vector `xi` (empty without a detail layer).
    pub xi: Vec<f32>,
    /// The translation box's step, for the error bound.
    step: Vec3,
}

impl PaletteFrame {
    /// The largest translation error of this frame's bones, per axis: half its box's step.
    pub fn translation_error(&self) -> Vec3 {
        self.step * 0.5
    }
}

/// Lane vertices of a palette frame of `bones` bones and `xi` kernel values.
pub fn palette_vertex_count(bones: usize, xi: usize) -> usize {
    2 * bones + xi.div_ceil(2)
}

/// The translation box of a palette stream whose posed vertices stay in `lo..hi` (the vertex
/// stream's quantisation box) with rest vertices `rest`: a bone's translation `t = v - R p`
/// has `|t| <= |v| + |p|`, so the cube of that half-size around the origin holds every
/// translation of a pose inside the box. 16 bits.
///
/// # Errors
/// The box's, for non-finite input.
pub fn translation_box(lo: Vec3, hi: Vec3, rest: &[Vec3]) -> Result<QuantBox, super::CodecError> {
    let v = lo.abs().max(hi.abs()).length();
    let p = rest.iter().fold(0.0f32, |m, p| m.max(p.length()));
    let r = Vec3::splat((v + p).max(f32::MIN_POSITIVE));
    QuantBox::from_bounds(-r, r, 0.0, 16)
}

/// Bone `k`'s lanes and `xi` as a palette frame's lane vertices (module docs) into `out`
/// (cleared first), translations quantised in `qbox`.
///
/// # Errors
/// [`PaletteError::NotFinite`] for a non-finite rotation, translation or `xi` value (`out` is
/// left empty then).
pub fn palette_lanes(
    bones: &[RigidTransform],
    xi: &[f32],
    qbox: &QuantBox,
    out: &mut Vec<[u16; 4]>,
) -> Result<(), PaletteError> {
    out.clear();
    if let Some(k) = bones.iter().position(|b| !b.is_finite()) {
        return Err(PaletteError::NotFinite {
            what: "bone",
            index: k,
        });
    }
    if let Some(k) = xi.iter().position(|v| !v.is_finite()) {
        return Err(PaletteError::NotFinite {
            what: "xi",
            index: k,
        });
    }
    for b in bones {
        let (index, q) = smallest_three(b.rotation);
        out.push([q[0], q[1], q[2], u16::from(index)]);
        let t = qbox.quantise(b.translation);
        out.push([t[0], t[1], t[2], 0]);
    }
    for pair in xi.chunks(2) {
        let bits = |k: usize| pair.get(k).map_or(0, |v| v.to_bits());
        let (a, b) = (bits(0), bits(1));
        out.push([a as u16, (a >> 16) as u16, b as u16, (b >> 16) as u16]);
    }
    Ok(())
}

/// Reads a decoded palette frame's `lanes` (translations in `qbox`, the frame header's box)
/// into `frame` (its buffers reused), checking that they hold `bones` bones and `xi` kernel
/// values (the stream's).
///
/// # Errors
/// [`PaletteError`]; `frame` is unchanged but for its buffers' contents then. Never panics.
pub fn read_palette_lanes(
    lanes: &[[u16; 4]],
    qbox: &QuantBox,
    bones: usize,
    xi: usize,
    frame: &mut PaletteFrame,
) -> Result<(), PaletteError> {
    let expected = palette_vertex_count(bones, xi);
    if lanes.len() != expected {
        return Err(PaletteError::Count {
            got: lanes.len(),
            expected,
            bones,
            xi,
        });
    }
    frame.bones.clear();
    for (k, pair) in lanes[..2 * bones].chunks_exact(2).enumerate() {
        let [a, b, c, index] = pair[0];
        if index > 3 {
            return Err(PaletteError::QuatIndex { bone: k, index });
        }
        let t = pair[1];
        frame.bones.push(RigidTransform::new(
            from_smallest_three(usize::from(index), [a, b, c]),
            qbox.dequantise([t[0], t[1], t[2]]),
        ));
    }
    frame.xi.clear();
    for (j, l) in lanes[2 * bones..].iter().enumerate() {
        for (h, bits) in [(0, l[0], l[1]), (1, l[2], l[3])]
            .into_iter()
            .map(|(h, lo, hi)| (h, u32::from(lo) | u32::from(hi) << 16))
        {
            let k = 2 * j + h;
            if k >= xi {
                break;
            }
            let v = f32::from_bits(bits);
            if !v.is_finite() {
                return Err(PaletteError::NotFinite {
                    what: "xi",
                    index: k,
                });
            }
            frame.xi.push(v);
        }
    }
    frame.step = qbox.step();
    Ok(())
}

/// The index of `q`'s largest component and the other three quantised (module docs).
fn smallest_three(q: Quat) -> (u8, [u16; 3]) {
    let q = q.normalize();
    let c = q.to_array();
    let index = (0..4)
        .max_by(|&a, &b| c[a].abs().total_cmp(&c[b].abs()))
        .unwrap_or(3);
    let sign = if c[index] < 0.0 { -1.0 } else { 1.0 };
    let mut out = [0u16; 3];
    for (o, k) in out.iter_mut().zip((0..4).filter(|&k| k != index)) {
        let v = (sign * c[k] * std::f32::consts::SQRT_2).clamp(-1.0, 1.0);
        *o = ((v + 1.0) * 0.5 * 65535.0).round() as u16;
    }
    (index as u8, out)
}

/// The unit quaternion of a stored largest-component index and three components.
fn from_smallest_three(index: usize, q: [u16; 3]) -> Quat {
    let mut c = [0.0f32; 4];
    let mut sum = 0.0;
    for (v, k) in q.iter().zip((0..4).filter(|&k| k != index)) {
        let x = (f32::from(*v) / 65535.0 * 2.0 - 1.0) * std::f32::consts::FRAC_1_SQRT_2;
        c[k] = x;
        sum += x * x;
    }
    c[index] = (1.0 - sum).max(0.0).sqrt();
    Quat::from_array(c).normalize()
}

/// A bound on how far a rest point `p` skinned with `weights` (bone, weight) moves between
/// the encoded transforms and `frame`'s decoded ones (module docs), before `f32` rounding.
pub fn vertex_error_bound(frame: &PaletteFrame, p: Vec3, weights: &[(u32, f32)]) -> f32 {
    let t = frame.translation_error().length();
    let sum: f32 = weights.iter().map(|&(_, w)| w.abs()).sum();
    sum * (2.0 * ROTATION_ERROR * p.length() + t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn random_bones(rng: &mut impl Rng, n: usize) -> Vec<RigidTransform> {
        (0..n)
            .map(|_| {
                let axis = Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                )
                .normalize_or(Vec3::X);
                let q = Quat::from_axis_angle(axis, rng.random_range(-3.1..3.1));
                // Both signs of the quaternion, which describe the same rotation.
                let q = if rng.random_bool(0.5) { q } else { -q };
                let t = Vec3::new(
                    rng.random_range(-2.0..2.0),
                    rng.random_range(-0.5..3.0),
                    rng.random_range(-1.0..1.0),
                );
                RigidTransform::new(q, t)
            })
            .collect()
    }

    /// Bones and xi through lanes and the codec (a keyframe, then a delta) and back.
    fn round_trip(
        bones: &[RigidTransform],
        xi: &[f32],
        frames: usize,
    ) -> (PaletteFrame, QuantBox, Vec<usize>) {
        use crate::codec::{FrameDecoder, FrameEncoder};
        let qbox = translation_box(Vec3::splat(-3.0), Vec3::splat(3.0), &[Vec3::ONE]).unwrap();
        let n = palette_vertex_count(bones.len(), xi.len());
        let mut enc = FrameEncoder::new(n, qbox, 0).unwrap();
        let mut dec = FrameDecoder::new(n);
        let mut frame = PaletteFrame::default();
        let mut sizes = Vec::new();
        let mut bytes = Vec::new();
        for _ in 0..frames {
            let header = enc
                .encode_lanes(|l| palette_lanes(bones, xi, &qbox, l).unwrap(), &mut bytes)
                .unwrap();
            sizes.push(bytes.len());
            let got = dec.decode(&bytes).unwrap();
            assert_eq!(got, header);
            read_palette_lanes(dec.lanes(), &got.qbox, bones.len(), xi.len(), &mut frame).unwrap();
        }
        (frame, qbox, sizes)
    }

    #[test]
    fn skinned_points_from_decoded_bones_stay_within_the_bound() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(18);
        let bones = random_bones(&mut rng, 150);
        let xi: Vec<f32> = (0..13).map(|k| 0.1 * k as f32 - 0.3).collect();
        let (frame, _, sizes) = round_trip(&bones, &xi, 2);
        assert_eq!(frame.xi, xi, "xi travels exactly");
        // An unchanged frame's delta is all zeros: a few bytes per bone at most.
        assert!(
            sizes[1] < sizes[0] / 4,
            "key {} bytes, delta {}",
            sizes[0],
            sizes[1]
        );
        let mut worst = 0.0f32;
        for _ in 0..2000 {
            let p = Vec3::new(
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
                rng.random_range(-1.5..1.5),
            );
            let k = rng.random_range(1..=8);
            let mut weights: Vec<(u32, f32)> = (0..k)
                .map(|_| (rng.random_range(0..150u32), rng.random_range(0.01..1.0)))
                .collect();
            let total: f32 = weights.iter().map(|w| w.1).sum();
            for w in &mut weights {
                w.1 /= total;
            }
            let skin = |bones: &[RigidTransform]| -> Vec3 {
                weights
                    .iter()
                    .map(|&(b, w)| bones[b as usize].transform_point(p) * w)
                    .sum()
            };
            let (want, got) = (skin(&bones), skin(&frame.bones));
            let bound = vertex_error_bound(&frame, p, &weights) + 1e-5;
            let err = want.distance(got);
            assert!(err <= bound, "error {err} over the bound {bound}");
            worst = worst.max(err / bound);
        }
        // The bound is not vacuous: the worst case uses a good part of it, and it is small:
        // below half a step of a 12-bit vertex stream over the same box (side 6).
        assert!(worst > 0.05, "worst error / bound {worst}");
        let vertex_half_step = 6.0 / 4095.0 / 2.0;
        assert!(vertex_error_bound(&frame, Vec3::ONE, &[(0, 1.0)]) < vertex_half_step);
    }

    #[test]
    fn rotations_round_trip_within_the_quaternion_bound() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut bones = random_bones(&mut rng, 500);
        // Edge cases: identity, a half turn (w = 0), components of equal size.
        bones.push(RigidTransform::new(Quat::IDENTITY, Vec3::ZERO));
        bones.push(RigidTransform::new(
            Quat::from_rotation_y(std::f32::consts::PI),
            Vec3::ONE,
        ));
        bones.push(RigidTransform::new(
            Quat::from_xyzw(0.5, 0.5, 0.5, 0.5),
            Vec3::ONE,
        ));
        let (frame, _, _) = round_trip(&bones, &[], 1);
        for (a, b) in bones.iter().zip(&frame.bones) {
            let (qa, qb) = (a.rotation.normalize(), b.rotation);
            // q and -q are the same rotation: compare the nearer sign.
            let d = (qa - qb).length().min((qa + qb).length());
            assert!(d <= ROTATION_ERROR, "quaternion error {d}");
            assert!(
                (b.translation - a.translation)
                    .abs()
                    .cmple(
                        frame.translation_error() * 1.0001
                        // plus f32 rounding of min + q * step: a few ulp of values up to ~3
                        + 1e-6
                    )
                    .all()
            );
        }
    }

    #[test]
    fn bad_lanes_are_refused_naming_what_is_wrong() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let bones = random_bones(&mut rng, 4);
        let qbox = translation_box(Vec3::splat(-3.0), Vec3::splat(3.0), &[]).unwrap();
        let mut good = Vec::new();
        palette_lanes(&bones, &[0.5, 1.0, 2.0], &qbox, &mut good).unwrap();
        assert_eq!(good.len(), palette_vertex_count(4, 3));
        assert_eq!(good.len(), 10);
        let mut frame = PaletteFrame::default();
        let read =
            |l: &[[u16; 4]], frame: &mut PaletteFrame| read_palette_lanes(l, &qbox, 4, 3, frame);
        read(&good, &mut frame).unwrap();
        assert_eq!(frame.xi, [0.5, 1.0, 2.0]);
        assert_eq!(
            read(&good[..9], &mut frame),
            Err(PaletteError::Count {
                got: 9,
                expected: 10,
                bones: 4,
                xi: 3
            })
        );
        let mut bad = good.clone();
        bad[2][3] = 4;
        assert_eq!(
            read(&bad, &mut frame),
            Err(PaletteError::QuatIndex { bone: 1, index: 4 })
        );
        let mut bad = good.clone();
        let nan = f32::NAN.to_bits();
        bad[9][0] = nan as u16;
        bad[9][1] = (nan >> 16) as u16;
        assert_eq!(
            read(&bad, &mut frame),
            Err(PaletteError::NotFinite {
                what: "xi",
                index: 2
            })
        );
        // Nothing non-finite is encoded.
        let mut nan = bones.clone();
        nan[2].translation.x = f32::NAN;
        let mut out = vec![[1u16; 4]];
        assert_eq!(
            palette_lanes(&nan, &[], &qbox, &mut out),
            Err(PaletteError::NotFinite {
                what: "bone",
                index: 2
            })
        );
        assert!(out.is_empty());
        // Any lanes of the right count read or are refused: no panic.
        for _ in 0..2000 {
            let lanes: Vec<[u16; 4]> = (0..10)
                .map(|_| std::array::from_fn(|_| rng.random()))
                .collect();
            let _ = read(&lanes, &mut frame);
        }
    }

    #[test]
    fn the_translation_box_holds_the_translations_of_poses_inside_the_vertex_box() {
        // A point p at rest moved to v anywhere in the box by some rotation: t = v - R p.
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let rest: Vec<Vec3> = (0..50)
            .map(|_| Vec3::new(rng.random_range(-1.0..2.0), rng.random_range(0.0..1.0), 0.5))
            .collect();
        let (lo, hi) = (Vec3::new(-2.0, -1.0, 0.0), Vec3::new(3.0, 2.0, 1.0));
        let qbox = translation_box(lo, hi, &rest).unwrap();
        for b in random_bones(&mut rng, 500) {
            let p = rest[rng.random_range(0..rest.len())];
            let v = Vec3::new(
                rng.random_range(lo.x..hi.x),
                rng.random_range(lo.y..hi.y),
                rng.random_range(lo.z..hi.z),
            );
            let t = v - b.rotation * p;
            let back = qbox.dequantise(qbox.quantise(t));
            assert!(
                (back - t)
                    .abs()
                    .cmple(qbox.error_bound() * 1.001 + 1e-6)
                    .all(),
                "{t} clamped to {back}"
            );
        }
    }
}

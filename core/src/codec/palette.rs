//! Palette frames (issue 18, first part): a frame of a skinned mesh as its bone transforms,
//! not its vertices. The base mesh is a fixed linear function of the bones' rigid transforms
//! (linear blend skinning, FKY08 eq. 1: `v = sum_k w_k (R_k p + t_k)`), and the detail layer
//! a fixed linear function of the detail kernel vector (HZY11 eq. 4: `h = D xi + b`), so a
//! viewer that holds the rest mesh, the skin and `D` once needs per frame only the bones and
//! `xi`: 13 bytes per bone and 4 bytes per training example.
//!
//! # Layout (little-endian)
//!
//! ```text
//! 0   4  magic "CRPF"
//! 4   1  version (1)
//! 5   1  flags (0; no bits are defined yet)
//! 6   2  reserved (0)
//! 8   4  seq
//! 12  4  bones B
//! 16  4  xi values N (0: no detail kernel vector)
//! 20 12  translation box min, 3 x f32
//! 32 12  translation box step, 3 x f32 (> 0; a zero extent uses step 1)
//! 44     B x 13 bytes: quaternion (1 byte: the index of the largest component; 3 x u16: the
//!        other three, smallest-three), translation (3 x u16 in the box)
//!        N x f32: xi
//! ```
//!
//! # Error bounds
//!
//! A rotation is stored as its unit quaternion with the largest component made positive and
//! dropped; the other three lie in `[-1/sqrt 2, 1/sqrt 2]` and are quantised to 16 bits, so each
//! is within `h = 1 / (sqrt 2 * 65535)` of the input. The dropped component is rebuilt as
//! `sqrt(1 - sum of squares)`, the quaternion normalised: `|q' - q| <= 4 h` (a conservative
//! bound, [`ROTATION_ERROR`]). Rotating a point `p` by two unit quaternions differs by at most
//! `2 |q' - q| |p|`. A translation is within half a step per axis of its per-frame box
//! ([`PaletteFrame::translation_error`]). So a skinned vertex moves by at most
//! `sum_k w_k (2 ROTATION_ERROR |p| + |translation error|)` ([`vertex_error_bound`]), plus
//! `f32` rounding. `xi` is stored as `f32`, exactly.

use glam::{Quat, Vec3};

use crate::runtime::skin::RigidTransform;

/// The four bytes a palette frame starts with.
pub const PALETTE_MAGIC: [u8; 4] = *b"CRPF";
/// The palette frame format this module writes and reads.
pub const PALETTE_VERSION: u8 = 1;
/// Bytes of the header.
pub const PALETTE_HEADER_LEN: usize = 44;
/// Bytes per bone.
pub const BONE_LEN: usize = 13;

/// Half the quantisation step of a stored quaternion component.
const COMPONENT_HALF_STEP: f32 = std::f32::consts::FRAC_1_SQRT_2 / 65535.0;
/// A bound on `|q' - q|` for a stored unit quaternion (module docs).
pub const ROTATION_ERROR: f32 = 4.0 * COMPONENT_HALF_STEP;

/// Why a palette frame could not be read or written.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PaletteError {
    /// Fewer bytes than the header, or than the header's counts need.
    #[error("palette frame truncated: {len} bytes, expected {expected}")]
    Truncated {
        /// Bytes received.
        len: usize,
        /// Bytes the header (and its counts) need.
        expected: usize,
    },
    /// More bytes than the header's counts need.
    #[error("palette frame: {len} bytes, the header's counts need exactly {expected}")]
    Trailing {
        /// Bytes received.
        len: usize,
        /// Bytes the counts need.
        expected: usize,
    },
    /// The first four bytes are not `CRPF`.
    #[error("bad magic {0:02x?}, expected \"CRPF\"")]
    BadMagic([u8; 4]),
    /// A version this decoder does not read.
    #[error("unsupported palette frame version {0}, this decoder reads version {PALETTE_VERSION}")]
    UnsupportedVersion(u8),
    /// Flags or reserved bytes that are not zero.
    #[error("palette frame: flags {flags:#04x} and reserved {reserved:#06x}, expected zero")]
    Reserved {
        /// The flags byte.
        flags: u8,
        /// The reserved bytes.
        reserved: u16,
    },
    /// A count that does not fit the receiver (a palette of another model).
    #[error("palette frame: {what} {got}, expected {expected}")]
    Count {
        /// `bones` or `xi values`.
        what: &'static str,
        /// In the frame.
        got: usize,
        /// What the receiver holds.
        expected: usize,
    },
    /// The translation box is not finite, or a step is not positive.
    #[error("palette frame: translation box min {min:?} step {step:?} is not usable")]
    BadBox {
        /// Its minimum.
        min: [f32; 3],
        /// Its step.
        step: [f32; 3],
    },
    /// A quaternion's largest-component index above 3.
    #[error("palette frame: bone {bone}: quaternion index {index}, expected 0..=3")]
    QuatIndex {
        /// The bone.
        bone: usize,
        /// The index byte.
        index: u8,
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
    /// The frame's sequence number.
    pub seq: u32,
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

/// Bytes of a palette frame of `bones` bones and `xi` kernel values.
pub fn palette_frame_len(bones: usize, xi: usize) -> usize {
    PALETTE_HEADER_LEN + bones * BONE_LEN + xi * 4
}

/// Appends the palette frame of `bones` and `xi` with sequence number `seq` to `out`.
///
/// # Errors
/// [`PaletteError::NotFinite`] for a non-finite rotation, translation or `xi` value (nothing is
/// written then).
pub fn encode_palette_frame(
    seq: u32,
    bones: &[RigidTransform],
    xi: &[f32],
    out: &mut Vec<u8>,
) -> Result<(), PaletteError> {
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
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for b in bones {
        lo = lo.min(b.translation);
        hi = hi.max(b.translation);
    }
    if bones.is_empty() {
        (lo, hi) = (Vec3::ZERO, Vec3::ZERO);
    }
    let extent = hi - lo;
    // A zero extent (one bone, or all translations equal on an axis) stores that axis exactly.
    let step = Vec3::select(extent.cmpgt(Vec3::ZERO), extent / 65535.0, Vec3::ONE);
    out.reserve(palette_frame_len(bones.len(), xi.len()));
    out.extend_from_slice(&PALETTE_MAGIC);
    out.push(PALETTE_VERSION);
    out.push(0);
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&seq.to_le_bytes());
    out.extend_from_slice(&(bones.len() as u32).to_le_bytes());
    out.extend_from_slice(&(xi.len() as u32).to_le_bytes());
    for v in lo.to_array().into_iter().chain(step.to_array()) {
        out.extend_from_slice(&v.to_le_bytes());
    }
    for b in bones {
        let (index, q) = smallest_three(b.rotation);
        out.push(index);
        for c in q {
            out.extend_from_slice(&c.to_le_bytes());
        }
        let t = ((b.translation - lo) / step)
            .round()
            .clamp(Vec3::ZERO, Vec3::splat(65535.0));
        for c in t.to_array() {
            out.extend_from_slice(&(c as u16).to_le_bytes());
        }
    }
    for v in xi {
        out.extend_from_slice(&v.to_le_bytes());
    }
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

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn f32_at(b: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

/// Decodes a palette frame into `frame` (its buffers reused), checking that it has `bones`
/// bones and `xi` kernel values (those of the receiver's model).
///
/// # Errors
/// [`PaletteError`]; `frame` is unchanged but for its buffers' contents then. Never panics.
pub fn decode_palette_frame(
    bytes: &[u8],
    bones: usize,
    xi: usize,
    frame: &mut PaletteFrame,
) -> Result<(), PaletteError> {
    if bytes.len() < PALETTE_HEADER_LEN {
        return Err(PaletteError::Truncated {
            len: bytes.len(),
            expected: PALETTE_HEADER_LEN,
        });
    }
    let magic = [bytes[0], bytes[1], bytes[2], bytes[3]];
    if magic != PALETTE_MAGIC {
        return Err(PaletteError::BadMagic(magic));
    }
    if bytes[4] != PALETTE_VERSION {
        return Err(PaletteError::UnsupportedVersion(bytes[4]));
    }
    let (flags, reserved) = (bytes[5], u16_at(bytes, 6));
    if flags != 0 || reserved != 0 {
        return Err(PaletteError::Reserved { flags, reserved });
    }
    let seq = u32_at(bytes, 8);
    let (b, n) = (u32_at(bytes, 12) as usize, u32_at(bytes, 16) as usize);
    if b != bones {
        return Err(PaletteError::Count {
            what: "bones",
            got: b,
            expected: bones,
        });
    }
    if n != xi {
        return Err(PaletteError::Count {
            what: "xi values",
            got: n,
            expected: xi,
        });
    }
    let expected = palette_frame_len(b, n);
    if bytes.len() < expected {
        return Err(PaletteError::Truncated {
            len: bytes.len(),
            expected,
        });
    }
    if bytes.len() > expected {
        return Err(PaletteError::Trailing {
            len: bytes.len(),
            expected,
        });
    }
    let min = Vec3::new(f32_at(bytes, 20), f32_at(bytes, 24), f32_at(bytes, 28));
    let step = Vec3::new(f32_at(bytes, 32), f32_at(bytes, 36), f32_at(bytes, 40));
    if !(min.is_finite() && step.is_finite() && step.cmpgt(Vec3::ZERO).all()) {
        return Err(PaletteError::BadBox {
            min: min.to_array(),
            step: step.to_array(),
        });
    }
    frame.bones.clear();
    for k in 0..b {
        let at = PALETTE_HEADER_LEN + k * BONE_LEN;
        let index = bytes[at];
        if index > 3 {
            return Err(PaletteError::QuatIndex { bone: k, index });
        }
        let q = [
            u16_at(bytes, at + 1),
            u16_at(bytes, at + 3),
            u16_at(bytes, at + 5),
        ];
        let t = Vec3::new(
            f32::from(u16_at(bytes, at + 7)),
            f32::from(u16_at(bytes, at + 9)),
            f32::from(u16_at(bytes, at + 11)),
        );
        frame.bones.push(RigidTransform::new(
            from_smallest_three(usize::from(index), q),
            min + t * step,
        ));
    }
    frame.xi.clear();
    let xi_at = PALETTE_HEADER_LEN + b * BONE_LEN;
    for k in 0..n {
        let v = f32_at(bytes, xi_at + 4 * k);
        if !v.is_finite() {
            return Err(PaletteError::NotFinite {
                what: "xi",
                index: k,
            });
        }
        frame.xi.push(v);
    }
    frame.seq = seq;
    frame.step = step;
    Ok(())
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

    #[test]
    fn skinned_points_from_decoded_bones_stay_within_the_bound() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(18);
        let bones = random_bones(&mut rng, 150);
        let xi: Vec<f32> = (0..14).map(|k| 0.1 * k as f32 - 0.3).collect();
        let mut bytes = Vec::new();
        encode_palette_frame(7, &bones, &xi, &mut bytes).unwrap();
        assert_eq!(bytes.len(), palette_frame_len(150, 14));
        assert_eq!(bytes.len(), 44 + 150 * 13 + 14 * 4);
        let mut frame = PaletteFrame::default();
        decode_palette_frame(&bytes, 150, 14, &mut frame).unwrap();
        assert_eq!(frame.seq, 7);
        assert_eq!(frame.xi, xi, "xi travels exactly");
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
        // The bound is not vacuous: the worst case uses a good part of it, and it is small.
        assert!(worst > 0.05, "worst error / bound {worst}");
        assert!(vertex_error_bound(&frame, Vec3::ONE, &[(0, 1.0)]) < 2e-4);
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
        let mut bytes = Vec::new();
        encode_palette_frame(0, &bones, &[], &mut bytes).unwrap();
        let mut frame = PaletteFrame::default();
        decode_palette_frame(&bytes, bones.len(), 0, &mut frame).unwrap();
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
    fn one_bone_and_no_bones_encode_exactly_where_the_box_is_flat() {
        let bone = RigidTransform::new(Quat::IDENTITY, Vec3::new(1.25, -3.0, 0.5));
        let mut bytes = Vec::new();
        encode_palette_frame(1, &[bone], &[], &mut bytes).unwrap();
        let mut frame = PaletteFrame::default();
        decode_palette_frame(&bytes, 1, 0, &mut frame).unwrap();
        assert_eq!(frame.bones[0].translation, bone.translation);
        bytes.clear();
        encode_palette_frame(2, &[], &[], &mut bytes).unwrap();
        decode_palette_frame(&bytes, 0, 0, &mut frame).unwrap();
        assert!(frame.bones.is_empty() && frame.seq == 2);
    }

    #[test]
    fn bad_frames_are_refused_naming_what_is_wrong() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let bones = random_bones(&mut rng, 4);
        let mut good = Vec::new();
        encode_palette_frame(3, &bones, &[0.5, 1.0], &mut good).unwrap();
        let mut frame = PaletteFrame::default();
        let decode = |b: &[u8], frame: &mut PaletteFrame| decode_palette_frame(b, 4, 2, frame);
        assert!(matches!(
            decode(&good[..10], &mut frame),
            Err(PaletteError::Truncated { len: 10, .. })
        ));
        assert!(matches!(
            decode(&good[..good.len() - 1], &mut frame),
            Err(PaletteError::Truncated { .. })
        ));
        let mut long = good.clone();
        long.push(0);
        assert!(matches!(
            decode(&long, &mut frame),
            Err(PaletteError::Trailing { .. })
        ));
        let mut bad = good.clone();
        bad[0] = b'X';
        assert!(matches!(
            decode(&bad, &mut frame),
            Err(PaletteError::BadMagic(_))
        ));
        let mut bad = good.clone();
        bad[4] = 2;
        assert_eq!(
            decode(&bad, &mut frame),
            Err(PaletteError::UnsupportedVersion(2))
        );
        let mut bad = good.clone();
        bad[5] = 1;
        assert!(matches!(
            decode(&bad, &mut frame),
            Err(PaletteError::Reserved { flags: 1, .. })
        ));
        assert_eq!(
            decode_palette_frame(&good, 5, 2, &mut frame),
            Err(PaletteError::Count {
                what: "bones",
                got: 4,
                expected: 5
            })
        );
        let mut bad = good.clone();
        bad[32..36].copy_from_slice(&0f32.to_le_bytes());
        assert!(matches!(
            decode(&bad, &mut frame),
            Err(PaletteError::BadBox { .. })
        ));
        let mut bad = good.clone();
        bad[PALETTE_HEADER_LEN + BONE_LEN] = 4;
        assert_eq!(
            decode(&bad, &mut frame),
            Err(PaletteError::QuatIndex { bone: 1, index: 4 })
        );
        let mut bad = good.clone();
        let xi_at = PALETTE_HEADER_LEN + 4 * BONE_LEN;
        bad[xi_at..xi_at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert_eq!(
            decode(&bad, &mut frame),
            Err(PaletteError::NotFinite {
                what: "xi",
                index: 0
            })
        );
        // Nothing non-finite is encoded.
        let mut nan = bones.clone();
        nan[2].translation.x = f32::NAN;
        let mut out = Vec::new();
        assert_eq!(
            encode_palette_frame(0, &nan, &[], &mut out),
            Err(PaletteError::NotFinite {
                what: "bone",
                index: 2
            })
        );
        assert!(out.is_empty());
        // Every prefix and every single-byte change either decodes or is refused: no panic.
        for cut in 0..good.len() {
            let _ = decode(&good[..cut], &mut frame);
        }
        for i in 0..good.len() {
            let mut b = good.clone();
            b[i] ^= 0xA5;
            let _ = decode(&b, &mut frame);
        }
    }
}

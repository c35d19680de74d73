//! Quantisation: positions to 16-bit integers in a fixed box, normals to 8-bit octahedral pairs.

use glam::Vec3;

use super::CodecError;

/// The largest angle, in degrees, between a unit vector and its 8-bit octahedral round trip
/// ([`oct_encode`] then [`oct_decode`]). With `round(c * 127)` a coordinate is off by at most
/// `1/254` in the octahedral square, and the map from the square to the sphere stretches that to
/// under a degree: measured 0.935° at worst (mean 0.34°) over 200,000 evenly spread directions
/// (`core/tests/codec.rs`), so 1° is the stated bound. Encoding picks the nearest grid point in
/// the square, not the best on the sphere (CDE14's "precise" variant), to keep encoding cheap.
pub const OCT_MAX_ERROR_DEG: f64 = 1.0;

/// A fixed axis-aligned box and grid positions are quantised in: `q = round((p - min) / step)`,
/// clamped to `0..=2^bits - 1`, decoded `p' = min + q * step`.
///
/// **Error bound.** Inside the box, `|p' - p| <= step / 2` per axis ([`QuantBox::error_bound`]),
/// with `step = extent / (2^bits - 1)`: `extent / 65535 / 2` at 16 bits. The decoded value is
/// rounded once to `f32` (computed in `f64`), which adds at most half an `f32` ulp of `p'`.
///
/// **Outside the box** each coordinate clamps to the nearest face (`-inf` to 0, `+inf` to the top
/// level). **NaN** maps to the middle level `2^(bits-1)` (the box's centre, to within half a
/// step), so a bad vertex shows up in the middle of the model instead of at a corner. Nothing
/// panics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuantBox {
    min: Vec3,
    step: Vec3,
    bits: u8,
    /// `1 / step` in f64, for [`QuantBox::quantise`].
    inv_step: [f64; 3],
}

impl QuantBox {
    /// The box around `lo..=hi` padded by `margin` times the largest side on every side (e.g.
    /// `0.25`: deformed poses leave the rest pose's box), on a grid of `bits` bits per axis.
    ///
    /// An axis of zero extent (a flat mesh with no margin) takes the largest axis's extent,
    /// centred on its value; if every axis is zero (one point), the extent is 1.0. `step` is
    /// rounded up to the next `f32` when needed so that `hi` stays inside the box.
    ///
    /// # Errors
    /// [`CodecError::InvalidBox`] for non-finite corners, `lo > hi` on an axis, a negative or
    /// non-finite margin, `bits` outside `1..=16`, or an extent that overflows `f32`.
    pub fn from_bounds(lo: Vec3, hi: Vec3, margin: f32, bits: u8) -> Result<QuantBox, CodecError> {
        if !(1..=16).contains(&bits) {
            return Err(CodecError::InvalidBox("bits must be 1..=16"));
        }
        if !lo.is_finite() || !hi.is_finite() {
            return Err(CodecError::InvalidBox("bounds are not finite"));
        }
        if lo.cmpgt(hi).any() {
            return Err(CodecError::InvalidBox("lower corner above upper corner"));
        }
        if !margin.is_finite() || margin < 0.0 {
            return Err(CodecError::InvalidBox(
                "margin must be finite and non-negative",
            ));
        }
        let levels = f64::from(levels(bits));
        let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
        let side = hi - lo;
        let pad = side.max_element() * f64::from(margin);
        let (mut lo, mut hi) = (lo - pad, hi + pad);
        let widest = (hi - lo).max_element();
        let fallback = if widest > 0.0 { widest } else { 1.0 };
        for k in 0..3 {
            if hi[k] - lo[k] <= 0.0 {
                lo[k] -= fallback / 2.0;
                hi[k] += fallback / 2.0;
            }
        }
        let mut min = [0f32; 3];
        let mut step = [0f32; 3];
        for k in 0..3 {
            // Round min down and step up so the f32 box still covers [lo, hi].
            let mut m = lo[k] as f32;
            if f64::from(m) > lo[k] {
                m = m.next_down();
            }
            let extent = hi[k] - f64::from(m);
            let mut s = (extent / levels) as f32;
            if f64::from(s) * levels < extent {
                s = s.next_up();
            }
            let top = f64::from(m) + levels * f64::from(s);
            if !m.is_finite() || !s.is_finite() || s <= 0.0 || top > f64::from(f32::MAX) {
                return Err(CodecError::InvalidBox("extent does not fit an f32 grid"));
            }
            min[k] = m;
            step[k] = s;
        }
        QuantBox::from_min_step(Vec3::from(min), Vec3::from(step), bits)
    }

    /// [`QuantBox::from_bounds`] around the bounding box of `positions` (the non-finite ones
    /// ignored; an empty or all-NaN slice gives the unit box at the origin).
    ///
    /// # Errors
    /// As [`QuantBox::from_bounds`].
    pub fn from_positions(
        positions: &[Vec3],
        margin: f32,
        bits: u8,
    ) -> Result<QuantBox, CodecError> {
        let mut it = positions.iter().filter(|p| p.is_finite());
        let (lo, hi) = match it.next() {
            Some(&first) => it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
            None => (Vec3::ZERO, Vec3::ZERO),
        };
        QuantBox::from_bounds(lo, hi, margin, bits)
    }

    /// A box given by its lower corner and step, e.g. as read from a frame header.
    ///
    /// # Errors
    /// [`CodecError::InvalidBox`] if `min` is not finite, a step is not finite and positive, or
    /// `bits` is outside `1..=16`.
    pub fn from_min_step(min: Vec3, step: Vec3, bits: u8) -> Result<QuantBox, CodecError> {
        if !(1..=16).contains(&bits) {
            return Err(CodecError::InvalidBox("bits must be 1..=16"));
        }
        if !min.is_finite() {
            return Err(CodecError::InvalidBox("min is not finite"));
        }
        if !step.is_finite() || step.cmple(Vec3::ZERO).any() {
            return Err(CodecError::InvalidBox("step must be finite and positive"));
        }
        let inv_step = step.as_dvec3().recip().to_array();
        Ok(QuantBox {
            min,
            step,
            bits,
            inv_step,
        })
    }

    /// The lower corner.
    pub fn min(&self) -> Vec3 {
        self.min
    }

    /// The grid step per axis.
    pub fn step(&self) -> Vec3 {
        self.step
    }

    /// Bits per axis (1..=16).
    pub fn bits(&self) -> u8 {
        self.bits
    }

    /// The highest level, `2^bits - 1`.
    pub fn max_level(&self) -> u16 {
        levels(self.bits)
    }

    /// The upper corner, `min + (2^bits - 1) * step` (rounded to `f32`).
    pub fn max(&self) -> Vec3 {
        self.dequantise([self.max_level(); 3])
    }

    /// The largest error of a decoded position inside the box, per axis: half a step.
    pub fn error_bound(&self) -> Vec3 {
        self.step * 0.5
    }

    /// One position on the grid (see the type's docs for clamping and NaN).
    #[inline]
    pub fn quantise(&self, p: Vec3) -> [u16; 3] {
        let top = f64::from(self.max_level());
        let mid = 1u16 << (self.bits - 1);
        let mut q = [0u16; 3];
        for (k, out) in q.iter_mut().enumerate() {
            // In f64, so the grid index is exact to far below a step for any f32 input; a
            // multiplication by the reciprocal moves it by ~1e-16 steps at most, and is cheaper
            // than a division.
            let t = (f64::from(p[k]) - f64::from(self.min[k])) * self.inv_step[k];
            *out = if t.is_nan() {
                mid
            } else {
                // Round half up by truncation: t is in 0..=top after the clamp, so the cast is
                // exact and needs no libm `round` call (this loop is most of the encoder's
                // own time).
                (t.clamp(0.0, top) + 0.5) as u16
            };
        }
        q
    }

    /// A grid point back to a position: `min + q * step` in `f64`, rounded once to `f32`
    /// (`Math.fround(min + q * step)` in JavaScript gives the same bits).
    #[inline]
    pub fn dequantise(&self, q: [u16; 3]) -> Vec3 {
        let c =
            |k: usize| (f64::from(self.min[k]) + f64::from(q[k]) * f64::from(self.step[k])) as f32;
        Vec3::new(c(0), c(1), c(2))
    }
}

/// `2^bits - 1` for `bits` in `1..=16`.
fn levels(bits: u8) -> u16 {
    (((1u32) << bits) - 1) as u16
}

/// `±1` with the sign of `x`, `+1` for zero (CDE14 `signNotZero`).
fn sign_not_zero(x: f32) -> f32 {
    if x < 0.0 { -1.0 } else { 1.0 }
}

/// A normal to two signed 8-bit octahedral coordinates (CDE14 §3.3, listing 1: project onto the
/// octahedron `|x| + |y| + |z| = 1`, fold the lower half over the diagonals, then snorm8
/// `round(c * 127)`). The input need not be unit length. A zero, non-finite or NaN vector
/// encodes as `+Z` (`[0, 0]`).
#[inline]
pub fn oct_encode(n: Vec3) -> [i8; 2] {
    let l1 = n.x.abs() + n.y.abs() + n.z.abs();
    if !(l1.is_finite() && l1 > 0.0) {
        return [0, 0];
    }
    let (mut u, mut v) = (n.x / l1, n.y / l1);
    if n.z < 0.0 {
        let (pu, pv) = (u, v);
        u = (1.0 - pv.abs()) * sign_not_zero(pu);
        v = (1.0 - pu.abs()) * sign_not_zero(pv);
    }
    // round(c * 127), half away from zero, by truncation (no libm call).
    let snorm = |c: f32| {
        let x = c.clamp(-1.0, 1.0) * 127.0;
        (x + 0.5f32.copysign(x)) as i8
    };
    [snorm(u), snorm(v)]
}

/// Two octahedral coordinates back to a unit normal, computed in `f64` and rounded to `f32` at
/// the end (so a JavaScript decoder doing the same operations in `Number`s and `Math.fround`
/// matches bit for bit):
/// ```text
/// u = max(a / 127, -1); v = max(b / 127, -1); z = 1 - |u| - |v|
/// if z < 0 { (u, v) = ((1 - |v|) * signNotZero(u), (1 - |u|) * signNotZero(v)) }
/// len = sqrt(u*u + v*v + z*z); n = (fround(u / len), fround(v / len), fround(z / len))
/// ```
#[inline]
pub fn oct_decode(o: [i8; 2]) -> Vec3 {
    let mut u = (f64::from(o[0]) / 127.0).max(-1.0);
    let mut v = (f64::from(o[1]) / 127.0).max(-1.0);
    let z = 1.0 - u.abs() - v.abs();
    if z < 0.0 {
        let (pu, pv) = (u, v);
        u = (1.0 - pv.abs()) * if pu < 0.0 { -1.0 } else { 1.0 };
        v = (1.0 - pu.abs()) * if pv < 0.0 { -1.0 } else { 1.0 };
    }
    // The octahedron's points have |u| + |v| + |z| = 1, so len >= 1/sqrt(3): no division by 0.
    let len = (u * u + v * v + z * z).sqrt();
    Vec3::new((u / len) as f32, (v / len) as f32, (z / len) as f32)
}

/// The `w` lane for a normal: `u` in the low byte, `v` in the high byte.
#[inline]
pub(crate) fn normal_lane(n: Vec3) -> u16 {
    let [u, v] = oct_encode(n);
    u16::from_le_bytes([u as u8, v as u8])
}

/// The normal stored in a `w` lane.
#[inline]
pub(crate) fn lane_normal(w: u16) -> Vec3 {
    let [u, v] = w.to_le_bytes();
    oct_decode([u as i8, v as i8])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nan_goes_to_the_middle_level_and_infinities_clamp() {
        let b = QuantBox::from_bounds(Vec3::ZERO, Vec3::ONE, 0.0, 16).unwrap();
        assert_eq!(
            b.quantise(Vec3::new(f32::NAN, f32::INFINITY, f32::NEG_INFINITY)),
            [32768, 65535, 0]
        );
        let b4 = QuantBox::from_bounds(Vec3::ZERO, Vec3::ONE, 0.0, 4).unwrap();
        assert_eq!(b4.quantise(Vec3::splat(f32::NAN)), [8, 8, 8]);
        assert_eq!(b4.quantise(Vec3::splat(2.0)), [15, 15, 15]);
    }

    #[test]
    fn corners_of_the_bounds_stay_inside_the_box() {
        let (lo, hi) = (
            Vec3::new(-0.3, 1e-3, -7.1),
            Vec3::new(0.7, 1e-3 + 1e-6, 9.9),
        );
        let b = QuantBox::from_bounds(lo, hi, 0.0, 16).unwrap();
        assert!(b.min().cmple(lo).all());
        assert!(
            (b.dequantise([65535; 3]) - hi)
                .abs()
                .cmple(b.error_bound())
                .all()
        );
        assert_eq!(b.quantise(lo), [0, 0, 0]);
        assert_eq!(b.quantise(hi), [65535; 3]);
    }

    #[test]
    fn degenerate_boxes_get_a_usable_extent() {
        let flat = QuantBox::from_bounds(Vec3::ZERO, Vec3::new(2.0, 0.0, 1.0), 0.0, 16).unwrap();
        assert!((flat.step().y * 65535.0 - 2.0).abs() < 1e-5);
        let point = QuantBox::from_bounds(Vec3::ONE, Vec3::ONE, 0.25, 16).unwrap();
        assert!((point.step() * 65535.0 - Vec3::ONE).abs().max_element() < 1e-5);
        assert!(QuantBox::from_bounds(Vec3::ZERO, Vec3::ONE, f32::NAN, 16).is_err());
        assert!(QuantBox::from_bounds(Vec3::ONE, Vec3::ZERO, 0.0, 16).is_err());
        assert!(QuantBox::from_bounds(Vec3::ZERO, Vec3::ONE, 0.0, 0).is_err());
        assert!(QuantBox::from_bounds(Vec3::ZERO, Vec3::splat(f32::MAX), 1.0, 16).is_err());
    }

    #[test]
    fn oct_encodes_zero_and_nan_as_plus_z() {
        assert_eq!(oct_encode(Vec3::ZERO), [0, 0]);
        assert_eq!(oct_encode(Vec3::new(f32::NAN, 0.0, 1.0)), [0, 0]);
        assert_eq!(oct_decode([0, 0]), Vec3::Z);
        assert_eq!(oct_decode(oct_encode(-Vec3::Z)), -Vec3::Z);
        assert_eq!(oct_decode(oct_encode(Vec3::X)), Vec3::X);
        // -128 is never produced but decodes as -1 (snorm rule).
        assert_eq!(oct_decode([-128, 0]), oct_decode([-127, 0]));
    }
}

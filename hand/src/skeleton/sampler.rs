//! [`PoseSampler`]: a seeded sampler of natural hand poses (a latent grip driving coupled
//! finger flexion, within the limits), on a small SplitMix64 generator.

use super::{Digit, DofKind, HandPose, Joint, JointLimits};

/// SplitMix64 (Steele, Lea & Flood 2014): a tiny, well-mixed, seedable generator; enough for
/// sampling poses, and it keeps `rand` out of core.
#[derive(Clone, Debug)]
struct SplitMix64(u64);

impl SplitMix64 {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)` with 24 random bits (all an `f32` mantissa holds).
    fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// Triangular in `(-1, 1)`, peaked at 0: a cheap bounded stand-in for Gaussian jitter.
    fn jitter(&mut self) -> f32 {
        self.uniform() - self.uniform()
    }
}

/// Seeded sampler of natural hand poses.
///
/// A latent grip amount in `[0, 1]` drives every finger's flexion together; each finger
/// follows it with its own jitter (and a small chance, highest for the index, of staying
/// straight on its own, as in pointing); PIP follows MCP and DIP is about 2/3 of PIP, the
/// coupling of the flexor tendons (Rijpkema & Girard 1991); abduction shrinks as the fingers
/// flex (a flexed MCP's collateral ligaments are taut); ring and little cup with the grip;
/// the thumb mixes the grip with its own random amount. The result is always clamped to the
/// limits, so every sample is within them.
#[derive(Clone, Debug)]
pub struct PoseSampler {
    rng: SplitMix64,
    limits: JointLimits,
}

impl PoseSampler {
    /// A sampler over [`JointLimits::adult`]; the same seed gives the same sequence.
    pub fn new(seed: u64) -> Self {
        PoseSampler::with_limits(seed, JointLimits::adult())
    }

    /// A sampler whose samples are clamped to `limits`.
    pub fn with_limits(seed: u64, limits: JointLimits) -> Self {
        PoseSampler {
            rng: SplitMix64(seed),
            limits,
        }
    }

    /// The next pose.
    pub fn sample(&mut self) -> HandPose {
        let r = &mut self.rng;
        let mut p = HandPose::FLAT;
        let grip = r.uniform();
        let spread = r.uniform();
        p.set_deg(Joint::Wrist, DofKind::Flexion, 25.0 * r.jitter());
        p.set_deg(Joint::Wrist, DofKind::Abduction, 10.0 * r.jitter());
        // Per finger: chance of staying straight independently of the grip, the ulnar cascade
        // (ulnar fingers curl a little more at the same grip), and the largest spread, degrees.
        let fingers = [
            (Digit::Index, 0.20, 0.00, 20.0),
            (Digit::Middle, 0.08, 0.03, 5.0),
            (Digit::Ring, 0.04, 0.06, 15.0),
            (Digit::Little, 0.08, 0.09, 20.0),
        ];
        let mut cupping = [0.0f32; 2];
        for (digit, straight, cascade, max_spread) in fingers {
            let g = if r.uniform() < straight {
                0.1 * r.uniform()
            } else {
                (grip + cascade + 0.15 * r.jitter()).clamp(0.0, 1.0)
            };
            let mcp = -10.0 + 98.0 * g + 6.0 * r.jitter();
            let pip = (105.0 * g + 8.0 * r.jitter()).max(0.0);
            let dip = (2.0 / 3.0) * pip + 5.0 * r.jitter();
            let abduction = (1.0 - g) * spread * max_spread + 3.0 * r.jitter();
            p.set_finger(digit, mcp, abduction, pip, dip);
            match digit {
                Digit::Ring => cupping[0] = 10.0 * g * r.uniform(),
                Digit::Little => cupping[1] = 15.0 * g * r.uniform(),
                _ => {}
            }
        }
        p.set_cupping(cupping[0], cupping[1]);
        let t = 0.5 * grip + 0.5 * r.uniform();
        let thumb_mcp = 55.0 * t + 8.0 * r.jitter();
        p.set_thumb(
            -15.0 + 60.0 * t + 5.0 * r.jitter(),
            -5.0 + 60.0 * r.uniform(),
            thumb_mcp,
            0.8 * thumb_mcp + 8.0 * r.jitter(),
        );
        p.clamp(&self.limits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix_matches_reference_values() {
        // The first outputs for this seed in rand_xoshiro's `reference` test (rust-random/rngs,
        // rand_xoshiro/src/splitmix64.rs), produced with Vigna's splitmix64.c.
        let mut r = SplitMix64(1477776061723855037);
        for expected in [
            1985237415132408290,
            2979275885539914483,
            13511426838097143398,
        ] {
            assert_eq!(r.next_u64(), expected);
        }
    }
}

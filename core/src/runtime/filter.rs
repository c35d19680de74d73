//! The One Euro filter (Casiez, Roussel, Vogel 2012, "1€ Filter: A Simple Speed-based Low-pass
//! Filter for Noisy Input in Interactive Systems", CHI '12) on marker positions.
//!
//! Each sample is smoothed by a first-order low-pass whose cutoff rises with the speed of the
//! signal: `fc = min_cutoff + beta · |ẋ|`, where `ẋ` is itself low-passed at `d_cutoff`.
//! Still markers get heavy smoothing (jitter removed), fast ones little (lag removed). Per
//! sample with period `Te`: `α(fc) = 1 / (1 + τ/Te)`, `τ = 1 / (2π fc)`, and
//! `x̂ = x̂_prev + α (x - x̂_prev)` (paper §4, eqs. 1-5). For a 3-D point the speed is the
//! length of the velocity vector, so the three axes share one cutoff.
//!
//! # Lag bound
//!
//! Because `fc ≥ min_cutoff` always, every step removes at least the fraction
//! `α_min = α(min_cutoff)` of the remaining error. After a step input of any size, the output's
//! remaining error after `k` samples is at most `(1 - α_min)^k` of the step: the filter is never
//! slower than a plain low-pass at `min_cutoff`. [`OneEuroParams::settle_samples`] turns that
//! into the number of samples after which the output is within a fraction of a step, and the
//! tests check the filter against it (and that `beta` makes a large step settle much sooner).
//!
//! A marker that drops out resets its filter: when it reappears it starts from the new sample,
//! not from a stale estimate.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// One Euro parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct OneEuroParams {
    /// Cutoff at rest, Hz (jitter removal; lower = smoother and laggier).
    pub min_cutoff_hz: f32,
    /// Cutoff increase per unit of speed, Hz per (unit/s) (lag removal when moving).
    pub beta: f32,
    /// Cutoff of the speed estimate, Hz.
    pub d_cutoff_hz: f32,
}

impl Default for OneEuroParams {
    /// Settings for positions in metres at 60-120 Hz: 1.5 Hz at rest, +1 Hz per 0.1 m/s (the
    /// paper's tuning procedure: min_cutoff for jitter at rest, then beta for lag at speed),
    /// 1 Hz for the speed estimate as the paper suggests.
    fn default() -> Self {
        OneEuroParams {
            min_cutoff_hz: 1.5,
            beta: 10.0,
            d_cutoff_hz: 1.0,
        }
    }
}

/// `α` of a first-order low-pass with cutoff `fc` (Hz) sampled every `dt` seconds (paper eq. 4).
pub fn alpha(fc: f32, dt: f32) -> f32 {
    let tau = 1.0 / (2.0 * std::f32::consts::PI * fc);
    1.0 / (1.0 + tau / dt)
}

impl OneEuroParams {
    /// Whether every parameter is finite and usable (cutoffs positive, beta non-negative).
    pub fn is_valid(&self) -> bool {
        self.min_cutoff_hz.is_finite()
            && self.min_cutoff_hz > 0.0
            && self.beta.is_finite()
            && self.beta >= 0.0
            && self.d_cutoff_hz.is_finite()
            && self.d_cutoff_hz > 0.0
    }

    /// The documented lag bound (module docs): samples at period `dt` after which the output is
    /// within `fraction` of a step input, whatever the step's size.
    pub fn settle_samples(&self, dt: f32, fraction: f32) -> usize {
        let keep = 1.0 - alpha(self.min_cutoff_hz, dt);
        if keep <= 0.0 {
            return 1;
        }
        (fraction.ln() / keep.ln()).ceil().max(1.0) as usize
    }
}

/// A One Euro filter on one 3-D point.
#[derive(Clone, Copy, Debug)]
pub struct OneEuro {
    params: OneEuroParams,
    state: Option<(Vec3, Vec3)>,
}

impl OneEuro {
    /// A filter with no history.
    pub fn new(params: OneEuroParams) -> OneEuro {
        OneEuro {
            params,
            state: None,
        }
    }

    /// Forgets the history (the next sample passes through).
    pub fn reset(&mut self) {
        self.state = None;
    }

    /// Filters a sample taken `dt` seconds after the previous one. The first sample after
    /// [`new`](Self::new) or [`reset`](Self::reset) passes through; a non-positive or
    /// non-finite `dt` is treated as a repeat of the previous time (the sample is ignored).
    pub fn filter(&mut self, x: Vec3, dt: f32) -> Vec3 {
        let Some((prev, dprev)) = self.state else {
            self.state = Some((x, Vec3::ZERO));
            return x;
        };
        if !(dt.is_finite() && dt > 0.0 && x.is_finite()) {
            return prev;
        }
        // Paper §4: speed, low-passed at d_cutoff; cutoff from it; then the position.
        let dx = (x - prev) / dt;
        let edx = dprev + alpha(self.params.d_cutoff_hz, dt) * (dx - dprev);
        let fc = self.params.min_cutoff_hz + self.params.beta * edx.length();
        let out = prev + alpha(fc, dt) * (x - prev);
        self.state = Some((out, edx));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alpha_matches_the_rc_formula() {
        // α = dt / (dt + RC), RC = 1 / (2π fc): at fc = 1/(2π) Hz, RC = 1 s.
        let fc = 1.0 / (2.0 * std::f32::consts::PI);
        assert!((alpha(fc, 0.5) - 0.5 / 1.5).abs() < 1e-6);
    }

    #[test]
    fn a_step_settles_within_the_documented_bound() {
        let dt = 0.01;
        for params in [
            OneEuroParams::default(),
            OneEuroParams {
                min_cutoff_hz: 0.5,
                beta: 0.0,
                d_cutoff_hz: 1.0,
            },
        ] {
            for step in [0.001f32, 0.01, 0.1] {
                let mut f = OneEuro::new(params);
                f.filter(Vec3::ZERO, dt);
                let target = Vec3::new(step, 0.0, 0.0);
                let bound = params.settle_samples(dt, 0.1);
                let mut settled_at = None;
                for k in 1..=bound {
                    let y = f.filter(target, dt);
                    // Never overshoots, never moves away.
                    assert!(y.x >= 0.0 && y.x <= step * (1.0 + 1e-6), "{y}");
                    // The per-sample bound (1 - α_min)^k.
                    let keep = (1.0 - alpha(params.min_cutoff_hz, dt)).powi(k as i32);
                    assert!(
                        (step - y.x) <= keep * step * (1.0 + 1e-4),
                        "k {k}: {} left, bound {}",
                        step - y.x,
                        keep * step
                    );
                    if settled_at.is_none() && step - y.x <= 0.1 * step {
                        settled_at = Some(k);
                    }
                }
                let settled = settled_at.expect("within 10% by the bound");
                assert!(settled <= bound);
                if params.beta > 0.0 && step >= 0.1 {
                    // Speed raises the cutoff: a 10 cm jump settles in a fraction of the
                    // at-rest bound.
                    assert!(settled * 4 <= bound, "{settled} of {bound}");
                }
            }
        }
    }

    #[test]
    fn smooths_jitter_at_rest_and_resets() {
        let mut f = OneEuro::new(OneEuroParams::default());
        let dt = 0.01;
        // ±0.5 mm alternating jitter around 0: the output's swing is far smaller.
        let mut swing: f32 = 0.0;
        for k in 0..200 {
            let x = Vec3::new(if k % 2 == 0 { 0.0005 } else { -0.0005 }, 0.0, 0.0);
            let y = f.filter(x, dt);
            if k > 100 {
                swing = swing.max(y.x.abs());
            }
        }
        assert!(swing < 0.0002, "{swing}");
        f.reset();
        assert_eq!(f.filter(Vec3::ONE, dt), Vec3::ONE);
        // Bad time steps and samples leave the state alone.
        assert_eq!(f.filter(Vec3::ZERO, 0.0), Vec3::ONE);
        assert_eq!(f.filter(Vec3::NAN, dt), Vec3::ONE);
    }
}

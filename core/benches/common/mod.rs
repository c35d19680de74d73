//! Helpers shared by the benchmarks.

use std::time::{Duration, Instant};

/// Median and minimum wall time of `f` over `iters` runs (after a warm-up). The minimum is the
/// figure to trust on a machine shared with other work.
pub(crate) fn timings(iters: usize, mut f: impl FnMut()) -> (Duration, Duration) {
    for _ in 0..iters / 10 + 1 {
        f();
    }
    let mut t: Vec<Duration> = (0..iters)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed()
        })
        .collect();
    t.sort();
    (t[iters / 2], t[0])
}

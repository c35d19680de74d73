//! Per-frame synthesis. Everything here writes into caller-provided buffers and allocates
//! nothing per frame.
//!
//! Layout:
//! - [`skin`]: linear-blend and dual-quaternion skinning: bone transforms, skin weights, the
//!   per-frame bone palette, and the packed LBS the predictor runs.
//! - [`edge_skin`]: how the translation solver predicts mesh edges from bone rotations.
//! - [`kernel`]: the kernels of the regression (Gaussian, inhomogeneous polynomial) and the
//!   kernel vector `xi(c)` (FKY08 §4.2).
//! - [`predict`]: bone rotations from control points (global and pose-local models).
//! - [`translations`]: the Poisson translation solver (FKY08 §5, eq. 11), factored once.
//! - `lower_factor`: the translation solve's Cholesky factor as its per-frame substitutions
//!   read it (three coordinates at once, 4-lane rows).
//! - [`confidence`]: how far a frame's control vector lies from the training examples, in the
//!   kernel's metric (issue 20).
//! - [`refine`]: bone-level local-global refinement after the regression: the control points
//!   as constraints, the regression as a prior (issue 20).
//! - [`detail`]: the detail layer's synthesis (HZY11 eq. 4): `S · base`, normals, `+ h n`.
//! - [`displacement`]: the detail regressor `h(c) = D xi(c) + b` (HZY11 §5.2).
//! - `simd`: the hand-written AVX2 + FMA kernels (regression operators, the translation
//!   solve's right-hand side and substitutions, the detail layer's `S · base`), chosen at run
//!   time, each beside a portable loop.
//! - [`filter`]: the One Euro filter (Casiez et al. 2012), the input smoothing of a room's
//!   control points.

pub mod confidence;
pub mod detail;
pub mod displacement;
pub mod edge_skin;
pub mod filter;
pub mod kernel;
mod lower_factor;
pub mod predict;
pub mod refine;
mod simd;
pub mod skin;
pub mod translations;

/// Whether to split `n` vertices over the rayon pool in tasks of `chunk`: more than one chunk,
/// and a pool of more than one thread. A one-thread pool would only hand the whole job from the
/// calling thread to its single worker and back: a cross-thread wake-up that measured ~15 µs per
/// call on the horse (120 vs 105 µs for `skin_lbs`, 92 vs 77 µs for `skin_lbs_packed`, with
/// `RAYON_NUM_THREADS=1`), for no parallelism.
#[cfg(feature = "parallel")]
pub(crate) fn use_pool(n: usize, chunk: usize) -> bool {
    n > chunk && rayon::current_num_threads() > 1
}

/// Fills `out` by `fill(first_row, rows)` over consecutive runs of rows: in tasks of `chunk`
/// rows on the rayon pool when [`use_pool`] says so, else in one call on this thread.
pub(crate) fn fill_rows<T: Send>(
    out: &mut [T],
    chunk: usize,
    fill: impl Fn(usize, &mut [T]) + Sync,
) {
    #[cfg(feature = "parallel")]
    if use_pool(out.len(), chunk) {
        use rayon::prelude::*;
        out.par_chunks_mut(chunk)
            .enumerate()
            .for_each(|(c, rows)| fill(c * chunk, rows));
        return;
    }
    let _ = chunk;
    fill(0, out);
}

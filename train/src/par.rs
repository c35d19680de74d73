//! The two loop shapes training parallelises, with rayon under the `parallel` feature and plain
//! iterators otherwise, so one code path serves tests, benchmarks and production.

/// `(0..n).map(f)` collected in order; `init` makes one scratch value per worker.
pub(crate) fn map_range<S, R: Send>(
    n: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize) -> R + Sync + Send,
) -> Vec<R> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        (0..n).into_par_iter().map_init(init, f).collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut s = init();
        (0..n).map(|i| f(&mut s, i)).collect()
    }
}

/// Calls `f(scratch, chunk_index, chunk)` on consecutive `chunk`-sized pieces of `items` and
/// collects the results in order.
pub(crate) fn map_chunks_mut<T: Send, S, R: Send>(
    items: &mut [T],
    chunk: usize,
    init: impl Fn() -> S + Sync + Send,
    f: impl Fn(&mut S, usize, &mut [T]) -> R + Sync + Send,
) -> Vec<R> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items
            .par_chunks_mut(chunk)
            .enumerate()
            .map_init(init, |s, (i, c)| f(s, i, c))
            .collect()
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut s = init();
        items
            .chunks_mut(chunk)
            .enumerate()
            .map(|(i, c)| f(&mut s, i, c))
            .collect()
    }
}

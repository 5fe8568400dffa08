//! Data parallelism that never changes a result.
//!
//! Every parallel loop here writes disjoint outputs, and every sum over many terms is made in a
//! fixed order (per cell in cell order, per row then rows in row order), so the bits do not
//! depend on how many threads run. Without the `parallel` feature (the wasm build) the same loops
//! run sequentially.
//!
//! What is worth a parallel loop: starting one wakes the other workers, which costs tens of
//! microseconds (docs/performance.md has the measurement). Passes over the lattice that take
//! that long run on one thread, or inside a parallel loop that runs anyway: the multigrid setup
//! runs beside the per-cell force stage, each velocity component's loading inside its own CG.
//! The per-cell stages, the gathers onto the lattice, the two components of the friction solve
//! and the pass that turns its solution into the pull, each 0.1 ms or more, run across threads.

/// Runs `f(i, item)` for every item, in parallel where threads are available.
pub fn for_each_mut<T: Send>(items: &mut [T], f: impl Fn(usize, &mut T) + Sync + Send) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        items.par_iter_mut().enumerate().for_each(|(i, t)| f(i, t));
    }
    #[cfg(not(feature = "parallel"))]
    for (i, t) in items.iter_mut().enumerate() {
        f(i, t);
    }
}

/// Runs `f(k, chunk)` over consecutive chunks of `chunk` elements (the last may be shorter).
pub fn for_each_chunk_mut<T: Send>(data: &mut [T], chunk: usize, f: impl Fn(usize, &mut [T]) + Sync + Send) {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        data.par_chunks_mut(chunk).enumerate().for_each(|(k, c)| f(k, c));
    }
    #[cfg(not(feature = "parallel"))]
    for (k, c) in data.chunks_mut(chunk).enumerate() {
        f(k, c);
    }
}

/// Runs `f(k, a_chunk, b_chunk)` over the k-th chunks of `chunk` elements of `a` and of `b` (two
/// arrays of one lattice, split alike).
pub fn for_each_chunk_pair_mut<A: Send, B: Send>(
    a: &mut [A],
    b: &mut [B],
    chunk: usize,
    f: impl Fn(usize, &mut [A], &mut [B]) + Sync + Send,
) {
    debug_assert_eq!(a.len(), b.len());
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        a.par_chunks_mut(chunk).zip(b.par_chunks_mut(chunk)).enumerate().for_each(|(k, (a, b))| f(k, a, b));
    }
    #[cfg(not(feature = "parallel"))]
    for (k, (a, b)) in a.chunks_mut(chunk).zip(b.chunks_mut(chunk)).enumerate() {
        f(k, a, b);
    }
}

/// Threads available to the loops above.
pub fn threads() -> usize {
    #[cfg(feature = "parallel")]
    {
        rayon::current_num_threads()
    }
    #[cfg(not(feature = "parallel"))]
    {
        1
    }
}

/// Rows per band when a lattice of `l` rows is split for the threads. Any value gives the same
/// bits; this one balances load.
pub fn band_rows(l: usize) -> usize {
    let bands = (threads() * 4).max(1);
    l.div_ceil(bands).max(1)
}

/// Runs `a` and `b`, side by side where threads are available, and returns both results.
pub fn join<A: Send, B: Send>(a: impl FnOnce() -> A + Send, b: impl FnOnce() -> B + Send) -> (A, B) {
    #[cfg(feature = "parallel")]
    {
        rayon::join(a, b)
    }
    #[cfg(not(feature = "parallel"))]
    {
        (a(), b())
    }
}

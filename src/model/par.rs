//! Data parallelism that never changes a result.
//!
//! Every parallel loop here writes disjoint outputs, and every sum over many terms is made in a
//! fixed order (per cell in cell order, per row then rows in row order), so the bits do not
//! depend on how many threads run. Without the `parallel` feature (the wasm build) the same loops
//! run sequentially.
//!
//! What is worth a parallel loop: starting one wakes the other workers, which costs tens of
//! microseconds (docs/performance.md has the measurement), unless they are kept awake for a whole
//! step by [`with_workers_spinning`], as `Monolayer::step` and `advance` do. Passes that take
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

/// Runs `f` on one of the pool's threads while the others wait for its parallel loops by
/// spinning instead of sleeping, and returns its result.
///
/// A step opens about sixteen parallel loops. Between two of them a rayon worker that found no
/// work spins briefly, then sleeps, and waking it costs 30–40 µs on these machines: with two
/// threads about four times per step, and a loop of 0.1 ms done mostly by the one thread that was
/// awake (docs/performance.md, "Fifteenth session"). Here the idle workers keep looking for the
/// loops' work for as long as `f` runs, so one wake-up serves the whole of `f`. They occupy their
/// cores meanwhile, which is what the threads were asked for. The results are the same: which
/// thread runs a piece of a loop never changes a bit (the module's rule).
pub fn with_workers_spinning<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    #[cfg(feature = "parallel")]
    {
        use std::sync::atomic::{AtomicBool, Ordering};
        use std::sync::Mutex;
        // One spinning call at a time, in the whole process: two at once on one pool could each
        // take a thread and spin there, each above a frame of the other's work that it waits
        // for (a join's wait runs a pending broadcast). Any other caller meanwhile runs `f`
        // plainly, and so does a pool of one thread, or of more threads than cores, where a
        // spinner would take the core that the thread running `f` is waiting for.
        static IN_FLIGHT: AtomicBool = AtomicBool::new(false);
        static CORES: std::sync::OnceLock<usize> = std::sync::OnceLock::new();
        let cores = *CORES.get_or_init(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        let threads = rayon::current_num_threads();
        if threads < 2
            || threads > cores
            || IN_FLIGHT.compare_exchange(false, true, Ordering::Acquire, Ordering::Relaxed).is_err()
        {
            return f();
        }
        struct Release;
        impl Drop for Release {
            fn drop(&mut self) {
                IN_FLIGHT.store(false, Ordering::Release);
            }
        }
        let _release = Release;
        let work = Mutex::new(Some(f));
        let result = Mutex::new(None);
        let done = AtomicBool::new(false);
        // Every thread of the pool runs this once, at the top of its stack: the first to arrive
        // runs `f`, the others steal the pieces of its loops until it is done. (A spinner spawned
        // as an ordinary job could be popped by the thread running `f` while it waits inside a
        // join, and would then spin forever above the frame that is to end it.)
        rayon::broadcast(|_| {
            let mine = work.lock().expect("no thread panicked holding the work").take();
            if let Some(f) = mine {
                // Set when `f` returns or unwinds, so that a panic in it ends the spinning too.
                struct Done<'a>(&'a AtomicBool);
                impl Drop for Done<'_> {
                    fn drop(&mut self) {
                        self.0.store(true, Ordering::Release);
                    }
                }
                let _done = Done(&done);
                let r = f();
                *result.lock().expect("no thread panicked holding the result") = Some(r);
            } else {
                while !done.load(Ordering::Acquire) {
                    if let Some(rayon::Yield::Idle) = rayon::yield_now() {
                        std::hint::spin_loop();
                    }
                }
            }
        });
        result.into_inner().expect("no thread panicked holding the result").expect("the work ran")
    }
    #[cfg(not(feature = "parallel"))]
    {
        f()
    }
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

#[cfg(all(test, feature = "parallel"))]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Duration;

    fn pool(threads: usize) -> rayon::ThreadPool {
        rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap()
    }

    /// A few parallel loops with serial work between them, as a step has; returns a checksum.
    fn loops(seed: u64) -> u64 {
        let mut data: Vec<u64> = (0..4096).map(|i| i * 2654435761 + seed).collect();
        for round in 0..8u64 {
            for_each_chunk_mut(&mut data, 64, |k, c| {
                c.iter_mut().for_each(|x| *x = x.rotate_left(5) ^ (k as u64 + round))
            });
            let (a, b) = join(|| data[..2048].iter().fold(0u64, |s, x| s.wrapping_add(*x)), || data[2048..].len());
            data[0] = data[0].wrapping_add(a + b as u64);
        }
        data.iter().fold(0, |s, x| s.wrapping_mul(31).wrapping_add(*x))
    }

    /// Runs `f` on a thread of its own and fails if it does not end within a minute: a guard
    /// against a hang, which would otherwise stall the test run instead of failing it.
    fn within_a_minute<R: Send + 'static>(f: impl FnOnce() -> R + Send + 'static) -> R {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || tx.send(f()).unwrap());
        rx.recv_timeout(Duration::from_secs(60)).expect("hung: the spinning workers never let go")
    }

    #[test]
    fn spinning_workers_give_the_plain_result() {
        let plain = pool(1).install(|| loops(7));
        let spun = within_a_minute(|| pool(2).install(|| with_workers_spinning(|| loops(7))));
        assert_eq!(spun, plain);
        // Outside any pool (the global one), and nested in itself (the inner call runs plainly).
        assert_eq!(within_a_minute(|| with_workers_spinning(|| with_workers_spinning(|| loops(7)))), plain);
    }

    #[test]
    fn callers_at_once_on_one_pool_all_finish() {
        // Several callers on one two-thread pool, each stepping loops that join: only one may
        // spin at a time, or two spinners could each wait above the other's work.
        let sums = within_a_minute(|| {
            let p = std::sync::Arc::new(pool(2));
            let callers: Vec<_> = (0..4u64)
                .map(|c| {
                    let p = p.clone();
                    std::thread::spawn(move || {
                        (0..200).fold(None, |_, i| Some(p.install(|| with_workers_spinning(|| loops(c + i)))))
                    })
                })
                .collect();
            callers.into_iter().map(|h| h.join().unwrap()).collect::<Vec<_>>()
        });
        let expected: Vec<_> = (0..4u64).map(|c| Some(loops(c + 199))).collect();
        assert_eq!(sums, expected);
    }

    #[test]
    fn a_panic_in_the_work_ends_the_spinning() {
        let r = within_a_minute(|| {
            std::panic::catch_unwind(|| pool(2).install(|| with_workers_spinning(|| -> u64 { panic!("in the work") })))
                .is_err()
        });
        assert!(r, "the panic reaches the caller");
        // And the next call spins again (the in-flight mark was released).
        assert_eq!(
            within_a_minute(|| pool(2).install(|| with_workers_spinning(|| loops(3)))),
            pool(1).install(|| loops(3))
        );
    }
}

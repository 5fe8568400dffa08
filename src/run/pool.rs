//! Simulations one per core: `workers` threads each take the next job and run it on a rayon
//! pool of one thread, so that every simulation gives the bits it gives alone (the parallel
//! loops of the core then run serially), until the jobs run out or a signal asks to stop.

use std::sync::atomic::{AtomicUsize, Ordering};

use crate::run::error::RunError;
use crate::run::runner::stop_signal;

/// Runs `work(index, job)` for every job, `workers` at a time, each on a one-thread rayon pool.
/// After SIGTERM or SIGINT no job starts (those under way stop after their step). Returns each
/// job's result, in the jobs' order (None: not started).
pub fn each_on_one_core<J: Sync, T: Send>(
    jobs: &[J],
    workers: usize,
    work: impl Fn(usize, &J) -> Result<T, RunError> + Sync,
) -> Vec<Option<Result<T, RunError>>> {
    let next = AtomicUsize::new(0);
    let results: Vec<std::sync::Mutex<Option<Result<T, RunError>>>> =
        jobs.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..workers.max(1).min(jobs.len().max(1)) {
            scope.spawn(|| {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a one-thread pool");
                while stop_signal().is_none() {
                    let i = next.fetch_add(1, Ordering::SeqCst);
                    let Some(job) = jobs.get(i) else { break };
                    let r = pool.install(|| work(i, job));
                    *results[i].lock().expect("no panics hold it") = Some(r);
                }
            });
        }
    });
    results.into_iter().map(|m| m.into_inner().expect("no panics hold it")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_job_runs_once_on_a_one_thread_pool_in_order_of_its_results() {
        let jobs: Vec<u64> = (0..20).collect();
        let out = each_on_one_core(&jobs, 3, |i, &j| {
            assert_eq!(rayon::current_num_threads(), 1);
            if j == 7 {
                return Err(RunError::Options("seven".into()));
            }
            Ok(i as u64 * 10 + j)
        });
        assert_eq!(out.len(), 20);
        for (i, r) in out.into_iter().enumerate() {
            match r.expect("every job ran") {
                Ok(v) => assert_eq!(v, i as u64 * 11),
                Err(e) => assert_eq!((i, e.to_string()), (7, "seven".to_string())),
            }
        }
    }
}

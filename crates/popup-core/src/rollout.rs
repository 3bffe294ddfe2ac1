//! Batched rollouts: many (params, run) pairs at once, in parallel.
//!
//! Job `b` writes only result `b`, and each job is a plain sequential run, so the output
//! is bit-identical to running the jobs one by one, for any thread count.

use crate::error::Result;
use crate::model::Model;
use crate::params::{ParamData, Params};
use crate::sim::{run, run_until, RunConfig, Trajectory};
use std::sync::atomic::AtomicBool;

/// One job of a batch.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// Parameters of this rollout.
    pub params: Params,
    /// What to run.
    pub run: RunConfig,
}

/// Run one job.
///
/// # Errors
/// As [`ParamData::new`] and [`run`].
pub fn run_job(model: &Model, job: &Job) -> Result<Trajectory> {
    let pd = ParamData::new(model, &job.params)?;
    run(model, &pd, &job.run)
}

/// Run a batch on `threads` threads (0 = all cores; 1 = sequential on this thread).
/// Results are in job order.
pub fn rollout(model: &Model, jobs: &[Job], threads: usize) -> Vec<Result<Trajectory>> {
    rollout_until(model, jobs, threads, &AtomicBool::new(false))
}

/// [`rollout`] that stops once `stop` is raised (e.g. by a Ctrl-C watcher): running jobs
/// end with the samples they have, jobs not started yet end with no samples.
pub fn rollout_until(model: &Model, jobs: &[Job], threads: usize, stop: &AtomicBool) -> Vec<Result<Trajectory>> {
    par_map(jobs, threads, |j| {
        let pd = ParamData::new(model, &j.params)?;
        run_until(model, &pd, &j.run, stop)
    })
}

/// `f` over `items` on `threads` threads (0 = all cores; 1 = sequential on this thread),
/// results in item order. Each call writes only its own result, so the output does not
/// depend on the thread count.
pub(crate) fn par_map<T: Sync, R: Send>(items: &[T], threads: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        if threads != 1 && items.len() > 1 {
            let go = || items.par_iter().map(&f).collect::<Vec<_>>();
            return match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
                Ok(pool) => pool.install(go),
                Err(_) => go(),
            };
        }
    }
    let _ = threads;
    items.iter().map(f).collect()
}

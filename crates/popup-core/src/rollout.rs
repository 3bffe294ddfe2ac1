//! Batched rollouts: many (params, run) pairs at once, in parallel.
//!
//! Job `b` writes only result `b`, and each job is a plain sequential run, so the output
//! is bit-identical to running the jobs one by one, for any thread count.

use crate::error::Result;
use crate::model::Model;
use crate::params::{ParamData, Params};
use crate::effects::same_motion;
use crate::sim::{resample, run, run_recorded, run_until, Motion, RunConfig, Trajectory};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

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
///
/// A job of an encoder replay whose parameters differ from an earlier
/// job's only in what acts on the sensor rows alone ([`crate::effects::same_motion`], e.g.
/// a friction fit's Jacobian) is not run again: its rows are computed from the earlier
/// run's motion (its bare rows, [`Motion`]) with this job's own sensor effects
/// ([`resample`]), the same bits.
pub fn rollout_until(model: &Model, jobs: &[Job], threads: usize, stop: &AtomicBool) -> Vec<Result<Trajectory>> {
    rollout_cached(model, jobs, threads, stop, None)
}

/// A run's motion kept for the jobs that share it.
type Kept = Arc<Motion>;

/// The motions of recent batches whose jobs shared one ([`rollout_cached`]): a later batch
/// with that motion (a friction fit's next step) is computed from its bare rows, not run.
/// Holds at most [`MotionCache::CAPACITY`] motions, the least recently used dropped first.
#[derive(Debug, Default)]
pub struct MotionCache {
    entries: Mutex<Vec<(Job, Kept)>>,
    hits: AtomicUsize,
}

impl MotionCache {
    /// Motions kept.
    pub const CAPACITY: usize = 4;

    /// Jobs computed from a kept motion so far (runs of physics saved).
    pub fn hits(&self) -> usize {
        self.hits.load(Ordering::Relaxed)
    }

    /// A motion that `job` shares, moved to the front.
    fn find(&self, job: &Job) -> Option<Kept> {
        let mut e = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        let i = e.iter().position(|(j, _)| shares(j, job))?;
        let hit = e.remove(i);
        let m = hit.1.clone();
        self.hits.fetch_add(1, Ordering::Relaxed);
        e.insert(0, hit);
        Some(m)
    }

    fn insert(&self, job: &Job, m: Kept) {
        let mut e = self.entries.lock().unwrap_or_else(|p| p.into_inner());
        e.insert(0, (job.clone(), m));
        e.truncate(Self::CAPACITY);
    }
}

/// [`rollout_until`] that also takes motions from, and gives them to, `cache`: the motion
/// of a batch whose jobs share one is kept, and a job sharing a kept motion is computed
/// from its states. The results are the same bits with or without a cache.
pub fn rollout_cached(model: &Model, jobs: &[Job], threads: usize, stop: &AtomicBool, cache: Option<&MotionCache>) -> Vec<Result<Trajectory>> {
    let base = shared_motion(jobs);
    let kept: Vec<Option<Kept>> = (0..jobs.len()).map(|j| if base[j].is_none() && eligible(&jobs[j]) { cache.and_then(|c| c.find(&jobs[j])) } else { None }).collect();
    let roots: Vec<(usize, bool)> =
        (0..jobs.len()).filter(|&j| base[j].is_none() && kept[j].is_none()).map(|r| (r, base.contains(&Some(r)))).collect();
    let ran = par_map(&roots, threads, |&(r, keep)| {
        let pd = ParamData::new(model, &jobs[r].params)?;
        if keep {
            run_recorded(model, &pd, &jobs[r].run, stop)
        } else {
            run_until(model, &pd, &jobs[r].run, stop).map(|t| (t, None))
        }
    });
    let mut out: Vec<Option<Result<Trajectory>>> = (0..jobs.len()).map(|_| None).collect();
    let mut motions = kept;
    for (&(r, _), res) in roots.iter().zip(ran) {
        out[r] = Some(match res {
            Ok((t, Some(s))) => {
                let m: Kept = Arc::new(s);
                // a run cut short by `stop` is not a motion to share later
                if let Some(c) = cache.filter(|_| !stop.load(Ordering::Relaxed)) {
                    c.insert(&jobs[r], m.clone());
                }
                motions[r] = Some(m);
                Ok(t)
            }
            Ok((t, None)) => Ok(t),
            Err(e) => Err(e),
        });
    }
    let rest: Vec<usize> = (0..jobs.len()).filter(|&j| out[j].is_none()).collect();
    let again = par_map(&rest, threads, |&j| {
        let pd = ParamData::new(model, &jobs[j].params)?;
        match motions[base[j].unwrap_or(j)].as_ref() {
            Some(m) => resample(model, &pd, &jobs[j].run, m),
            // the shared run failed: this one runs on its own (and fails with its own error)
            None => run_until(model, &pd, &jobs[j].run, stop),
        }
    });
    for (&j, res) in rest.iter().zip(again) {
        out[j] = Some(res);
    }
    out.into_iter().map(|r| r.expect("every job has a result")).collect()
}

/// An encoder replay: the motor side is prescribed, so the motion does not depend on
/// [`crate::effects::OUTPUT_ONLY_IN_REPLAY`] (a gear's link side, free in its gap, is
/// behind the motor side and its friction).
fn eligible(job: &Job) -> bool {
    job.run.drive.is_replay()
}

/// Whether `b` has the motion of `a`: both [`eligible`], the same run config and the same
/// parameters but for [`crate::effects::OUTPUT_ONLY_IN_REPLAY`].
fn shares(a: &Job, b: &Job) -> bool {
    let (p, q) = (&a.params, &b.params);
    eligible(a) && eligible(b) && p.payload_kg == q.payload_kg && p.pressure_pa == q.pressure_pa && same_motion(&p.effects, &q.effects) && a.run == b.run
}

/// For each job, the earlier job whose motion it shares (`None`: it runs its own): both
/// encoder replays of the same run config, their parameters equal
/// but for [`crate::effects::OUTPUT_ONLY_IN_REPLAY`].
pub fn shared_motion(jobs: &[Job]) -> Vec<Option<usize>> {
    let mut base = vec![None; jobs.len()];
    let mut roots: Vec<usize> = Vec::new();
    for (j, job) in jobs.iter().enumerate() {
        if !eligible(job) {
            continue;
        }
        match roots.iter().find(|&&i| shares(&jobs[i], job)) {
            Some(&i) => base[j] = Some(i),
            None => roots.push(j),
        }
    }
    base
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

//! Bit-for-bit determinism: the same run twice, and a batch of 16 jobs (varied payload,
//! pressures, torque and replay drives) through `rollout` on 1, 2 and 4 threads and one by
//! one through `run_job` — every f64 compared with `to_bits`.

mod common;

use common::{traj_bits, Rng};
use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::model::{Integrator, Model, Options};
use popup_core::params::Params;
use popup_core::rollout::{rollout, run_job, Job};
use popup_core::sim::RunConfig;
use popup_core::spec::ArmSpec;

fn jobs() -> Vec<Job> {
    let mut rng = Rng(2024);
    (0..16)
        .map(|n| {
            let params = Params { payload_kg: rng.uniform(0.0, 4.0), pressure_pa: [rng.uniform(8e3, 95e3), rng.uniform(8e3, 95e3)], effects: Default::default() };
            let drive = if n % 3 == 2 {
                let t: Vec<f64> = (0..=40).map(|k| k as f64 * 0.0125).collect();
                let (a, w) = (rng.uniform(0.1, 0.5), rng.uniform(2.0, 8.0));
                let y: Vec<[f64; 3]> = t.iter().map(|&t| [a * (w * t).sin(), 0.3 + a * (w * t).cos(), -0.2 * t]).collect();
                Drive::Replay(Spline3::new(&t, &y).unwrap())
            } else {
                let t = [0.0, 0.1, 0.2, 0.5];
                let y: Vec<[f64; 3]> = (0..4).map(|_| [rng.uniform(-3.0, 3.0), rng.uniform(-10.0, 30.0), rng.uniform(-8.0, 8.0)]).collect();
                Drive::Torque(Linear3::new(&t, &y).unwrap())
            };
            let duration = if n % 3 == 2 { None } else { Some(0.5) };
            Job { params, run: RunConfig { drive, initial: None, duration, sample_period: 5e-3, check_step: true } }
        })
        .collect()
}

#[test]
fn same_run_twice_is_bit_identical() {
    for integ in [Integrator::Rk4, Integrator::SemiImplicit] {
        let dt = if integ == Integrator::Rk4 { 1e-3 } else { 2.5e-4 };
        let model = Model::compile(&ArmSpec::popup_lab(), Options { dt, integrator: integ, ..Options::default() }).unwrap();
        for job in jobs().iter().take(6) {
            let a = run_job(&model, job).unwrap();
            let b = run_job(&model, job).unwrap();
            assert!(a.nsample > 50);
            assert_eq!(traj_bits(&a), traj_bits(&b), "{integ:?}: two identical runs differ");
        }
    }
}

#[test]
fn rollout_is_bit_identical_for_any_thread_count() {
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let jobs = jobs();
    let one_by_one: Vec<Vec<u64>> = jobs.iter().map(|j| traj_bits(&run_job(&model, j).unwrap())).collect();
    // the jobs really differ from each other
    for i in 1..one_by_one.len() {
        assert_ne!(one_by_one[i], one_by_one[i - 1], "jobs {} and {i} gave the same output", i - 1);
    }
    for threads in [1, 2, 4] {
        let out = rollout(&model, &jobs, threads);
        assert_eq!(out.len(), jobs.len());
        for (k, r) in out.iter().enumerate() {
            let tr = r.as_ref().unwrap_or_else(|e| panic!("job {k} failed: {e}"));
            assert_eq!(traj_bits(tr), one_by_one[k], "job {k} differs with {threads} threads");
        }
    }
    println!("16 jobs ({} f64 each): rollout with 1, 2, 4 threads == run_job one by one, bit for bit", one_by_one[0].len());
}

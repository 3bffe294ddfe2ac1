//! A batch whose replay jobs differ only in effects that act on the sensor rows alone
//! (`joint_friction`, `actuator_saturation`) runs the physics once and recomputes the rows
//! of the others at its sample states (`rollout::shared_motion`, `sim::resample`): every
//! f64 the same as running each job on its own, over random families of parameters, both
//! integrators, sensor delays, a held gear, a gear with play (rigid and compliant flanks),
//! and the cases that must not share.

mod common;

use common::{traj_bits, Rng};
use popup_core::drive::{Drive, Spline3};
use popup_core::model::{Integrator, Model, Options, Structure};
use popup_core::params::Params;
use popup_core::rollout::{rollout, rollout_cached, run_job, shared_motion, Job, MotionCache};
use std::sync::atomic::AtomicBool;
use popup_core::sim::RunConfig;
use popup_core::spec::ArmSpec;

fn replay(rng: &mut Rng) -> RunConfig {
    let t: Vec<f64> = (0..=60).map(|k| k as f64 * 0.01).collect();
    let (a, w) = (rng.uniform(0.2, 0.6), rng.uniform(3.0, 9.0));
    let y: Vec<[f64; 3]> = t.iter().map(|&t| [a * (w * t).sin(), 0.3 + a * (w * t).cos() - a, -0.4 * (w * t).sin()]).collect();
    RunConfig { drive: Drive::Replay(Spline3::new(&t, &y).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true }
}

/// Jobs that share a run config and all parameters but friction and saturation (random).
fn family(model: &Model, rng: &mut Rng, n: usize, base: Params) -> Vec<Job> {
    let run = replay(rng);
    (0..n)
        .map(|k| {
            let mut p = base;
            let f = &mut p.effects.joint_friction;
            for j in 0..3 {
                f.tau_c[j] = rng.uniform(0.0, 3.0);
                f.b[j] = rng.uniform(0.0, 0.5);
                if k % 2 == 1 {
                    f.tau_s[j] = rng.uniform(0.0, 1.5);
                    f.v_s[j] = rng.uniform(0.01, 0.2);
                    f.v_eps[j] = rng.uniform(1e-3, 0.05);
                }
            }
            if k % 3 == 2 {
                p.effects.actuator_saturation.tau_max = [rng.uniform(2.0, 20.0), rng.uniform(5.0, 30.0), f64::INFINITY];
            }
            if k % 4 == 3 {
                // the delays of the groups read from the physics (not the encoder's)
                let d = &mut p.effects.sensor_delay;
                d.imu = rng.uniform(0.0, 0.02);
                d.torque = rng.uniform(0.0, 0.01);
                d.mocap = rng.uniform(0.0, 0.03);
            }
            let _ = model;
            Job { params: p, run: run.clone() }
        })
        .collect()
}

fn check_same_traj_bits(model: &Model, jobs: &[Job], expect_shared: bool) {
    let plan = shared_motion(jobs);
    if expect_shared {
        assert!(plan[0].is_none() && plan[1..].iter().all(|b| *b == Some(0)), "plan {plan:?}");
    } else {
        assert!(plan.iter().all(|b| b.is_none()), "plan {plan:?}");
    }
    let alone: Vec<Vec<u64>> = jobs.iter().map(|j| traj_bits(&run_job(model, j).unwrap())).collect();
    for i in 1..alone.len() {
        assert_ne!(alone[i], alone[0], "job {i} gives the rows of job 0: the family varies nothing");
    }
    for threads in [1, 2] {
        for (k, r) in rollout(model, jobs, threads).iter().enumerate() {
            let tr = r.as_ref().unwrap_or_else(|e| panic!("job {k} failed: {e}"));
            assert_eq!(traj_bits(tr), alone[k], "job {k} ({threads} threads) differs from its own run");
        }
    }
}

#[test]
fn friction_and_saturation_jobs_share_one_run_and_give_the_same_traj_bits() {
    let mut rng = Rng(77);
    for integ in [Integrator::Rk4, Integrator::SemiImplicit] {
        let dt = if integ == Integrator::Rk4 { 1e-3 } else { 2.5e-4 };
        let model = Model::compile(&ArmSpec::popup_lab(), Options { dt, integrator: integ, ..Options::default() }).unwrap();
        for case in 0..4 {
            let mut base = Params::defaults(&model);
            base.payload_kg = rng.uniform(0.0, 2.0);
            if case >= 1 {
                // sensor delays: the rows go through the delay line, the encoder one moves the drive
                let d = &mut base.effects.sensor_delay;
                d.imu = rng.uniform(0.0, 0.02);
                d.torque = rng.uniform(0.0, 0.01);
                d.mocap = rng.uniform(0.0, 0.03);
                d.encoder = if case == 3 { rng.uniform(0.0, 0.01) } else { 0.0 };
            }
            if case == 2 {
                // a held gear is prescribed like a rigid one (the play operator of the encoder)
                base.effects.backlash.gap = [0.01, 0.02, 0.0];
                base.effects.backlash.held = [1.0, 1.0, 0.0];
            }
            let jobs = family(&model, &mut rng, 7, base);
            check_same_traj_bits(&model, &jobs, true);
        }
    }
}

#[test]
fn a_gear_with_play_shares_too_its_link_side_is_behind_the_motor_side() {
    // gaps wide enough for the link sides to cross them, rigid and compliant flanks: the
    // motor side is prescribed and the friction acts there, so the motion is the same
    let mut rng = Rng(82);
    for (integ, dt) in [(Integrator::Rk4, 1e-3), (Integrator::SemiImplicit, 2.5e-4)] {
        let model = Model::compile(&ArmSpec::popup_lab(), Options { dt, integrator: integ, ..Options::default() }).unwrap();
        for compliant in [false, true] {
            let mut b = Params::defaults(&model);
            b.effects.backlash.gap = [0.01, 0.02, 0.015];
            b.effects.backlash.inertia = [0.05, 0.05, 0.05];
            if compliant {
                b.effects.backlash.contact_k = [2e4, 2e4, 2e4];
                b.effects.backlash.contact_c = [5.0, 5.0, 5.0];
            }
            let jobs = family(&model, &mut rng, 6, b);
            check_same_traj_bits(&model, &jobs, true);
        }
    }
}

#[test]
fn other_structures_share_too_multi_segment_torsion_and_beam_links() {
    let mut rng = Rng(80);
    for structure in [
        Structure { segments: [2, 3], torsion: [true, false], elements: [0, 0] },
        // a beam link: the articulated-body solver with the motor rows prescribed
        Structure { segments: [1, 1], torsion: [false, false], elements: [2, 0] },
    ] {
        let model = Model::compile(&ArmSpec::popup_lab(), Options { dt: 2.5e-4, structure, ..Options::default() }).unwrap();
        let mut base = Params::defaults(&model);
        if structure.torsion[0] {
            base.effects.torsion.k_t = [300.0, f64::INFINITY];
            base.effects.torsion.c_t = [0.2, 0.0];
        }
        let jobs = family(&model, &mut rng, 4, base);
        check_same_traj_bits(&model, &jobs, true);
    }
}

#[test]
fn jobs_that_move_differently_run_on_their_own() {
    let mut rng = Rng(78);
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let base = Params::defaults(&model);
    // another payload, pressure or leak changes the motion
    for change in 0..4 {
        let mut jobs = family(&model, &mut rng, 2, base);
        match change {
            0 => jobs[1].params.payload_kg += 0.3,
            1 => jobs[1].params.pressure_pa[0] *= 0.8,
            3 => jobs[1].params.effects.sensor_delay.encoder = 0.004,
            _ => jobs[1].params.effects.pressure_leak.rate = [0.01, 0.0],
        }
        check_same_traj_bits(&model, &jobs, false);
    }
    // another encoder record: no sharing
    let mut jobs = family(&model, &mut rng, 2, base);
    jobs[1].run = replay(&mut rng);
    check_same_traj_bits(&model, &jobs, false);
}

#[test]
fn a_shared_run_that_fails_fails_every_job_with_its_own_error() {
    let mut rng = Rng(79);
    // a step far beyond the stability limit: the step check refuses every job alike
    let model = Model::compile(&ArmSpec::popup_lab(), Options { dt: 0.1, ..Options::default() }).unwrap();
    let mut jobs = family(&model, &mut rng, 3, Params::defaults(&model));
    for j in &mut jobs {
        j.run.sample_period = 0.1;
    }
    assert_eq!(shared_motion(&jobs), vec![None, Some(0), Some(0)]);
    let alone: Vec<String> = jobs.iter().map(|j| run_job(&model, j).unwrap_err().to_string()).collect();
    let batch: Vec<String> = rollout(&model, &jobs, 2).into_iter().map(|r| r.unwrap_err().to_string()).collect();
    assert_eq!(batch, alone);
}

#[test]
fn a_kept_motion_serves_later_batches_with_the_same_traj_bits() {
    let mut rng = Rng(81);
    let model = Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap();
    let cache = MotionCache::default();
    let stop = AtomicBool::new(false);
    let jobs = family(&model, &mut rng, 9, Params::defaults(&model));
    let alone: Vec<Vec<u64>> = jobs.iter().map(|j| traj_bits(&run_job(&model, j).unwrap())).collect();
    // a batch that shares one motion keeps it; later single jobs (a fit's next steps) and
    // batches come from it, the same bits as their own runs
    let first = rollout_cached(&model, &jobs[..3], 2, &stop, Some(&cache));
    for (k, r) in first.iter().enumerate() {
        assert_eq!(traj_bits(r.as_ref().unwrap()), alone[k]);
    }
    for k in 3..9 {
        let r = rollout_cached(&model, &jobs[k..k + 1], 1, &stop, Some(&cache));
        assert_eq!(traj_bits(r[0].as_ref().unwrap()), alone[k], "job {k} from the kept motion");
    }
    assert_eq!(cache.hits(), 6);
    // other motions (each shared by a pair) push it out after CAPACITY of them; results stay right
    for n in 0..MotionCache::CAPACITY + 1 {
        let mut b = Params::defaults(&model);
        b.payload_kg = 0.1 * (n + 1) as f64;
        let other = family(&model, &mut rng, 2, b);
        let want: Vec<Vec<u64>> = other.iter().map(|j| traj_bits(&run_job(&model, j).unwrap())).collect();
        let got: Vec<Vec<u64>> = rollout_cached(&model, &other, 2, &stop, Some(&cache)).iter().map(|r| traj_bits(r.as_ref().unwrap())).collect();
        assert_eq!(got, want);
    }
    assert_eq!(cache.hits(), 6, "other motions are not this one");
    let again = rollout_cached(&model, &jobs[..1], 1, &stop, Some(&cache));
    assert_eq!(traj_bits(again[0].as_ref().unwrap()), alone[0]);
    assert_eq!(cache.hits(), 6, "pushed out: run again");
}

#[test]
fn same_motion_ignores_exactly_the_parameters_of_the_output_only_table() {
    use popup_core::effects::{same_motion, Effects, OUTPUT_ONLY_IN_REPLAY, PARAMS};
    let base = Effects::default();
    let flat = base.to_flat();
    let mut off = 0;
    for p in PARAMS.iter() {
        let listed = OUTPUT_ONLY_IN_REPLAY.iter().any(|&(e, n, _)| e == p.effect && (n == "*" || n == p.name));
        for i in 0..p.len {
            let mut f = flat;
            // a value inside the bounds, away from the neutral one
            let (lo, hi) = (p.lo, if p.hi.is_finite() { p.hi } else { p.lo.max(1.0) * 10.0 });
            f[off + i] = if f[off + i] == hi { 0.5 * (lo + hi) } else { (0.5 * (f[off + i] + hi)).min(f[off + i] + 1.0) };
            if !flat[off + i].is_finite() {
                f[off + i] = hi;
            }
            if p.integer {
                f[off + i] = if flat[off + i] == hi { lo } else { hi };
            }
            let e = Effects::from_flat(&f).unwrap();
            assert_eq!(same_motion(&base, &e), listed, "{}.{}[{i}]", p.effect, p.name);
        }
        off += p.len;
    }
}

//! Issue 19: every loop over time has a bound derived from its inputs, checked before it
//! starts; a raised stop flag ends a run within the poll interval.

use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::error::Error;
use popup_core::model::{Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::rollout::{rollout_until, Job};
use popup_core::sim::{run, RunConfig};
use popup_core::spec::ArmSpec;
use std::sync::atomic::AtomicBool;

fn lab() -> Model {
    Model::compile(&ArmSpec::popup_lab(), Options::default()).unwrap()
}

fn pd(m: &Model) -> ParamData {
    ParamData::new(m, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects: Default::default() }).unwrap()
}

fn replay(last_t: f64) -> RunConfig {
    let t = [0.0, 0.5, last_t];
    RunConfig { drive: Drive::Replay(Spline3::new(&t, &[[0.0; 3]; 3]).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true }
}

#[test]
fn absurd_replay_span_is_refused_before_running() {
    let m = lab();
    for (last, steps) in [(1e300, "1e303 steps"), (1e9, "1e12 steps")] {
        let e = run(&m, &pd(&m), &replay(last)).unwrap_err();
        assert!(matches!(e, Error::Input { .. }), "{e:?}");
        let msg = e.to_string();
        assert!(msg.contains("replay span") && msg.contains(steps) && msg.contains("the limit is 1e9 steps"), "{msg}");
        assert!(msg.len() < 400, "no 300-digit numbers: {msg}");
    }
}

#[test]
fn absurd_durations_and_sample_periods_are_refused() {
    let m = lab();
    let torque = |d: f64, sp: f64| RunConfig {
        drive: Drive::Torque(Linear3::new(&[0.0], &[[0.0, 18.0, 4.0]]).unwrap()),
        initial: None,
        duration: Some(d),
        sample_period: sp,
        check_step: true,
    };
    let e = run(&m, &pd(&m), &torque(1e300, 1e-3)).unwrap_err().to_string();
    assert!(e.contains("duration 1e300 s") && e.contains("the limit is"), "{e}");
    let e = run(&m, &pd(&m), &torque(0.1, 1e300)).unwrap_err().to_string();
    assert!(e.contains("sample_period") && e.contains("1e300 s"), "{e}");
    let e = run(&m, &pd(&m), &torque(f64::NAN, 1e-3)).unwrap_err().to_string();
    assert!(e.contains("duration") && e.contains("NaN"), "{e}");
}

#[test]
fn a_raised_stop_flag_ends_the_runs_early() {
    let m = lab();
    let t = [0.0, 100.0];
    let job = Job {
        params: Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects: Default::default() },
        run: RunConfig { drive: Drive::Replay(Spline3::new(&t, &[[0.0; 3]; 2]).unwrap()), initial: None, duration: None, sample_period: 1.0, check_step: true },
    };
    // the flag is up from the start: each run stops at its first poll
    let out = rollout_until(&m, &[job.clone(), job], 2, &AtomicBool::new(true));
    for r in out {
        let tr = r.unwrap();
        assert!(tr.nsample <= 2, "stopped runs keep what they had: {}", tr.nsample);
        assert!(tr.final_state.t < 2.0, "{}", tr.final_state.t);
    }
}

#[test]
fn an_encoder_angle_no_motor_reaches_is_refused_naming_row_and_column() {
    // found by the replay fuzzing: 1e300 rad ended as a static-equilibrium failure
    let t = [0.0, 2.246687641658144e-211, 1.0];
    let e = Spline3::new(&t, &[[0.0; 3], [0.0, 0.0, 1e300], [0.0; 3]]).unwrap_err();
    assert!(matches!(e, Error::Input { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("row 1, column 2 (q3) is 1e300 rad") && msg.contains("4 turns"), "{msg}");
    // four turns are still an angle
    assert!(Spline3::new(&[0.0, 1.0], &[[0.0; 3], [25.0, -25.0, 0.0]]).is_ok());
}

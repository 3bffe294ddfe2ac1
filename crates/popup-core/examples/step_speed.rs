//! Steps per second of one 7-DOF rollout (torque-driven and replay), per integrator, and of
//! the largest chain (17 joints: 3 segments per link and torsion joints; RK4 at dt = 0.5 and
//! 0.25 ms).
//! Run: `cargo run --release -p popup-core --example step_speed`. The torque-driven arm
//! hangs below the shoulder (q2 = -1.2 rad), the only pose where constant torques are stable.

use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::model::{Integrator, Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::sim::{rest_state, run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::gravity_torque;
use std::time::Instant;

fn main() {
    let duration = 20.0;
    let largest = Structure { segments: [3, 3], torsion: [true, true], elements: [0, 0] };
    for (integ, structure) in [(Integrator::Rk4, Structure::default()), (Integrator::SemiImplicit, Structure::default()), (Integrator::Rk4, largest)] {
        // the 3-segment links have overdamped segment modes near −2900 1/s: RK4 needs dt < 0.92 ms
        let dts = if structure.is_nominal() { [1e-3, 5e-4] } else { [5e-4, 2.5e-4] };
        for dt in dts {
            let model = Model::compile(&ArmSpec::popup_lab(), Options { dt, integrator: integ, structure, ..Options::default() }).unwrap();
            let mut effects = popup_core::effects::Effects::default();
            effects.torsion.k_t = [500.0, 200.0];
            effects.torsion.c_t = [0.1, 0.01];
            let pd = ParamData::new(&model, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3], effects }).unwrap();
            let st = rest_state(&model, &pd, 0.0, [0.0, -1.2, 0.4]).unwrap();
            let g = gravity_torque(&model, &pd, &st.q);
            let hold = model.motor_idx.map(|i| g[i]);
            let n = (duration / 0.002) as usize;
            let t: Vec<f64> = (0..=n).map(|k| k as f64 * 0.002).collect();
            let tau: Vec<[f64; 3]> = t.iter().map(|&x| [hold[0], hold[1] + 2.0 * (6.0 * x).sin(), hold[2]]).collect();
            let q: Vec<[f64; 3]> = t.iter().map(|&x| [0.1 * (x).sin(), -1.2 + 0.2 * (2.0 * x).sin(), 0.4 + 0.1 * (3.0 * x).sin()]).collect();
            for (name, drive) in [("torque", Drive::Torque(Linear3::new(&t, &tau).unwrap())), ("replay", Drive::Replay(Spline3::new(&t, &q).unwrap()))] {
                for sp in [duration, 0.002] {
                    let cfg = RunConfig { drive: drive.clone(), initial: None, duration: Some(duration), sample_period: sp, check_step: true };
                    let t0 = Instant::now();
                    let tr = run(&model, &pd, &cfg).unwrap();
                    let el = t0.elapsed().as_secs_f64();
                    let steps = duration / dt;
                    println!(
                        "{:13} nv={:2} dt={dt:e} {name:6} samples={:6}: {:9.0} steps/s ({:.3} µs/step)",
                        integ.name(),
                        model.nv,
                        tr.nsample,
                        steps / el,
                        el / steps * 1e6
                    );
                }
            }
        }
    }
}

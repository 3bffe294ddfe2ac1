mod common;

use common::{col, constant_torque, orders};
use popup_core::math::VecN;
use popup_core::model::{Disable, Integrator, Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sim::{rest_state, run, RunConfig, State, Trajectory};
use popup_core::spec::ArmSpec;

fn model(dt: f64, integ: Integrator) -> Model {
    let opts = Options { dt, integrator: integ, disable: Disable { damper: true, ..Disable::default() }, ..Options::default() };
    Model::compile(&ArmSpec::popup_lab(), opts).unwrap()
}

fn start(m: &Model, pd: &ParamData) -> State {
    let mut s = rest_state(m, pd, 0.0, [0.3, 0.6, -0.3]).unwrap();
    s.q[3] += 0.02;
    s.q[5] += 0.01;
    s.v[0] = 0.5;
    s.v[1] = -0.3;
    s.v[4] = 0.8;
    s.v[6] = 0.5;
    s
}

fn free_run(dt: f64, integ: Integrator, t: f64) -> Trajectory {
    let m = model(dt, integ);
    let pd = ParamData::new(&m, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3] }).unwrap();
    let s = start(&m, &pd);
    let cfg = RunConfig { drive: constant_torque([0.0; 3]), initial: Some(s), duration: Some(t), sample_period: dt, check_step: true };
    run(&m, &pd, &cfg).unwrap()
}


fn run_from(dt: f64, integ: Integrator, t: f64, s: State, sp: f64) -> Trajectory {
    let m = model(dt, integ);
    let pd = ParamData::new(&m, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3] }).unwrap();
    let cfg = RunConfig { drive: constant_torque([0.0; 3]), initial: Some(s), duration: Some(t), sample_period: sp, check_step: true };
    run(&m, &pd, &cfg).unwrap()
}

#[test]
fn explore2() {
    let m = model(1e-3, Integrator::Rk4);
    let pd = ParamData::new(&m, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3] }).unwrap();
    let swing = start(&m, &pd);
    let mut hang = rest_state(&m, &pd, 0.0, [0.0, -std::f64::consts::FRAC_PI_2, 0.0]).unwrap();
    hang.q[3] += 0.02; hang.q[5] += 0.01; hang.v[1] = 0.2; hang.v[4] = -0.3; hang.v[0] = 0.1;
    for (name, s0) in [("swing", swing), ("hang", hang)] {
        for tt in [0.5, 1.0, 2.0] {
            let r = run_from(1.25e-4/2.0, Integrator::Rk4, tt, s0, 2e-3).final_state;
            let mut errs = vec![];
            for dt in [2e-4, 1e-4, 5e-5, 2.5e-5] {
                let f = run_from(dt, Integrator::SemiImplicit, tt, s0, 2e-3).final_state;
                errs.push(common::qdiff(&f, &r));
            }
            println!("{name} T {tt}: SI errs {errs:?} orders {:?}", orders(&errs));
        }
        for integ in [Integrator::Rk4, Integrator::SemiImplicit] {
            let dts = if integ == Integrator::Rk4 { vec![2e-3, 1e-3, 5e-4, 2.5e-4] } else { vec![2e-4, 1e-4, 5e-5] };
            let mut dr = vec![];
            for dt in dts {
                let tr = run_from(dt, integ, 2.0, s0, 2e-3);
                let e = col(&tr, "energy");
                let n = e.len();
                let d = e.iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                let d1 = e[..n / 3].iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                let d3 = e[2 * n / 3..].iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                println!("{name} {integ:?} dt {dt:e} E0 {} drift {d:e} first {d1:e} last {d3:e} final {:e}", e[0], e[n-1]-e[0]);
                dr.push(d);
            }
            println!("  orders {:?}", orders(&dr));
        }
    }
}

#[test]
#[ignore]
fn explore() {
    for integ in [Integrator::Rk4, Integrator::SemiImplicit] {
        let dts: Vec<f64> = if integ == Integrator::Rk4 { vec![4e-3, 2e-3, 1e-3, 5e-4, 2.5e-4] } else { vec![4e-4, 2e-4, 1e-4, 5e-5] };
        let mut drift = vec![];
        for &dt in &dts {
            let t0 = std::time::Instant::now();
            match std::panic::catch_unwind(|| free_run(dt, integ, 2.0)) {
                Ok(tr) => {
                    let e = col(&tr, "energy");
                    let d = e.iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                    let n = e.len();
                    let d1 = e[..n / 3].iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                    let d3 = e[2 * n / 3..].iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
                    let q2 = col(&tr, "q2");
                    println!("{integ:?} dt {dt:e}: E0 {} drift {d:e} first third {d1:e} last third {d3:e}  q2 end {} ({:?})", e[0], q2[n-1], t0.elapsed());
                    drift.push(d);
                }
                Err(_) => println!("{dt} failed"),
            }
        }
        println!("orders {:?}", orders(&drift));
    }
    let _ = VecN::zeros();
    let m = model(1e-3, Integrator::Rk4);
    let pd = ParamData::new(&m, &Params { payload_kg: 2.0, pressure_pa: [30e3, 30e3] }).unwrap();
    let s = start(&m, &pd);
    let mut e: Vec<f64> = popup_core::statics::linear_eigs(&m, &pd, &s.q, &[0,1,2,3,4,5,6], false).iter().map(|x| x.0.norm()).collect();
    e.sort_by(|a,b| a.partial_cmp(b).unwrap());
    println!("eigs {e:?}");
    for dt in [2e-5, 1e-5] {
        let tr = free_run(dt, Integrator::SemiImplicit, 2.0);
        let e = col(&tr, "energy");
        let d = e.iter().map(|x| (x - e[0]).abs()).fold(0.0, f64::max);
        println!("SI dt {dt}: drift {d:e} q2 end {}", col(&tr, "q2")[e.len()-1]);
    }
}

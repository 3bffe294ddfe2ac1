//! The nominal 7-DOF model (one segment per link, no torsion) is bit-identical to the code
//! before the chain length became variable.
//!
//! `tests/data/nominal_reference.txt` was written by the 7-DOF-only code (commit "bit-identity
//! reference data from the fixed 7-DOF core") with `POPUP_WRITE_REFERENCE=1 cargo test
//! --release -p popup-core --test bit_identity`. It holds, per run, every output channel of
//! every sample (`Trajectory.data`), the final state and the wrinkling alarms, each f64 as
//! the 16 hex digits of its bits. The runs start from the static rest state (Newton on the
//! bending joints), so the equilibrium solver is covered too. Any change to the floating-
//! point operations of the nominal model (order of a sum, a different factorisation,
//! vectors of another length in a dot product) shows here as a changed bit.

use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::model::{Integrator, Model, Options};
use popup_core::params::{ParamData, Params};
use popup_core::sim::{run, RunConfig, Trajectory};
use popup_core::spec::ArmSpec;
use std::f64::consts::PI;
use std::fmt::Write as _;

const PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/nominal_reference.txt");

fn bits(tr: &Trajectory) -> Vec<u64> {
    let mut b: Vec<u64> = tr.data.iter().map(|x| x.to_bits()).collect();
    b.push(tr.nsample as u64);
    b.push(tr.final_state.t.to_bits());
    // the first 7 joints: the whole chain of the nominal model
    b.extend((0..7).map(|i| tr.final_state.q[i].to_bits()));
    b.extend((0..7).map(|i| tr.final_state.v[i].to_bits()));
    for a in &tr.alarms {
        b.extend([a.link as u64, a.t_start.to_bits(), a.t_end.to_bits(), a.peak_ratio.to_bits()]);
    }
    b
}

/// The reference runs: (name, bits).
fn runs() -> Vec<(String, Vec<u64>)> {
    let mut out = Vec::new();
    for (integ, dt) in [(Integrator::Rk4, 1e-3), (Integrator::SemiImplicit, 2.5e-4)] {
        // the reference data was generated with the spec's first armature assumption (0.05 kg·m²)
        let mut spec = ArmSpec::popup_lab();
        spec.motors.armature_kgm2 = [0.05; 3];
        let model = Model::compile(&spec, Options { dt, integrator: integ, ..Options::default() }).unwrap();
        let mut p = Params::defaults(&model);
        p.payload_kg = 1.3;
        p.pressure_pa = [27e3, 41e3];
        let pd = ParamData::new(&model, &p).unwrap();

        // torque drive from rest at zero motor angles: the arm falls and swings, all
        // bending joints excited; torques vary piecewise linearly
        let t = [0.0, 0.05, 0.12, 0.3, 0.45, 0.6];
        let y = [[0.0, 0.0, 0.0], [3.0, 25.0, 6.0], [-2.0, 40.0, 12.0], [1.5, 10.0, -4.0], [-1.0, 30.0, 8.0], [0.0, 20.0, 2.0]];
        let drive = Drive::Torque(Linear3::new(&t, &y).unwrap());
        let cfg = RunConfig { drive, initial: None, duration: Some(0.6), sample_period: 1e-2, check_step: true };
        out.push((format!("{} torque", integ.name()), bits(&run(&model, &pd, &cfg).unwrap())));

        // encoder replay: a fast out-of-plane move with the elbow bent
        let tk: Vec<f64> = (0..=48).map(|k| k as f64 * 0.0125).collect();
        let yk: Vec<[f64; 3]> = tk
            .iter()
            .map(|&t| [0.6 * (2.0 * PI * 1.1 * t).sin(), 0.4 + 0.3 * (2.0 * PI * 0.7 * t).sin(), -0.8 + 0.25 * (2.0 * PI * 1.6 * t).cos()])
            .collect();
        let drive = Drive::Replay(Spline3::new(&tk, &yk).unwrap());
        let cfg = RunConfig { drive, initial: None, duration: None, sample_period: 1e-2, check_step: true };
        out.push((format!("{} replay", integ.name()), bits(&run(&model, &pd, &cfg).unwrap())));
    }
    out
}

fn write(runs: &[(String, Vec<u64>)]) {
    let mut s = String::from("# popup-core nominal 7-DOF reference: per run a header line, then f64 bits as hex, 6 per line\n");
    for (name, b) in runs {
        writeln!(s, "run {name} {}", b.len()).unwrap();
        for chunk in b.chunks(6) {
            let line: Vec<String> = chunk.iter().map(|x| format!("{x:016x}")).collect();
            writeln!(s, "{}", line.join(" ")).unwrap();
        }
    }
    std::fs::write(PATH, s).unwrap();
}

fn read() -> Vec<(String, Vec<u64>)> {
    let text = std::fs::read_to_string(PATH).expect("reference data file");
    let mut out: Vec<(String, Vec<u64>)> = Vec::new();
    for line in text.lines() {
        if line.starts_with('#') || line.trim().is_empty() {
            continue;
        }
        if let Some(rest) = line.strip_prefix("run ") {
            let (name, n) = rest.rsplit_once(' ').unwrap();
            out.push((name.to_string(), Vec::with_capacity(n.parse().unwrap())));
            continue;
        }
        let cur = out.last_mut().unwrap();
        cur.1.extend(line.split_whitespace().map(|h| u64::from_str_radix(h, 16).unwrap()));
    }
    out
}

#[test]
fn nominal_model_is_bit_identical_to_the_fixed_7dof_code() {
    let now = runs();
    if std::env::var("POPUP_WRITE_REFERENCE").is_ok() {
        write(&now);
    }
    let reference = read();
    assert_eq!(reference.len(), now.len());
    for ((rn, rb), (nn, nb)) in reference.iter().zip(&now) {
        assert_eq!(rn, nn);
        assert_eq!(rb.len(), nb.len(), "{rn}: number of values");
        let diff: Vec<usize> = (0..rb.len()).filter(|&i| rb[i] != nb[i]).collect();
        assert!(
            diff.is_empty(),
            "{rn}: {} of {} values differ; first at {} (reference {:e}, now {:e})",
            diff.len(),
            rb.len(),
            diff[0],
            f64::from_bits(rb[diff[0]]),
            f64::from_bits(nb[diff[0]])
        );
    }
}

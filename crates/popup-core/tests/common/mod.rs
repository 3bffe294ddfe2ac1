//! Helpers shared by the contract tests (deterministic RNG, runs, channel access).
#![allow(dead_code)]

use popup_core::drive::{Drive, Linear3, Spline3};
use popup_core::effects::Effects;
use popup_core::math::VecN;
use popup_core::model::Model;
use popup_core::params::{ParamData, Params};
use popup_core::sensor::{channel_index, NCH};
use popup_core::sim::{run, RunConfig, State, Trajectory};

/// xorshift64* — deterministic, no external crate.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
    /// Uniform entries in [lo, hi) for the first `n` joints, 0 beyond.
    pub fn vec_n(&mut self, lo: f64, hi: f64, n: usize) -> VecN {
        VecN::from_fn(|i, _| if i < n { self.uniform(lo, hi) } else { 0.0 })
    }
}

/// Column `name` of a trajectory.
pub fn col(tr: &Trajectory, name: &str) -> Vec<f64> {
    let c = channel_index(name).unwrap_or_else(|| panic!("no channel {name}"));
    (0..tr.nsample).map(|r| tr.data[r * NCH + c]).collect()
}

/// Constant motor torques as a drive.
pub fn constant_torque(tau: [f64; 3]) -> Drive {
    Drive::Torque(Linear3::new(&[0.0], &[tau]).unwrap())
}

/// Full joint state (q, v) of sample row `r` rebuilt from the channels.
pub fn state_of_row(model: &Model, tr: &Trajectory, r: usize) -> State {
    let row = &tr.data[r * NCH..(r + 1) * NCH];
    let mut q = VecN::zeros();
    let mut v = VecN::zeros();
    for k in 0..3 {
        q[model.motor_idx[k]] = row[1 + k];
        v[model.motor_idx[k]] = row[4 + k];
    }
    assert!(model.segments == [1, 1] && model.torsion_idx == [None, None], "state_of_row needs the 7-joint chain");
    for a in 0..4 {
        q[model.root_bend_idx[a]] = row[21 + a];
        v[model.root_bend_idx[a]] = row[25 + a];
    }
    State { t: row[0], q, v }
}

/// Max-abs difference of the joint coordinates of two states.
pub fn qdiff(a: &State, b: &State) -> f64 {
    (0..a.q.len()).map(|i| (a.q[i] - b.q[i]).abs()).fold(0.0, f64::max)
}

/// log2 of successive error ratios.
pub fn orders(errs: &[f64]) -> Vec<f64> {
    errs.windows(2).map(|w| (w[0] / w[1]).log2()).collect()
}

/// Roots βL of the tip-mass cantilever frequency equation 1 + cos βL cosh βL +
/// μ βL (cos βL sinh βL − sin βL cosh βL) = 0 (μ = tip mass / beam mass), the first `k`.
pub fn tip_mass_roots(mu: f64, k: usize) -> Vec<f64> {
    let f = |b: f64| 1.0 + b.cos() * b.cosh() + mu * b * (b.cos() * b.sinh() - b.sin() * b.cosh());
    let mut out = Vec::new();
    let mut x = 0.05;
    while out.len() < k {
        let (mut lo, mut hi) = (x, x + 0.01);
        if f(lo) * f(hi) <= 0.0 {
            for _ in 0..100 {
                let mid = 0.5 * (lo + hi);
                if f(lo) * f(mid) <= 0.0 {
                    hi = mid
                } else {
                    lo = mid
                }
            }
            out.push(0.5 * (lo + hi));
        }
        x += 0.01;
    }
    out
}

/// Smootherstep 0 → 1 over [0, 1] (zero rate and acceleration at both ends).
pub fn ramp(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    u * u * u * (10.0 - 15.0 * u + 6.0 * u * u)
}

/// The lab arm's parameters (1 kg payload, 30 kPa in both links) with the effects `fx`.
pub fn lab_pd(m: &Model, fx: Effects) -> ParamData {
    ParamData::new(m, &Params { payload_kg: 1.0, pressure_pa: [30e3; 2], effects: fx }).unwrap()
}

/// Encoder replay of the motor angles `y` [rad] at stamps `t` [s] (cubic spline, step
/// checked), sampled every 2 ms.
pub fn replay_2ms(m: &Model, fx: Effects, t: &[f64], y: &[[f64; 3]]) -> Trajectory {
    let cfg = RunConfig { drive: Drive::Replay(Spline3::new(t, y).unwrap()), initial: None, duration: None, sample_period: 2e-3, check_step: true };
    run(m, &lab_pd(m, fx), &cfg).unwrap()
}

/// Largest |a − b| over channel `ch` of two runs sampled alike.
pub fn max_abs_diff(a: &Trajectory, b: &Trajectory, ch: &str) -> f64 {
    col(a, ch).iter().zip(col(b, ch)).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

/// Every f64 of a run as bits (samples, sample count, final state, alarms) and its
/// warnings: two runs are the same when these are equal.
pub fn traj_bits(tr: &Trajectory) -> Vec<u64> {
    let mut b: Vec<u64> = tr.data.iter().map(|x| x.to_bits()).collect();
    b.push(tr.nsample as u64);
    b.push(tr.final_state.t.to_bits());
    b.extend(tr.final_state.q.iter().chain(tr.final_state.v.iter()).map(|x| x.to_bits()));
    for a in &tr.alarms {
        b.extend([a.link as u64, a.t_start.to_bits(), a.t_end.to_bits(), a.peak_ratio.to_bits()]);
    }
    b.extend(tr.warnings.iter().flat_map(|w| w.bytes().map(u64::from)));
    b
}

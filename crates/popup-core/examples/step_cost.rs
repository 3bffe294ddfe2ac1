//! Cost of one RK4 step and of its parts vs the number of beam elements, and the CRBA +
//! Cholesky forward dynamics vs the O(nv) articulated-body path (`dynamics::articulated`)
//! for nv = 7 … 31.
//!
//! Run: `cargo run --release -p popup-core --example step_cost` (single-threaded; every
//! figure is the best of several repeats, in ns per call; `-- sweep` prints table 2 only).
//! Asserts nothing.
//!
//! Table 1: `popup-lab`, 2 kg payload, torque drive holding the gravity torques at the
//! rest pose (q2 = −1.2 rad), link 2 as beam(n) for n = 0 … 6 and both links beam(1 … 3):
//! the whole `integrate::step_with` (RK4 = 4 evaluations), CRBA, RNEA, the Cholesky solve,
//! the beam links' dense elastic + Rayleigh forces, all passive forces, one evaluation of
//! each forward-dynamics path and an RK4 step built on the articulated path.
//! Table 2: per evaluation, both paths for one structure per nv = 7 … 31 (PRBM segments,
//! torsion joints, beam links), the crossover, and a least-squares line through the
//! articulated path's cost (R², largest deviation).

use popup_core::drive::{Drive, Linear3};
use popup_core::dynamics::articulated::{accel_articulated, articulated};
use popup_core::dynamics::{crba_into, rnea};
use popup_core::forward::{accel_with, passive, prescribe};
use popup_core::integrate::{step_with, Workspace};
use popup_core::math::{cholesky_solve, MatN, VecN};
use popup_core::model::{Model, Options, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::sim::rest_state;
use popup_core::spec::ArmSpec;
use popup_core::statics::gravity_torque;
use std::hint::black_box;
use std::time::Instant;

/// Best-of-`REPEATS` time per call [ns]; each repeat runs about `TARGET_S` seconds.
const REPEATS: usize = 15;
const TARGET_S: f64 = 0.008;

fn time_ns<F: FnMut()>(mut f: F) -> f64 {
    // calibrate the number of calls per repeat
    let mut n = 1usize;
    loop {
        let t0 = Instant::now();
        for _ in 0..n {
            f();
        }
        let el = t0.elapsed().as_secs_f64();
        if el > 2e-3 || n > 1 << 24 {
            n = ((n as f64) * TARGET_S / el.max(1e-9)).ceil().max(1.0) as usize;
            break;
        }
        n *= 4;
    }
    let mut best = f64::INFINITY;
    for _ in 0..REPEATS {
        let t0 = Instant::now();
        for _ in 0..n {
            f();
        }
        best = best.min(t0.elapsed().as_secs_f64() / n as f64);
    }
    best * 1e9
}

/// A compiled arm with its parameters, a holding-torque drive and a state.
struct Setup {
    model: Model,
    pd: ParamData,
    drive: Drive,
    q: VecN,
    v: VecN,
}

fn setup(structure: Structure) -> Option<Setup> {
    let model = Model::compile(&ArmSpec::popup_lab(), Options { structure, ..Options::default() }).ok()?;
    let mut p = Params::defaults(&model);
    p.payload_kg = 2.0;
    p.pressure_pa = [30e3, 30e3];
    p.effects.torsion.k_t = [500.0, 200.0];
    p.effects.torsion.c_t = [0.1, 0.01];
    let pd = ParamData::new(&model, &p).ok()?;
    let q = match rest_state(&model, &pd, 0.0, [0.0, -1.2, 0.4]) {
        Ok(s) => s.q,
        Err(_) => {
            let mut q = VecN::zeros();
            for (k, &i) in model.motor_idx.iter().enumerate() {
                q[i] = [0.0, -1.2, 0.4][k];
            }
            q
        }
    };
    let g = gravity_torque(&model, &pd, &q);
    let hold = model.motor_idx.map(|i| g[i]);
    let drive = Drive::Torque(Linear3::new(&[0.0], &[hold]).unwrap());
    // small, deterministic joint rates so that every velocity term is exercised
    let v = VecN::from_fn(|i, _| if i < model.nv { 0.05 * ((i as f64) * 1.7).sin() } else { 0.0 });
    Some(Setup { model, pd, drive, q, v })
}

/// The beam links' dense forces `−K_φ φ − C_φ φ̇` (the loop of `forward::passive`).
fn beam_forces(model: &Model, pd: &ParamData, q: &VecN, v: &VecN, out: &mut VecN) {
    for bl in model.beam.iter().flatten() {
        let r = bl.start..bl.start + bl.dof();
        for i in r.clone() {
            let mut f = 0.0;
            for j in r.clone() {
                f -= pd.beam_k[(i, j)] * q[j];
                f -= pd.beam_c[(i, j)] * v[j];
            }
            out[i] += f;
        }
    }
}

/// Classical RK4 on the articulated path (the same stages as `integrate::rk4`).
fn rk4_articulated(model: &Model, pd: &ParamData, drive: &Drive, t: f64, h: f64, q: &mut VecN, v: &mut VecN) {
    let stage = |t: f64, q: &mut VecN, v: &mut VecN| {
        let am = prescribe(model, drive, t, q, v);
        accel_articulated(model, pd, drive, t, q, v, am)
    };
    let (q0, mut v1) = (*q, *v);
    let mut q1 = q0;
    let a1 = stage(t, &mut q1, &mut v1);
    let (mut q2, mut v2) = (q1 + v1 * (0.5 * h), v1 + a1 * (0.5 * h));
    let a2 = stage(t + 0.5 * h, &mut q2, &mut v2);
    let (mut q3, mut v3) = (q1 + v2 * (0.5 * h), v1 + a2 * (0.5 * h));
    let a3 = stage(t + 0.5 * h, &mut q3, &mut v3);
    let (mut q4, mut v4) = (q1 + v3 * h, v1 + a3 * h);
    let a4 = stage(t + h, &mut q4, &mut v4);
    *q = q1 + (v1 + (v2 + v3) * 2.0 + v4) * (h / 6.0);
    *v = v1 + (a1 + (a2 + a3) * 2.0 + a4) * (h / 6.0);
    prescribe(model, drive, t + h, q, v);
}

/// Per-evaluation costs [ns]: (CRBA path `accel_with`, articulated path `accel_articulated`,
/// CRBA + RNEA + Cholesky, articulated core).
fn eval_costs(s: &Setup) -> (f64, f64, f64, f64) {
    let (m, pd, d) = (&s.model, &s.pd, &s.drive);
    let mut ws = MatN::zeros();
    let t_crba_path = time_ns(|| {
        black_box(accel_with(m, pd, d, black_box(0.1), black_box(&s.q), black_box(&s.v), None, 0.0, &mut ws));
    });
    let t_art_path = time_ns(|| {
        black_box(accel_articulated(m, pd, d, black_box(0.1), black_box(&s.q), black_box(&s.v), None));
    });
    let rot = m.rotations(&s.q);
    let tau = passive(m, pd, 0.1, &s.q, &s.v);
    let n = m.nv;
    let mut mm = MatN::zeros();
    let t_crba_core = time_ns(|| {
        crba_into(m, &pd.body, black_box(&rot), &mut mm);
        for i in 0..n {
            mm[(i, i)] += m.armature[i];
        }
        let b = rnea(m, &pd.body, black_box(&rot), black_box(&s.v), &VecN::zeros(), &m.gravity);
        let mut rhs = tau - b;
        black_box(cholesky_solve(&mut mm, &mut rhs, n));
        black_box(rhs);
    });
    let t_art_core = time_ns(|| {
        black_box(articulated(m, &pd.body, black_box(&rot), black_box(&s.v), black_box(&tau), &m.armature, &m.gravity, &[], &[]));
    });
    (t_crba_path, t_art_path, t_crba_core, t_art_core)
}

/// Least-squares line y = a + b x; returns (a, b, R², largest |y − fit| / fit).
fn line_fit(x: &[f64], y: &[f64]) -> (f64, f64, f64, f64) {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    let sxx: f64 = x.iter().map(|a| (a - mx) * (a - mx)).sum();
    let syy: f64 = y.iter().map(|b| (b - my) * (b - my)).sum();
    let b = sxy / sxx;
    let a = my - b * mx;
    let ss_res: f64 = x.iter().zip(y).map(|(xi, yi)| (yi - a - b * xi).powi(2)).sum();
    let dev = x.iter().zip(y).map(|(xi, yi)| ((yi - a - b * xi) / (a + b * xi)).abs()).fold(0.0, f64::max);
    (a, b, 1.0 - ss_res / syy, dev)
}

fn name(st: &Structure) -> String {
    let t = |l: usize| if st.torsion[l] { "+t" } else { "" };
    format!("{}{} / {}{}", st.link_name(0), t(0), st.link_name(1), t(1))
}

fn main() {
    // `-- sweep`: table 2 only
    if std::env::args().nth(1).as_deref() != Some("sweep") {
        table1();
    }
    table2();
}

fn table1() {
    // ---- table 1: RK4 step breakdown vs beam elements
    let mut configs: Vec<Structure> = (0..=6).map(|n| Structure { elements: [0, n], ..Structure::default() }).collect();
    configs.extend((1..=3).map(|n| Structure { elements: [n, n], ..Structure::default() }));
    println!("Table 1: RK4 step and its parts [ns per call, best of {REPEATS}] (popup-lab, 2 kg, holding torques)");
    println!(
        "{:<18} {:>3} {:>9} {:>8} {:>7} {:>7} {:>7} {:>7} {:>9} {:>9} {:>9}",
        "links", "nv", "step_rk4", "crba", "rnea", "chol", "beam_f", "passive", "eval_crba", "eval_aba", "step_aba"
    );
    for st in &configs {
        let Some(s) = setup(*st) else {
            println!("{:<18} does not compile", name(st));
            continue;
        };
        let (m, pd, d) = (&s.model, &s.pd, &s.drive);
        let n = m.nv;
        let h = 1e-4;
        let mut ws = Workspace::new();
        let t_step = time_ns(|| {
            let (mut q, mut v) = (s.q, s.v);
            step_with(m, pd, d, black_box(0.1), h, &mut q, &mut v, &mut ws);
            black_box((q, v));
        });
        let t_step_aba = time_ns(|| {
            let (mut q, mut v) = (s.q, s.v);
            rk4_articulated(m, pd, d, black_box(0.1), h, &mut q, &mut v);
            black_box((q, v));
        });
        let rot = m.rotations(&s.q);
        let mut mm = MatN::zeros();
        let t_crba = time_ns(|| crba_into(m, &pd.body, black_box(&rot), &mut mm));
        let t_rnea = time_ns(|| {
            black_box(rnea(m, &pd.body, black_box(&rot), black_box(&s.v), &VecN::zeros(), &m.gravity));
        });
        crba_into(m, &pd.body, &rot, &mut mm);
        for i in 0..n {
            mm[(i, i)] += m.armature[i];
        }
        let rhs0 = VecN::from_fn(|i, _| if i < n { 1.0 } else { 0.0 });
        let t_copy = time_ns(|| {
            let a = black_box(mm);
            black_box(a);
        });
        let t_chol = time_ns(|| {
            let mut a = black_box(mm);
            let mut b = black_box(rhs0);
            black_box(cholesky_solve(&mut a, &mut b, n));
            black_box(b);
        }) - t_copy;
        let t_beam = time_ns(|| {
            let mut out = VecN::zeros();
            beam_forces(m, pd, black_box(&s.q), black_box(&s.v), &mut out);
            black_box(out);
        });
        let t_pass = time_ns(|| {
            black_box(passive(m, pd, black_box(0.1), black_box(&s.q), black_box(&s.v)));
        });
        let (e_crba, e_aba, _, _) = eval_costs(&s);
        println!(
            "{:<18} {:>3} {:>9.0} {:>8.0} {:>7.0} {:>7.0} {:>7.0} {:>7.0} {:>9.0} {:>9.0} {:>9.0}",
            name(st),
            n,
            t_step,
            t_crba,
            t_rnea,
            t_chol.max(0.0),
            t_beam,
            t_pass,
            e_crba,
            e_aba,
            t_step_aba
        );
    }
    println!("(chol: Cholesky factorisation + solve of the nv × nv system, the 7.7 kB matrix copy subtracted;");
    println!(" beam_f: the dense −K_φ φ − C_φ φ̇ blocks alone; passive: all passive forces incl. beam_f;");
    println!(" eval_*: one forward-dynamics evaluation; step_aba: RK4 on the articulated path)");
}

fn table2() {

    // ---- table 2: per-evaluation cost vs nv
    // link options: (segments, elements, torsion) → joints 2 s + t (PRBM) or 4 n + t (beam)
    let mut opts: Vec<(usize, usize, bool)> = Vec::new();
    for t in [false, true] {
        for sgm in 1..=3 {
            opts.push((sgm, 0, t));
        }
        for e in 1..=6 {
            opts.push((1, e, t));
        }
    }
    let joints = |o: &(usize, usize, bool)| if o.1 > 0 { 4 * o.1 } else { 2 * o.0 } + usize::from(o.2);
    println!();
    println!("Table 2: one forward-dynamics evaluation [ns] (RK4 does 4 per step)");
    println!("{:<22} {:>3} {:>10} {:>10} {:>7} {:>10} {:>10} {:>7}", "links", "nv", "crba_path", "aba_path", "ratio", "crba_core", "aba_core", "ratio");
    let (mut xs, mut ys, mut ys_core) = (Vec::new(), Vec::new(), Vec::new());
    let mut rows: Vec<(usize, f64, f64)> = Vec::new();
    for nv in 7..=31 {
        // the structure with the most beam joints for this nv (ties: link 2 the beam)
        let mut best: Option<(usize, Structure)> = None;
        for o1 in &opts {
            for o2 in &opts {
                if 3 + joints(o1) + joints(o2) != nv {
                    continue;
                }
                let st = Structure { segments: [o1.0, o2.0], torsion: [o1.2, o2.2], elements: [o1.1, o2.1] };
                let score = 4 * (o1.1 + o2.1) * 10 + o2.1;
                if best.map_or(true, |(b, _)| score > b) && Model::compile(&ArmSpec::popup_lab(), Options { structure: st, ..Options::default() }).is_ok() {
                    best = Some((score, st));
                }
            }
        }
        let Some((_, st)) = best else {
            println!("{:<22} {nv:>3} (no structure)", "-");
            continue;
        };
        let Some(s) = setup(st) else { continue };
        // two rounds, the faster of each (the machine may be shared)
        let (c, a, cc, ac) = eval_costs(&s);
        let (c2, a2, cc2, ac2) = eval_costs(&s);
        let (c, a, cc, ac) = (c.min(c2), a.min(a2), cc.min(cc2), ac.min(ac2));
        println!("{:<22} {:>3} {:>10.0} {:>10.0} {:>7.2} {:>10.0} {:>10.0} {:>7.2}", name(&st), nv, c, a, c / a, cc, ac, cc / ac);
        xs.push(nv as f64);
        ys.push(a);
        ys_core.push(ac);
        rows.push((nv, c, a));
    }
    // crossover: the first nv from which the articulated path stays cheaper
    let cross = (0..rows.len()).find(|&k| rows[k..].iter().all(|r| r.2 < r.1)).map(|k| rows[k].0);
    match cross {
        Some(nv) => println!("crossover: the articulated path is cheaper for every nv >= {nv} measured"),
        None => println!("crossover: none (the CRBA path stays cheaper up to nv = 31)"),
    }
    let (a, b, r2, dev) = line_fit(&xs, &ys);
    println!("articulated path (accel_articulated): {a:.0} ns + {b:.1} ns × nv, R² = {r2:.4}, largest deviation {:.1} %", dev * 100.0);
    let (a, b, r2, dev) = line_fit(&xs, &ys_core);
    println!("articulated core (articulated()):      {a:.0} ns + {b:.1} ns × nv, R² = {r2:.4}, largest deviation {:.1} %", dev * 100.0);
    let crba: Vec<f64> = rows.iter().map(|r| r.1).collect();
    let (a, b, r2, dev) = line_fit(&xs, &crba);
    println!("(CRBA path for comparison, same fit:   {a:.0} ns + {b:.1} ns × nv, R² = {r2:.4}, largest deviation {:.1} %)", dev * 100.0);
}

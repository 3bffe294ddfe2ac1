//! `higher_bending_modes`: links split into 2 or 3 segments, each with its own universal
//! joint (`Options.structure.segments`).
//!
//! - (1) at zero bending every frame of the arm file's chain (motor frames, IMU mounts, end
//!   effector, payload mount) is where the one-segment model puts it (1e-12);
//! - (2) mass, centre of mass and inertia of each link are unchanged (1e-12), and the tube
//!   mass is really spread over the segments (len/S per segment), not lumped on the last;
//! - (3) the segment stiffness k_s = k Σ_{i<S} (1 − i/S)² gives the static tip deflection of
//!   the one-joint link under a small tip force (relative 1e-4; the factor 1 would be off by
//!   25 % for S = 2), in both bending planes, and `seg_k_scale` divides it;
//! - (4) the first bending mode stays within 15 % of the one-segment model while a higher
//!   mode per plane and per added segment appears;
//! - the channels d11..d22 / dd11..dd22 sum the segments, m11..m22 are the root moments, the
//!   energy counts every segment spring; bad segment counts are refused by name.

use popup_core::drive::{Drive, Spline3};
use popup_core::kinematics::prbm::{end_effector, frames};
use popup_core::math::{Vec3, VecN};
use popup_core::model::{Model, Options, Rbi, Structure};
use popup_core::params::{ParamData, Params};
use popup_core::sensor::{channel_index, energy, NCH};
use popup_core::sim::{rest_state, run, RunConfig};
use popup_core::spec::ArmSpec;
use popup_core::statics::locked_modes;
use popup_core::Error;
use std::f64::consts::{FRAC_PI_2, PI};

fn structures() -> Vec<Structure> {
    let mut v = Vec::new();
    for s0 in 1..=3 {
        for s1 in 1..=3 {
            for t in [[false, false], [true, false], [false, true], [true, true]] {
                let s = Structure { segments: [s0, s1], torsion: t, elements: [0, 0] };
                if !s.is_nominal() {
                    v.push(s);
                }
            }
        }
    }
    v
}

fn compile(spec: &ArmSpec, structure: Structure) -> Model {
    Model::compile(spec, Options { structure, ..Options::default() }).unwrap()
}

fn params(model: &Model, payload: f64) -> Params {
    let mut p = Params::defaults(model);
    p.payload_kg = payload;
    p.pressure_pa = [30e3, 30e3];
    for l in 0..2 {
        if model.torsion_idx[l].is_some() {
            p.effects.torsion.k_t[l] = 500.0;
            p.effects.torsion.c_t[l] = 0.1;
        }
    }
    p
}

/// Joint vector with the motors at `qm` and every passive joint at zero.
fn motors_only(model: &Model, qm: [f64; 3]) -> VecN {
    let mut q = VecN::zeros();
    for k in 0..3 {
        q[model.motor_idx[k]] = qm[k];
    }
    q
}

#[test]
fn original_frames_unchanged_at_zero_bending() {
    let spec = ArmSpec::popup_lab();
    let nominal = compile(&spec, Structure::default());
    let poses = [[0.0, 0.0, 0.0], [0.3, -0.7, 1.1], [-2.0, 1.2, -0.4], [1.0, FRAC_PI_2, -FRAC_PI_2]];
    let mut worst: f64 = 0.0;
    for s in structures() {
        let m = compile(&spec, s);
        assert_eq!(m.nv, 3 + 2 * (s.segments[0] + s.segments[1]) + s.torsion.iter().filter(|&&t| t).count());
        assert_eq!(m.joints.len(), m.nv);
        for qm in poses {
            let (f0, f) = (frames(&nominal, &motors_only(&nominal, qm)), frames(&m, &motors_only(&m, qm)));
            for b in 0..7 {
                let (i0, i) = (nominal.spec_body[b] + 1, m.spec_body[b] + 1);
                let d = (f0.r_wb[i0] - f.r_wb[i]).amax().max((f0.p_wb[i0] - f.p_wb[i]).amax());
                worst = worst.max(d);
                assert!(d < 1e-12, "{s:?} at {qm:?}: frame of body {} ({}) differs by {d:e}", b + 1, spec.bodies[b].name);
            }
            for k in 0..2 {
                let p0 = f0.point(nominal.imu[k].0 + 1, &nominal.imu[k].1);
                let p = f.point(m.imu[k].0 + 1, &m.imu[k].1);
                assert!((p0 - p).amax() < 1e-12, "{s:?}: IMU {k} mount moved by {:e}", (p0 - p).amax());
                assert!((f0.r_wb[nominal.imu[k].0 + 1] - f.r_wb[m.imu[k].0 + 1]).amax() < 1e-12, "{s:?}: IMU {k} axes turned");
            }
            let e0 = end_effector(&nominal, &motors_only(&nominal, qm));
            let e = end_effector(&m, &motors_only(&m, qm));
            assert!((e0 - e).amax() < 1e-12, "{s:?}: end effector moved by {:e}", (e0 - e).amax());
            let pl0 = f0.point(nominal.payload_body + 1, &nominal.payload_com);
            let pl = f.point(m.payload_body + 1, &m.payload_com);
            assert!((pl0 - pl).amax() < 1e-12, "{s:?}: payload moved");
        }
        // names: the root segment keeps the arm file's names, the others get _2, _3
        for l in 0..2 {
            for a in 0..2 {
                let js = m.channel_joints(2 * l + a);
                assert_eq!(js.len(), s.segments[l]);
                for (k, &j) in js.iter().enumerate() {
                    let base = format!("d{}{}", l + 1, a + 1);
                    let want = if k == 0 { base } else { format!("{base}_{}", k + 1) };
                    assert_eq!(m.joint_name(j), want);
                }
            }
            if s.torsion[l] {
                assert_eq!(m.joint_name(m.torsion_idx[l].unwrap()), format!("t{}", l + 1));
            }
        }
    }
    println!("frames at zero bending: worst difference {worst:.2e}");
}

/// Mass properties of link l (the bodies after its motor, up to the next motor) at
/// q, about the world origin in world axes.
fn link_inertia(m: &Model, l: usize, q: &VecN) -> Rbi {
    let f = frames(m, q);
    let start = m.motor_idx[l + 1];
    let end = if l == 0 { m.motor_idx[2] } else { m.nv };
    let mut total = Rbi::ZERO;
    for i in start..end {
        let (r, p) = (f.r_wb[i + 1], f.p_wb[i + 1]);
        total = total.add(&m.body[i].to_parent(&r, &(r.transpose() * p)));
    }
    total
}

#[test]
fn link_mass_properties_unchanged_and_spread_over_segments() {
    let spec = ArmSpec::popup_lab();
    let nominal = compile(&spec, Structure::default());
    let mut worst: f64 = 0.0;
    for s in structures() {
        let m = compile(&spec, s);
        for qm in [[0.0, 0.0, 0.0], [0.4, -1.0, 0.7]] {
            for l in 0..2 {
                let (a, b) = (link_inertia(&nominal, l, &motors_only(&nominal, qm)), link_inertia(&m, l, &motors_only(&m, qm)));
                let d = [(a.m - b.m).abs(), (a.h - b.h).amax(), (a.j - b.j).amax(), (a.h / a.m - b.h / b.m).amax()].into_iter().fold(0.0, f64::max);
                worst = worst.max(d);
                assert!(d < 1e-12, "{s:?} link {}: mass properties differ by {d:e}\n{a:?}\n{b:?}", l + 1);
            }
        }
        // each segment body holds its share of the outer tube; the points stay on the last
        let tube = [0.57, 0.38];
        let points = [1.5, 0.0];
        for l in 0..2 {
            let ns = s.segments[l];
            for k in 0..ns {
                let j = m.channel_joints(2 * l + 1)[k]; // second axis: its body is the segment
                let want = tube[l] / ns as f64 + if k + 1 == ns { points[l] } else { 0.0 };
                assert!((m.body[j].m - want).abs() < 1e-12, "{s:?} link {} segment {}: {} kg, expected {want}", l + 1, k + 1, m.body[j].m);
                // the segment's centre of mass: the middle of its piece of tube (points aside)
                let c = m.body[j].h / m.body[j].m;
                let seg = 0.57 / ns as f64;
                let want_x = if k + 1 == ns { (tube[l] / ns as f64 * (-seg / 2.0)) / want } else { -seg / 2.0 };
                assert!((c.x - want_x).abs() < 1e-12 && c.y.abs() < 1e-12 && c.z.abs() < 1e-12, "{s:?} link {} segment {}: centre {c:?}", l + 1, k + 1);
            }
        }
    }
    println!("link mass, centre and inertia vs one segment: worst difference {worst:.2e}");
}

/// popup-lab with every mass removed but a point load at the tip of link `l` (payload mount
/// moved there for link 1): gravity on the payload is then a pure tip force.
fn tip_load_spec(l: usize) -> ArmSpec {
    let mut spec = ArmSpec::popup_lab();
    for b in &mut spec.bodies {
        for p in &mut b.parts {
            p.mass_kg = 0.0;
            p.inertia_kgm2 = [0.0; 6];
        }
    }
    spec.payload.body = if l == 0 { 4 } else { 7 };
    spec.payload.com_m = [0.0; 3];
    spec
}

/// Static deflection of the loaded tip of link `l` under a 0.05 kg tip load with gravity
/// `g`, motors at zero (the arm along +x), in the axes of the link's root frame (the body of
/// its motor) and relative to it, so that only link l's own compliance counts.
fn tip_deflection(l: usize, segments: [usize; 2], g: [f64; 3], seg_k_scale: f64) -> Vec3 {
    let spec = tip_load_spec(l);
    let m = Model::compile(&spec, Options { gravity: Some(g), structure: Structure { segments, torsion: [false; 2], elements: [0, 0] }, ..Options::default() }).unwrap();
    let mut p = Params::defaults(&m);
    p.payload_kg = 0.05;
    p.effects.higher_bending_modes.k_scale[l] = seg_k_scale;
    let pd = ParamData::new(&m, &p).unwrap();
    let st = rest_state(&m, &pd, 0.0, [0.0; 3]).unwrap();
    let local = |q: &VecN| {
        let f = frames(&m, q);
        let root = m.motor_idx[l + 1] + 1;
        f.r_wb[root].transpose() * (f.point(m.payload_body + 1, &m.payload_com) - f.p_wb[root])
    };
    local(&st.q) - local(&VecN::zeros())
}

#[test]
fn segment_stiffness_gives_the_one_joint_tip_deflection() {
    // vertical plane (gravity −z) and lateral plane (gravity −y), both links
    for g in [[0.0, 0.0, -9.81], [0.0, -9.81, 0.0]] {
        for l in 0..2 {
            let one = tip_deflection(l, [1, 1], g, 1.0);
            assert!(one.norm() > 1e-4, "the tip load must deflect the tip (got {one:?} m)");
            for s in [2, 3] {
                let mut segs = [1, 1];
                segs[l] = s;
                let d = tip_deflection(l, segs, g, 1.0);
                let rel = (d - one).norm() / one.norm();
                println!("link {} g {g:?} S = {s}: tip deflection {:.6e} m vs one joint {:.6e} m (rel {rel:.1e})", l + 1, d.norm(), one.norm());
                assert!(rel < 1e-4, "link {} S = {s}: deflection {d:?} vs {one:?} (rel {rel:e})", l + 1);
                // seg_k_scale stiffens every segment joint of that link
                let d2 = tip_deflection(l, segs, g, 2.0);
                let r2 = (d2 - d * 0.5).norm() / d.norm();
                assert!(r2 < 1e-3, "seg_k_scale 2 should halve the deflection: {d2:?} vs {d:?}");
            }
        }
    }
}

/// Static tip deflection [m] and tip rotation [rad] (both in link l's root axes) of link `l`
/// under the 0.05 kg tip load of [`tip_deflection`], with gravity −z, for `segments` and a
/// `root_ratio` on that link.
fn tip_deflection_and_rotation(l: usize, segments: [usize; 2], root_ratio: f64) -> (Vec3, Vec3) {
    let spec = tip_load_spec(l);
    let m = Model::compile(&spec, Options { gravity: Some([0.0, 0.0, -9.81]), structure: Structure { segments, torsion: [false; 2], elements: [0, 0] }, ..Options::default() }).unwrap();
    let mut p = Params::defaults(&m);
    p.payload_kg = 0.05;
    p.effects.higher_bending_modes.root_ratio[l] = root_ratio;
    let pd = ParamData::new(&m, &p).unwrap();
    let st = rest_state(&m, &pd, 0.0, [0.0; 3]).unwrap();
    let root = m.motor_idx[l + 1] + 1;
    let tip = m.payload_body + 1;
    let pose = |q: &VecN| {
        let f = frames(&m, q);
        let r = f.r_wb[root].transpose() * f.r_wb[tip];
        (f.r_wb[root].transpose() * (f.point(tip, &m.payload_com) - f.p_wb[root]), r)
    };
    let (p1, r1) = pose(&st.q);
    let (p0, r0) = pose(&VecN::zeros());
    let dr = r1 * r0.transpose();
    (p1 - p0, Vec3::new(dr[(2, 1)] - dr[(1, 2)], dr[(0, 2)] - dr[(2, 0)], dr[(1, 0)] - dr[(0, 1)]) * 0.5)
}

#[test]
fn root_ratio_keeps_the_tip_deflection_and_four_gives_a_cantilevers_tip_rotation() {
    for l in 0..2 {
        let (d1, _) = tip_deflection_and_rotation(l, [1, 1], 1.0);
        for s in [2, 3] {
            let mut segs = [1, 1];
            segs[l] = s;
            let (d_eq, th_eq) = tip_deflection_and_rotation(l, segs, 1.0);
            for r in [0.5, 4.0, 10.0] {
                let (d, th) = tip_deflection_and_rotation(l, segs, r);
                // the transverse deflection (linear in the load); the axial shortening along the
                // link (x) is second order and depends on the bent shape
                let rel = ((d.y - d1.y).powi(2) + (d.z - d1.z).powi(2)).sqrt() / d1.norm();
                println!("link {} S = {s} root_ratio {r}: deflection {:.6e} m (one joint {:.6e}), rotation {:.6e} rad (equal springs {:.6e})", l + 1, d.norm(), d1.norm(), th.norm(), th_eq.norm());
                assert!(rel < 1e-4 && (d.x - d1.x).abs() < 1e-3 * d1.norm(), "link {} S = {s} root_ratio {r}: deflection {d:?} vs {d1:?}", l + 1);
                // a stiffer root leaves more of the bending to the outer joints: more tip rotation
                assert_eq!(th.norm() > th_eq.norm(), r > 1.0, "link {} S = {s} root_ratio {r}", l + 1);
            }
            // the 2-segment split 4:1 is a uniform cantilever's under a tip force: tip rotation
            // θ = F L²/2EI with deflection δ = F L³/3EI, θ/δ 1.5/1.2 = 1.25 × the equal split's
            if s == 2 {
                let (d4, th4) = tip_deflection_and_rotation(l, segs, 4.0);
                let ratio = (th4.norm() / d4.norm()) / (th_eq.norm() / d_eq.norm());
                println!("link {}: (θ/δ)(4:1) / (θ/δ)(equal) = {ratio:.5}", l + 1);
                assert!((ratio - 1.25).abs() < 1e-3, "link {}: {ratio}", l + 1);
            }
        }
        // one segment: root_ratio is neutral
        let (d, _) = tip_deflection_and_rotation(l, [1, 1], 4.0);
        assert_eq!(d, d1);
    }
}

#[test]
fn segment_stiffness_formula() {
    let spec = ArmSpec::popup_lab();
    for (s, f) in [(1, 1.0), (2, 1.25), (3, 1.0 + 4.0 / 9.0 + 1.0 / 9.0)] {
        let m = compile(&spec, Structure { segments: [s, s], torsion: [false; 2], elements: [0, 0] });
        assert!((m.seg_factor[0] - f).abs() < 1e-15 && (m.seg_factor[1] - f).abs() < 1e-15);
        let nominal = compile(&spec, Structure::default());
        let (pd, pd0) = (ParamData::new(&m, &params(&m, 1.0)).unwrap(), ParamData::new(&nominal, &params(&nominal, 1.0)).unwrap());
        for l in 0..2 {
            for a in 0..2 {
                for &j in m.channel_joints(2 * l + a) {
                    let j0 = nominal.root_bend_idx[2 * l + a];
                    assert!((pd.k[j] - pd0.k[j0] * f).abs() < 1e-9 * pd0.k[j0], "k of {}", m.joint_name(j));
                    assert!((pd.c[j] - pd0.c[j0] * f).abs() < 1e-9 * pd0.c[j0], "c of {}", m.joint_name(j));
                }
            }
        }
    }
}

#[test]
fn first_mode_kept_and_higher_modes_appear() {
    let spec = ArmSpec::popup_lab();
    let nominal = compile(&spec, Structure::default());
    for (payload, qm) in [(2.0, [0.0, 0.0, 0.0]), (0.0, [0.0, 0.0, 0.0]), (2.0, [0.0, 0.6, -0.3])] {
        let pd0 = ParamData::new(&nominal, &params(&nominal, payload)).unwrap();
        let modes0 = locked_modes(&nominal, &pd0, &rest_state(&nominal, &pd0, 0.0, qm).unwrap().q);
        assert_eq!(modes0.len(), 4);
        for s in [[2, 2], [3, 3], [2, 1], [1, 3]] {
            let m = compile(&spec, Structure { segments: s, torsion: [false; 2], elements: [0, 0] });
            let pd = ParamData::new(&m, &params(&m, payload)).unwrap();
            let modes = locked_modes(&m, &pd, &rest_state(&m, &pd, 0.0, qm).unwrap().q);
            println!("payload {payload} motors {qm:?} segments {s:?}: modes {modes:.1?} (one segment {modes0:.1?}) rad/s");
            assert_eq!(modes.len(), 2 * (s[0] + s[1]), "one mode per bending joint");
            assert!(modes.iter().all(|&w| w > 0.0));
            let rel = (modes[0] - modes0[0]).abs() / modes0[0];
            assert!(rel < 0.15, "segments {s:?}: first mode {} vs {} (rel {rel:.3})", modes[0], modes0[0]);
            // the two planes' first modes (lateral, vertical) both stay
            assert!((modes[1] - modes0[1]).abs() / modes0[1] < 0.15);
            // the added modes lie above the one-segment model's first modes
            assert!(modes[4..].iter().all(|&w| w > 1.5 * modes0[1]), "higher modes {modes:?}");
        }
    }
}

#[test]
fn channels_sum_segments_root_moments_and_energy() {
    let spec = ArmSpec::popup_lab();
    let m = compile(&spec, Structure { segments: [2, 3], torsion: [true, false], elements: [0, 0] });
    let pd = ParamData::new(&m, &params(&m, 1.5)).unwrap();
    // a fast out-of-plane replay so that every joint moves
    let tk: Vec<f64> = (0..=24).map(|k| k as f64 * 0.0125).collect();
    let yk: Vec<[f64; 3]> = tk.iter().map(|&t| [0.5 * (2.0 * PI * 1.3 * t).sin(), 0.3 + 0.3 * (2.0 * PI * 0.9 * t).sin(), -0.9]).collect();
    let cfg = RunConfig { drive: Drive::Replay(Spline3::new(&tk, &yk).unwrap()), initial: None, duration: None, sample_period: 0.3, check_step: true };
    let tr = run(&m, &pd, &cfg).unwrap();
    let row = &tr.data[(tr.nsample - 1) * NCH..tr.nsample * NCH];
    let st = tr.final_state;
    let ch = |n: &str| row[channel_index(n).unwrap()];
    for (a, name) in ["d11", "d12", "d21", "d22"].iter().enumerate() {
        let js = m.channel_joints(a);
        let sum_q: f64 = js.iter().map(|&j| st.q[j]).sum();
        let sum_v: f64 = js.iter().map(|&j| st.v[j]).sum();
        assert!((ch(name) - sum_q).abs() < 1e-15, "{name}");
        assert!((ch(&format!("d{name}")) - sum_v).abs() < 1e-13, "d{name}");
        assert!(js.iter().all(|&j| st.q[j].abs() > 1e-6), "every segment of {name} moves");
        let r = m.root_bend_idx[a];
        assert_eq!(r, js[0]);
        let mom = pd.k[r] * st.q[r] + pd.c[r] * st.v[r];
        assert!((ch(&format!("m{}", &name[1..])) - mom).abs() < 1e-12 * mom.abs().max(1.0), "m{}", &name[1..]);
    }
    let ratio1 = (ch("m11").hypot(ch("m12"))) / pd.mw[0];
    assert!((ch("m1_ratio") - ratio1).abs() < 1e-12);
    // energy: spring of every passive joint, torsion included
    let spring: f64 = m.passive().iter().map(|&j| 0.5 * pd.k[j] * st.q[j] * st.q[j]).sum();
    let e_all = energy(&m, &pd, 0.0, &st.q, &st.v);
    let off = Model::compile(&spec, Options { structure: m.options.structure, disable: popup_core::model::Disable { spring: true, ..Default::default() }, ..Options::default() }).unwrap();
    let e_nospring = energy(&off, &ParamData::new(&off, &pd.params).unwrap(), 0.0, &st.q, &st.v);
    assert!((ch("energy") - e_all).abs() < 1e-12 * e_all.abs());
    assert!((e_all - e_nospring - spring).abs() < 1e-10 * e_all.abs(), "energy {e_all} vs {e_nospring} + springs {spring}");
    assert!(st.q[m.torsion_idx[0].unwrap()].abs() > 1e-6, "the out-of-plane move twists link 1");
}

#[test]
fn bad_structure_is_refused_by_name() {
    let spec = ArmSpec::popup_lab();
    for (s, what) in [([4, 1], "options.structure.segments[0] (link 1)"), ([1, 4], "options.structure.segments[1] (link 2)")] {
        match Model::compile(&spec, Options { structure: Structure { segments: s, torsion: [false; 2], elements: [0, 0] }, ..Options::default() }) {
            Err(Error::InvalidParameter { what: w, .. }) => assert_eq!(w, what),
            other => panic!("{s:?}: {other:?}"),
        }
    }
    // a universal joint that is not (d = 0, a = 0) + (d = 0, a = L) cannot be split
    let mut odd = spec.clone();
    odd.joints[2].a = 0.01;
    match Model::compile(&odd, Options { structure: Structure { segments: [2, 1], torsion: [false; 2], elements: [0, 0] }, ..Options::default() }) {
        Err(Error::InvalidParameter { what, requirement, .. }) => {
            assert_eq!(what, "joints[2].a");
            assert!(requirement.contains("link 1"), "{requirement}");
        }
        other => panic!("{other:?}"),
    }
    // ... while the one-segment model of the same arm file compiles as before
    assert!(Model::compile(&odd, Options::default()).is_ok());
    let mut p = Params::defaults(&compile(&spec, Structure::default()));
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        p.effects.higher_bending_modes.k_scale = [1.0, bad];
        match ParamData::new(&compile(&spec, Structure { segments: [2, 2], torsion: [false; 2], elements: [0, 0] }), &p) {
            Err(Error::InvalidParameter { what, .. }) => assert_eq!(what, "effects.higher_bending_modes.k_scale[1]"),
            other => panic!("seg_k_scale {bad}: {other:?}"),
        }
    }
}

#[test]
fn expanded_chain_conserves_energy_without_dampers() {
    // segments and torsion joints, dampers off, motors free (zero torque): the arm falls
    // and swings; the energy channel (kinetic + gravity + every spring) must stay constant
    // up to the RK4 error, which falls ~h⁴ (checked at two steps)
    let spec = ArmSpec::popup_lab();
    let structure = Structure { segments: [2, 3], torsion: [true, true], elements: [0, 0] };
    let drift = |dt: f64| {
        let m = Model::compile(&spec, Options { dt, structure, disable: popup_core::model::Disable { damper: true, ..Default::default() }, ..Options::default() }).unwrap();
        let pd = ParamData::new(&m, &params(&m, 1.0)).unwrap();
        let mut st = rest_state(&m, &pd, 0.0, [0.0, 0.3, -0.5]).unwrap();
        st.v[m.motor_idx[0]] = 1.0; // out-of-plane motion too
        let cfg = RunConfig { drive: popup_core::drive::Drive::Torque(popup_core::drive::Linear3::new(&[0.0], &[[0.0; 3]]).unwrap()), initial: Some(st), duration: Some(0.4), sample_period: 0.01, check_step: true };
        let tr = run(&m, &pd, &cfg).unwrap();
        let e: Vec<f64> = (0..tr.nsample).map(|r| tr.data[r * NCH + channel_index("energy").unwrap()]).collect();
        let q2: Vec<f64> = (0..tr.nsample).map(|r| tr.data[r * NCH + channel_index("q2").unwrap()]).collect();
        let swing = q2.iter().fold(0.0f64, |s, x| s.max((x - q2[0]).abs()));
        let d = e.iter().fold(0.0f64, |s, x| s.max((x - e[0]).abs()));
        (d, swing, e[0])
    };
    let (d1, swing, e0) = drift(2e-4);
    let (d2, _, _) = drift(1e-4);
    println!("energy drift {d1:.3e} J (dt 2e-4), {d2:.3e} J (dt 1e-4), of {e0:.3} J; shoulder swing {swing:.3} rad");
    assert!(swing > 0.3, "the arm must move ({swing} rad)");
    assert!(d1 < 1e-5 * e0.abs().max(1.0), "energy drift {d1:e} J");
    assert!(d1 / d2 > 8.0, "energy error must fall at high order: {d1:e} → {d2:e}");
}

#[test]
fn initial_state_beyond_the_chain_is_refused() {
    let m = compile(&ArmSpec::popup_lab(), Structure { segments: [2, 1], torsion: [false; 2], elements: [0, 0] });
    let pd = ParamData::new(&m, &params(&m, 1.0)).unwrap();
    let mut st = rest_state(&m, &pd, 0.0, [0.0; 3]).unwrap();
    st.q[m.nv] = 0.1;
    let cfg = RunConfig { drive: popup_core::drive::Drive::Torque(popup_core::drive::Linear3::new(&[0.0], &[[0.0; 3]]).unwrap()), initial: Some(st), duration: Some(0.01), sample_period: 0.01, check_step: true };
    match run(&m, &pd, &cfg) {
        Err(Error::Input { what, message }) => {
            assert_eq!(what, "initial state");
            assert!(message.contains(&format!("entry {}", m.nv)), "{message}");
        }
        other => panic!("{other:?}"),
    }
}

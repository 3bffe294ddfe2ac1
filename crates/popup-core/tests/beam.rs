//! Euler–Bernoulli cantilever checks against closed-form results: static tip deflection
//! and rotation, bending (βL = 1.8751, 4.6941, 7.8548), torsion and axial frequencies,
//! the tip-mass frequency equation, convergence order with element count, Rayleigh
//! damping. `cargo test --release --test beam -- --nocapture` prints the convergence table.

use popup_core::beam::{Cantilever, ModeKind, Rayleigh, Section};
use std::f64::consts::PI;

mod common;

/// The thesis's first fitted link: E = 0.557 GPa, t = 1.2 mm (popup-lab's radius).
fn tube() -> Section {
    Section::tube(0.557e9, 0.3, 1100.0, 0.05, 1.2e-3)
}

const L: f64 = 0.5;
const BETA_L: [f64; 3] = [1.875_104_068_7, 4.694_091_132_9, 7.854_757_438_2];

fn bending_exact(s: &Section, k: usize) -> f64 {
    BETA_L[k].powi(2) / (L * L) * (s.e * s.i() / s.mass_per_length()).sqrt()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn static_tip_load_matches_closed_form_exactly() {
    let s = tube();
    let c = Cantilever::new(s, L, 4, 0.0).unwrap();
    let p = 3.0;
    let ei = s.e * s.i();
    let u = c.static_tip([0.0, p, 0.0, 0.0, 0.0, 0.0]).unwrap();
    assert!(rel(u[1], p * L.powi(3) / (3.0 * ei)) < 1e-10, "{u:?}");
    assert!(rel(u[5], p * L * L / (2.0 * ei)) < 1e-10);
    let u = c.static_tip([0.0, 0.0, p, 0.0, 0.0, 0.0]).unwrap();
    assert!(rel(u[2], p * L.powi(3) / (3.0 * ei)) < 1e-10);
    assert!(rel(-u[4], p * L * L / (2.0 * ei)) < 1e-10, "θy = −dw/dx");
    let u = c.static_tip([p, 0.0, 0.0, 0.7, 0.0, 0.0]).unwrap();
    assert!(rel(u[0], p * L / (s.e * s.area())) < 1e-10);
    assert!(rel(u[3], 0.7 * L / (s.g() * s.j())) < 1e-10);
    // a tip moment bends to M L²/(2EI), rotates M L/EI
    let u = c.static_tip([0.0, 0.0, 0.0, 0.0, 0.0, 0.4]).unwrap();
    assert!(rel(u[1], 0.4 * L * L / (2.0 * ei)) < 1e-10 && rel(u[5], 0.4 * L / ei) < 1e-10);
}

#[test]
fn bending_torsion_axial_frequencies_match_closed_form() {
    let s = tube();
    let m = Cantilever::new(s, L, 24, 0.0).unwrap().modes().unwrap();
    for kind in [ModeKind::BendingY, ModeKind::BendingZ] {
        let w = m.of(kind, 3);
        for k in 0..3 {
            assert!(rel(w[k], bending_exact(&s, k)) < 1e-5, "{kind:?} mode {k}: {} vs {}", w[k], bending_exact(&s, k));
        }
    }
    let wt = m.of(ModeKind::Torsion, 2);
    let wa = m.of(ModeKind::Axial, 2);
    for k in 0..2 {
        let f = (2 * k + 1) as f64 * PI / (2.0 * L);
        assert!(rel(wt[k], f * (s.g() / s.rho).sqrt()) < 2e-3 * (k + 1) as f64, "torsion {k}");
        assert!(rel(wa[k], f * (s.e / s.rho).sqrt()) < 2e-3 * (k + 1) as f64, "axial {k}");
    }
}

/// Error of ω₁ (bending) falls as h⁴ (cubic Hermite, consistent mass); of ω₁ (axial,
/// linear elements) as h².
#[test]
fn convergence_orders() {
    let s = tube();
    let exact_a = PI / (2.0 * L) * (s.e / s.rho).sqrt();
    let mut prev: Option<(f64, f64)> = None;
    println!("n   err(bending w1)  order  err(bending w3)  err(axial w1)  order");
    for n in [2usize, 4, 8, 16] {
        let m = Cantilever::new(s, L, n, 0.0).unwrap().modes().unwrap();
        let eb = rel(m.of(ModeKind::BendingY, 1)[0], bending_exact(&s, 0));
        let eb3 = m.of(ModeKind::BendingY, 3).get(2).map_or(f64::NAN, |w| rel(*w, bending_exact(&s, 2)));
        let ea = rel(m.of(ModeKind::Axial, 1)[0], exact_a);
        let (ob, oa) = prev.map_or((f64::NAN, f64::NAN), |(pb, pa)| ((pb / eb).log2(), (pa / ea).log2()));
        println!("{n:<3} {eb:>15.3e}  {ob:>5.2}  {eb3:>15.3e}  {ea:>13.3e}  {oa:>5.2}");
        if n >= 4 {
            assert!((3.6..4.4).contains(&ob), "bending order {ob} at n = {n}");
            assert!((1.8..2.2).contains(&oa), "axial order {oa} at n = {n}");
        }
        prev = Some((eb, ea));
    }
}

/// 1 + cos βL cosh βL + (m/ρAL) βL (cos βL sinh βL − sin βL cosh βL) = 0.
#[test]
fn tip_mass_frequency_equation() {
    let s = tube();
    let ratio = 2.0;
    let mt = ratio * s.mass_per_length() * L;
    let bl = common::tip_mass_roots(ratio, 1)[0];
    let exact = bl * bl / (L * L) * (s.e * s.i() / s.mass_per_length()).sqrt();
    let w = Cantilever::new(s, L, 24, mt).unwrap().modes().unwrap().of(ModeKind::BendingY, 1)[0];
    assert!(rel(w, exact) < 1e-6, "{w} vs {exact} (βL = {bl})");
    // and the tip mass lowers it well below the bare beam's
    assert!(w < 0.6 * bending_exact(&s, 0));
}

#[test]
fn rayleigh_from_two_ratios() {
    let r = Rayleigh::from_ratios(10.0, 0.02, 100.0, 0.05).unwrap();
    assert!((r.ratio(10.0) - 0.02).abs() < 1e-12 && (r.ratio(100.0) - 0.05).abs() < 1e-12);
    // stiffness-proportional only: the thesis's λ = 3.896e-4 s gives ζ = λω/2
    let th = Rayleigh { mu: 0.0, lambda: 3.896e-4 };
    assert!((th.ratio(100.0) - 0.01948).abs() < 1e-12);
    // × 10⁴ s as printed would overdamp every mode
    assert!(Rayleigh { mu: 0.0, lambda: 3.896e4 }.ratio(1.0) > 1.0);
    let e = Rayleigh::from_ratios(10.0, 0.5, 100.0, 0.001).unwrap_err().to_string();
    assert!(e.contains("negative coefficient"), "{e}");
    assert!(Rayleigh::from_ratios(10.0, 0.02, 10.0, 0.05).is_err());
}

/// Timoshenko with Fichter's pressure term: the tip deflection under an end load is
/// P L³/(3EI) + P L/(κGA + p π r²), exact; pressure stiffens, shear softens.
#[test]
fn shear_and_pressure_tip_deflection() {
    let mut s = tube();
    s.shear = true;
    let ei = s.e * s.i();
    let p = 3.0;
    for pres in [0.0, 30e3, 90e3] {
        s.pressure_pa = pres;
        let u = Cantilever::new(s, L, 3, 0.0).unwrap().static_tip([0.0, p, 0.0, 0.0, 0.0, 0.0]).unwrap();
        let want = p * L.powi(3) / (3.0 * ei) + p * L / (0.5 * s.g() * s.area() + pres * PI * s.r * s.r);
        assert!(rel(u[1], want) < 1e-10, "p = {pres}: {} vs {want}", u[1]);
        assert!(rel(u[5], p * L * L / (2.0 * ei)) < 1e-10, "the end rotation has no shear part");
    }
    let eb = Cantilever::new(tube(), L, 3, 0.0).unwrap().static_tip([0.0, p, 0.0, 0.0, 0.0, 0.0]).unwrap()[1];
    let soft = Cantilever::new(Section { pressure_pa: 0.0, ..s }, L, 3, 0.0).unwrap().static_tip([0.0, p, 0.0, 0.0, 0.0, 0.0]).unwrap()[1];
    let stiff = Cantilever::new(Section { pressure_pa: 90e3, ..s }, L, 3, 0.0).unwrap().static_tip([0.0, p, 0.0, 0.0, 0.0, 0.0]).unwrap()[1];
    assert!(eb < stiff && stiff < soft);
    // shear lowers the bending frequencies
    let w_eb = Cantilever::new(tube(), L, 16, 0.0).unwrap().modes().unwrap().of(ModeKind::BendingY, 2);
    let w_t = Cantilever::new(Section { pressure_pa: 0.0, ..s }, L, 16, 0.0).unwrap().modes().unwrap().of(ModeKind::BendingY, 2);
    assert!(w_t[0] < w_eb[0] && w_t[1] < w_eb[1]);
    let mut bad = s;
    bad.pressure_pa = -1.0;
    assert!(bad.validate().unwrap_err().to_string().contains("beam.pressure_pa"));
}

/// Ratios asked on bending modes 0 and 1 land on them even though a torsion or axial
/// mode lies in between in the spectrum, and the user is told.
#[test]
fn rayleigh_on_named_modes_warns_about_the_spectrum_order() {
    let s = tube();
    let m = Cantilever::new(s, L, 12, 0.0).unwrap().modes().unwrap();
    let (r, warn) = Rayleigh::for_modes(&m, ModeKind::BendingZ, (0, 0.02), (1, 0.05)).unwrap();
    let w = m.of(ModeKind::BendingZ, 2);
    assert!((r.ratio(w[0]) - 0.02).abs() < 1e-12 && (r.ratio(w[1]) - 0.05).abs() < 1e-12);
    // bending in y and z are degenerate pairs: BendingZ mode 0 is not spectrum mode 0 or BendingZ mode 1 not 1
    assert!(!warn.is_empty() && warn[0].contains("wrong mode"), "{warn:?}");
    assert!(Rayleigh::for_modes(&m, ModeKind::Torsion, (0, 0.02), (40, 0.05)).is_err());
}

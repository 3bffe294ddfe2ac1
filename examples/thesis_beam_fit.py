#!/usr/bin/env python
"""The thesis's fitting experiment (its section 2.3) on ``popup-lab``: fit the Young's
modulus E and the stiffness-proportional damping λ of a beam link so that its tip
response matches the PRBM link's, and check the thesis's printed λ.

    MPLBACKEND=Agg python examples/thesis_beam_fit.py            # about 1 min on 2 cores
    MPLBACKEND=Agg python examples/thesis_beam_fit.py --quick    # shorter record, fewer seeds
    python examples/thesis_beam_fit.py --no-doc                  # do not touch docs/beam_vs_prbm.md

The experiment: 2 kg payload, gravity on, motors locked at q = (0, 0, 0) (arm horizontal),
the arm released from the undeflected state (every bending coordinate 0, at rest): the
tip sags under gravity and rings. Measured channel: the vertical tip displacement
``ee_z``. The "measurement" is the PRBM model (link 2 one universal joint, k(30 kPa) =
360 N·m/rad, c = 0.463 N·m·s/rad, RK4 at dt = 0.1 ms); the model fitted is the same arm
with link 2 an Euler–Bernoulli beam of 4 elements (link 1 stays PRBM in both), with the
wall thickness of each thesis preset held fixed (1.2 mm and 0.8 mm) and E, λ of link 2
free.

Fitting machinery: :func:`popup.fit_params`, the diagnosis's own least squares (bounded
trust-region-reflective least squares on the normalised free-run residual,
forward-difference Jacobians as batched rollouts over flat effect vectors) for any named
effect parameters: here ``higher_bending_modes.e_pa[1]`` and ``lambda_s[1]`` with bounds
narrowed to a physical range, a batched grid of seeds (one rollout; a ringing response is
not convex in the stiffness), and the undeflected initial state (the ``[initial]`` table
of a measured run only knows the four PRBM channel angles, not a beam link's node joints).
The PRBM run is written and read back as a measured run (``popup.io.from_sim`` /
``write_run`` / ``read_run``).

Motors locked by encoder replay, not by constant holding torques: with
``Model.simulate(holding_torque, initial_q=0)`` the motors are free inertias under a
constant torque and drift (q2 by 0.018 rad in 3 s, the pose is only neutrally stable),
which mixes a rigid-body motion into the tip signal; the replay holds them exactly.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
import tomllib
from typing import Any, Dict, List, Tuple

import numpy as np

import popup
from popup import effects as fx
from popup.io import from_sim, read_run, write_run

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DOC = os.path.join(ROOT, "docs", "beam_vs_prbm.md")
OUT = os.path.join(ROOT, "out")

HBM = fx.EFFECTS["higher_bending_modes"]
#: The thesis's fitted FEM-link values (section 2.3): name, E [Pa], wall t [m], λ as we read
#: it (× 10⁻⁴ s), λ as printed (× 10⁴ s).
THESIS = [
    ("thesis-1.2mm", 0.557e9, 1.2e-3, 3.896e-4, 3.896e4),
    ("thesis-0.8mm", 794.9e6, 0.8e-3, 3.4919e-4, 3.4919e4),
]
PAYLOAD = 2.0
N_EL = 4  # beam elements on link 2
FS = 500.0  # sample rate of the record [Hz]
DT_FIT = 5e-5  # semi-implicit step of the fitted model [s] (stable up to E ≈ 2 GPa with 4 elements)
E_BOUNDS = (2e7, 2e9)
LAMBDA_BOUNDS = (1e-6, 2e-2)


def _divisor_dt(limit: float, period: float) -> float:
    """The largest dt <= 0.9·limit that divides the sample period ``period``."""
    k = math.ceil(period / (0.9 * limit))
    return period / k


def overshoot_and_cycles(z: np.ndarray, zf: Any = None) -> Tuple[float, int, float]:
    """Of a step response z (from z[0] towards the final value ``zf``, default the mean of
    the last 5 % of the record): overshoot past the final value [% of the step], the number
    of crossings of the final value, and the damping ratio from the mean logarithmic
    decrement of its successive overshoots (NaN with fewer than two)."""
    from scipy.signal import find_peaks

    zf = float(np.mean(z[-max(len(z) // 20, 2) :])) if zf is None else float(zf)
    drop = float(z[0] - zf)
    e = (z - zf) / drop if drop != 0 else z * 0
    over = float(max(0.0, -np.min(e))) * 100.0
    s = np.sign(e[np.abs(e) > 0.01])
    crossings = int(np.sum(s[1:] != s[:-1]))
    mins, _ = find_peaks(-e, height=0.02)
    zeta = math.nan
    if len(mins) >= 2:
        d = math.log(abs(e[mins[0]]) / abs(e[mins[-1]])) / (len(mins) - 1)
        zeta = d / math.sqrt(4 * math.pi**2 + d * d)
    return over, crossings, zeta


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="2 s record, fewer seeds (no doc unless --doc)")
    ap.add_argument("--doc", action="store_true", help="write docs/beam_vs_prbm.md even with --quick")
    ap.add_argument("--no-doc", action="store_true", help="do not write docs/beam_vs_prbm.md")
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args(argv)
    write_doc = (not a.quick or a.doc) and not a.no_doc
    T = 2.0 if a.quick else 3.0
    t0 = time.perf_counter()

    def say(s: str = "") -> None:
        print(s, flush=True)

    # ------------------------------------------------------------- the PRBM "measurement"
    prbm = popup.Model("popup-lab", payload_kg=PAYLOAD, dt=1e-4)
    t = np.arange(0.0, T + 1e-9, 1.0 / FS)
    q_enc = np.zeros((len(t), 3))
    nv_p = len(prbm.joint_names)
    res_p = prbm.replay(t, q_enc, sample_rate=FS, initial_q=np.zeros(nv_p), initial_v=np.zeros(nv_p))
    z_p = res_p.channel("ee_z")
    k2 = float(prbm.stiffness[prbm.joint_names.index("d21")])
    c2 = float(prbm.damping[prbm.joint_names.index("d21")])
    arm = tomllib.loads(prbm.arm.to_toml())
    r2 = float(arm["links"][1]["radius_m"])
    L = float(next(j["a"] for j in arm["joints"] if j["name"] == "d22"))  # universal joint → tip: the d22 DH row's a
    w_p = prbm.locked_modes()
    say("=" * 96)
    say("The thesis's fitting experiment (section 2.3): beam link 2 fitted to the PRBM link 2")
    say("=" * 96)
    say(f"PRBM link 2: k = {k2:.1f} N·m/rad, c = {c2:.3f} N·m·s/rad at 30 kPa; r = {r2} m, L = {L} m; payload {PAYLOAD} kg")
    say(f"record: motors locked at 0 (encoder replay), released from q = 0 at rest; ee_z at {FS:.0f} Hz for {T} s")
    z_static = float(prbm.end_effector(prbm.rest_state().tolist())[2])
    over_p, hc_p, zeta_p = overshoot_and_cycles(z_p, z_static)
    say(f"PRBM response: static sag {1e3 * (z_p[0] - z_static):.1f} mm, overshoot {over_p:.0f} %, {hc_p} crossings of the final value, ζ(log dec) = {zeta_p:.4f}")
    say(f"PRBM locked modes [rad/s]: {np.array2string(w_p, precision=2)}")

    # ------------------------------------------------------------- the beam model and problem
    beam = popup.Model("popup-lab", payload_kg=PAYLOAD, dt=DT_FIT, integrator="semi_implicit").with_effect(
        "higher_bending_modes", elements=[0, N_EL]
    )
    nv_b = len(beam.joint_names)
    free = ["higher_bending_modes.e_pa[1]", "higher_bending_modes.lambda_s[1]"]

    with tempfile.TemporaryDirectory() as tmp:
        df = from_sim(res_p, description="PRBM reference of the thesis's beam-fit experiment")
        write_run(os.path.join(tmp, "prbm"), df.attrs["experiment"], df)
        run = read_run(os.path.join(tmp, "prbm"))

    def material(e: float, lam: float, wall: float) -> popup.Model:
        return beam.with_effect("higher_bending_modes", e_pa=[e, e], lambda_s=[lam, lam], wall_m=[wall, wall])

    def z_of(model: popup.Model) -> np.ndarray:
        return model.replay(t, q_enc, sample_rate=FS, initial_q=np.zeros(nv_b), initial_v=np.zeros(nv_b)).channel("ee_z")

    def nrmse(model: popup.Model) -> float:
        return float(np.sqrt(np.mean((z_of(model) - z_p) ** 2)) / np.std(z_p))

    say("")
    say(f"fitted model: link 2 beam({N_EL}) (Euler–Bernoulli, no shear), semi-implicit dt = {DT_FIT:g} s; free: e_pa[1], lambda_s[1]")
    fits: List[Dict[str, Any]] = []
    ne, nl = (7, 2) if a.quick else (11, 3)
    for name, e_th, wall, lam_th, lam_printed in THESIS:
        e_match = k2 * L / (3.0 * math.pi * r2**3 * wall)
        tf = time.perf_counter()
        fit = popup.fit_params(
            material(e_th, lam_th, wall),
            run,
            free,
            bounds={free[0]: E_BOUNDS, free[1]: LAMBDA_BOUNDS},
            grid={free[0]: np.geomspace(3e7, 1.5e9, ne), free[1]: np.geomspace(2e-4, 2e-3, nl)},
            channels=["ee_z"],
            sample_rate=FS,
            initial_q=np.zeros(nv_b),
            initial_v=np.zeros(nv_b),
            threads=a.threads,
            max_iter=40,
        )
        e_fit, lam_fit = (float(v) for v in fit.x)
        e0, lam0 = (float(v) for v in fit.x0)
        fits.append(
            dict(name=name, wall=wall, e_th=e_th, lam_th=lam_th, lam_printed=lam_printed, e_match=e_match, e0=e0, lam0=lam0,
                 e=e_fit, lam=lam_fit, err=fit.error, err_th=nrmse(material(e_th, lam_th, wall)), err_match=nrmse(material(e_match, c2 / k2, wall)),
                 nfev=fit.nfev, secs=fit.seconds, model=fit.model, ci=fit.ci95)
        )
        say(f"  t = {wall * 1e3:.1f} mm: seed E = {e0 / 1e6:.0f} MPa, λ = {lam0:.2e} s (grid {ne * nl} runs); "
            f"fit: E = {e_fit / 1e6:.2f} ± {fit.ci95[0] / 1e6:.2f} MPa, λ = {lam_fit:.4e} ± {fit.ci95[1]:.1e} s, NRMSE {fit.error:.4f} "
            f"({fit.nfev} rollouts, {time.perf_counter() - tf:.1f} s)")

    # ------------------------------------------------------------- check with RK4
    say("")
    say("check: the fitted beams rerun with RK4 at the largest stable dt the step check names (÷ 0.9, dividing 2 ms)")
    checks = []
    for f in fits:
        m = popup.Model("popup-lab", payload_kg=PAYLOAD, dt=1e-4).with_effect(
            "higher_bending_modes", elements=[0, N_EL], e_pa=[f["e"], f["e"]], lambda_s=[f["lam"], f["lam"]], wall_m=[f["wall"], f["wall"]]
        )
        lim = m.stable_dt(np.zeros(nv_b), replay=True)
        dt = _divisor_dt(lim, 1.0 / FS) if lim < 1e-4 else 1e-4
        m = popup.Model("popup-lab", payload_kg=PAYLOAD, dt=dt).with_effects({"higher_bending_modes": f["model"].effects["higher_bending_modes"]})
        rz = m.replay(t, q_enc, sample_rate=FS, initial_q=np.zeros(nv_b), initial_v=np.zeros(nv_b)).channel("ee_z")
        zs = z_of(f["model"])
        e_rk4 = float(np.sqrt(np.mean((rz - z_p) ** 2)) / np.std(z_p))
        wb = m.locked_modes()
        f.update(dt_rk4=dt, err_rk4=e_rk4, semi_vs_rk4=float(np.max(np.abs(zs - rz))), modes=wb, z=rz)
        checks.append(f)
        say(f"  t = {f['wall'] * 1e3:.1f} mm: RK4 dt = {dt:.3g} s: NRMSE vs PRBM {e_rk4:.4f}; max |semi-implicit − RK4| = {f['semi_vs_rk4'] * 1e3:.3f} mm; "
            f"locked modes {np.array2string(wb[:6], precision=1)} rad/s")

    # ------------------------------------------------------------- the printed λ
    say("")
    say("damping ratio of the beam's modes, ζ = λω/2 (stiffness-proportional Rayleigh damping)")
    rows_zeta = []
    for name, e_th, wall, lam_th, lam_printed in THESIS:
        mth = beam.with_effect("higher_bending_modes", e_pa=[e_th, e_th], wall_m=[wall, wall])
        wth = mth.locked_modes()
        # the first mode that is mostly link 2 bending: the first pair beyond the PRBM's count
        w2nd = float(wth[len(w_p)])
        for lam, label in ((lam_th, "(× 10⁻⁴, read)"), (lam_printed, "(× 10⁴, printed)")):
            z1 = lam * wth[0] / 2
            z2 = lam * w2nd / 2
            nover = int(np.sum(lam * wth / 2 > 1.0))
            rows_zeta.append((name, lam, label, wth[0], z1, w2nd, z2, nover, len(wth)))
            say(f"  {name}: λ = {lam:.4g} s {label}: ω1 = {wth[0]:.1f} rad/s → ζ1 = {z1:.3g}; link-2 2nd bending ω = {w2nd:.0f} rad/s → ζ = {z2:.3g}; "
                f"overdamped modes (ζ > 1): {nover} of {len(wth)}")
    w1 = float(rows_zeta[0][3])  # ω1 of the thesis-1.2mm beam
    checks_th = [float(rows_zeta[0][3]), float(rows_zeta[2][3])]
    say(f"  with × 10⁴ s every mode above 2/λ = {2 / 3.896e4:.1e} rad/s is overdamped, i.e. all of them (ζ1 ≈ 3e5).")
    try:
        beam.with_effect("higher_bending_modes", lambda_s=[3.896e4, 3.896e4])
        refused = "accepted (!)"
    except popup.ParameterError as e:
        refused = str(e)
    say(f"  λ = 3.896e4 s in the model: {refused}")
    # simulate: the read value, and the largest λ the registry allows (1 s, ζ1 ≈ 7). Link 2's
    # own bending (d22, the beam's tip rotation) shows it: the tip position also carries link
    # 1's PRBM ringing, which link 2's damping does not touch.
    lam_max = float(HBM.params["lambda_s"].upper)
    fl = np.array([material(0.557e9, lam, 1.2e-3).effects_flat for lam in (3.896e-4, lam_max)])
    rb = beam.rollout(encoder_t=t, encoder_q=q_enc, initial_q=np.zeros(nv_b), initial_v=np.zeros(nv_b), sample_rate=FS, effects=fl, threads=a.threads)
    m_th = beam.with_effect("higher_bending_modes", e_pa=[0.557e9, 0.557e9], wall_m=[1.2e-3, 1.2e-3])
    d22_static = float(m_th.replay(t[:2], q_enc[:2], sample_rate=FS, initial_q=m_th.rest_state()).channel("d22")[0])
    d22 = rb.channel("d22")
    sims_l = []
    for lam, d in zip((3.896e-4, lam_max), d22):
        over, hc, ze = overshoot_and_cycles(d, d22_static)
        sims_l.append((lam, over, hc, ze, lam * w1 / 2, float(d[-1] / d22_static)))
        say(f"  simulated thesis-1.2mm with λ = {lam:g} s: link-2 tip rotation d22 overshoots its static value by {over:.0f} %, "
            f"{hc} crossings of it, ζ(log dec) = {ze:.4f}; at t = {T:g} s it has reached {100 * d[-1] / d22_static:.0f} % of it")
    z_th = rb.channel("ee_z")[0]

    # ------------------------------------------------------------- plot
    os.makedirs(OUT, exist_ok=True)
    png = os.path.join(OUT, "thesis_beam_fit.png")
    try:
        import matplotlib

        matplotlib.use(os.environ.get("MPLBACKEND", "Agg"))
        import matplotlib.pyplot as plt

        fig, axs = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
        axs[0].plot(t, 1e3 * z_p, "k", lw=2, label="PRBM link 2 (reference)")
        for f, st in zip(fits, ("C0", "C1")):
            axs[0].plot(t, 1e3 * f["z"], st, lw=1, label=f"beam({N_EL}) fitted, t = {f['wall'] * 1e3:.1f} mm: E = {f['e'] / 1e6:.0f} MPa, λ = {f['lam']:.2e} s")
        axs[0].plot(t, 1e3 * z_th, "C2--", lw=1, label="beam, thesis 0.557 GPa / 1.2 mm / 3.896e-4 s")
        axs[0].set_ylabel("ee_z [mm]")
        axs[0].legend(fontsize=8)
        axs[0].set_title("tip released from the undeflected state, 2 kg, motors locked")
        axs[1].plot(t, 1e3 * d22[0], "C2", label="λ = 3.896e-4 s (× 10⁻⁴, read)")
        axs[1].plot(t, 1e3 * d22[1], "C3", label=f"λ = {lam_max:g} s (largest allowed; the printed 3.896e4 s is ~4e4 × more)")
        axs[1].axhline(1e3 * d22_static, color="0.5", lw=0.8, ls=":", label="static")
        axs[1].set_xlabel("t [s]")
        axs[1].set_ylabel("link-2 tip rotation d22 [mrad]")
        axs[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(png, dpi=110)
        say(f"\nplot: {os.path.relpath(png, ROOT)}")
    except ImportError:  # pragma: no cover
        say("\n(matplotlib missing: no plot)")

    wall_s = time.perf_counter() - t0
    say(f"total {wall_s:.0f} s")

    # ------------------------------------------------------------- doc section
    if write_doc:
        md: List[str] = []
        md.append("## The thesis's fitting experiment (section 2.3)\n")
        md.append(
            f"Generated by `python examples/thesis_beam_fit.py` ({time.strftime('%Y-%m-%d')}, {wall_s:.0f} s on "
            f"{os.cpu_count()} cores; plot `out/thesis_beam_fit.png`).\n"
        )
        md.append(
            f"**Experiment.** `popup-lab`, {PAYLOAD:g} kg payload, gravity, 30 kPa, motors locked at q = (0, 0, 0) "
            f"(encoder replay), released from the undeflected state at rest; the vertical tip displacement `ee_z` at "
            f"{FS:.0f} Hz for {T:g} s. Reference: the PRBM (link 2 one universal joint, k = {k2:.0f} N·m/rad, "
            f"c = {c2:.3f} N·m·s/rad; RK4, dt = 0.1 ms). Fitted: the same arm with link 2 a beam of {N_EL} "
            f"Euler–Bernoulli elements (link 1 PRBM in both), wall thickness held at each thesis preset's, E and λ "
            f"of link 2 free, bounded least squares on the normalised residual with `popup.fit_params` (the "
            f"diagnosis's machinery; seeded by a {ne} × {nl} grid in one batched rollout; semi-implicit, dt = {DT_FIT:g} s; "
            f"the results rerun with RK4 below).\n"
        )
        md.append("| wall t | fitted E | fitted λ | NRMSE fit | NRMSE (RK4 rerun) | E matched to k (k L/3 = EI) | thesis E | thesis λ | NRMSE of thesis values |")
        md.append("|---|---|---|---|---|---|---|---|---|")
        for f in fits:
            md.append(
                f"| {f['wall'] * 1e3:.1f} mm | **{f['e'] / 1e6:.1f} MPa** | **{f['lam']:.3e} s** | {f['err']:.4f} | {f['err_rk4']:.4f} | "
                f"{f['e_match'] / 1e6:.1f} MPa | {f['e_th'] / 1e6:.1f} MPa | {f['lam_th']:.4e} s | {f['err_th']:.3f} |"
            )
        f0_, f1_ = fits
        md.append("")
        md.append(
            f"- The fit lands on E·t = {f0_['e'] * f0_['wall']:.4g} and {f1_['e'] * f1_['wall']:.4g} N/m "
            f"(EI = {f0_['e'] * math.pi * r2**3 * f0_['wall']:.1f} N·m²), i.e. {f0_['e'] / f0_['e_match']:.3f} × the E matched "
            f"statically to k(30 kPa) (EI = kL/3 = {k2 * L / 3:.1f} N·m²): the PRBM's tip response is reproduced by "
            f"the beam whose tip deflection under a tip force equals the PRBM's. λ comes out "
            f"{f0_['lam']:.3e} s ≈ c/k = {c2 / k2:.3e} s ({f0_['lam'] / (c2 / k2):.2f} ×): stiffness-proportional damping "
            f"of the same EI puts the PRBM's damping ratio on the first mode."
        )
        md.append(
            f"- The thesis's values are {f0_['e_th'] / f0_['e']:.1f} × (1.2 mm) and {f1_['e_th'] / f1_['e']:.1f} × (0.8 mm) "
            f"stiffer than this fit (their E·t agree with each other: {f0_['e_th'] * f0_['wall']:.4g} vs "
            f"{f1_['e_th'] * f1_['wall']:.4g} N/m, EI ≈ {f0_['e_th'] * math.pi * r2**3 * f0_['wall']:.0f} N·m² at r = {r2} m), "
            f"so the thesis's E does not follow from popup-lab's k(30 kPa) = {k2:.0f} N·m/rad with I = π r³ t, r = {r2} m and "
            f"L = {L} m (its PRBM, its radius or its length convention must differ by that factor; the thesis does not give "
            f"enough to tell which). Against popup-lab's PRBM the thesis values give an error of {f0_['err_th']:.2f} / "
            f"{f1_['err_th']:.2f} NRMSE (first mode {checks_th[0]:.1f} rad/s instead of {w_p[0]:.1f}) against {f0_['err']:.4f} "
            f"for the fit. The presets stay as published (`popup_core::beam::PRESETS`); the E that matches popup-lab's "
            f"PRBM is the fitted one."
        )
        md.append(
            f"- The RK4 rerun (dt = {f0_['dt_rk4']:.3g} / {f1_['dt_rk4']:.3g} s, from the step check) differs from the "
            f"semi-implicit fit by at most {f0_['semi_vs_rk4'] * 1e3:.3f} / {f1_['semi_vs_rk4'] * 1e3:.3f} mm. The remaining "
            f"error is the model difference itself: the beam's tip also rotates (1.5 × the PRBM's rotation for the same "
            f"deflection) and its mass is distributed, so the 2nd arm mode differs by a few per cent."
        )
        md.append("")
        md.append("**The printed λ.** ζ = λω/2 for each mode of the thesis presets (beam link 2, link 1 PRBM, 2 kg):\n")
        md.append("| preset | λ | ω1 [rad/s] | ζ1 | link-2 2nd bending ω [rad/s] | ζ | overdamped modes |")
        md.append("|---|---|---|---|---|---|---|")
        for name, lam, label, ww1, z1, w2n, z2, nover, ntot in rows_zeta:
            md.append(f"| {name} | {lam:.4e} s {label} | {ww1:.1f} | {z1:.3g} | {w2n:.0f} | {z2:.3g} | {nover} of {ntot} |")
        md.append("")
        (l1, o1, h1, ze1, zz1, fr1), (l2, o2, h2, ze2, zz2, fr2) = sims_l
        md.append(
            f"With the printed × 10⁴ s every mode is overdamped (ζ1 ≈ 3 × 10⁵; any mode above 2/λ = 5 × 10⁻⁵ rad/s): "
            f"the slow root of each overdamped mode is s ≈ −k/c = −1/λ, so the tip would creep to its sag with a "
            f"time constant of λ ≈ {3.896e4 / 3600:.0f} h and no oscillation, which contradicts the thesis's ringing responses. The engine refuses it (`lambda_s` ≤ {lam_max:g} s): `{refused}`. Simulated (thesis-1.2mm material, "
            f"same experiment, link 2's own bending d22 = its tip rotation): λ = {l1:g} s rings — overshoot {o1:.0f} % of the "
            f"static rotation, {h1} crossings of it in {T:g} s, ζ from the log decrement {ze1:.4f} (the arm's first mode, link 1's PRBM damping included) — while already "
            f"λ = {l2:g} s (the largest allowed, ζ1 ≈ {zz2:.1f} with ω1 = {w1:.1f} rad/s) gives overshoot {o2:.0f} %, {h2} "
            f"crossings, {100 * fr2:.0f} % of the static rotation reached after {T:g} s: a creep. × 10⁻⁴ s is therefore the reading that reproduces an "
            f"underdamped response; it is the value of the presets. Even with it the top finite-element modes "
            f"(ω > 2/λ ≈ {2 / 3.896e-4:.0f} rad/s) are overdamped, which is what makes explicit RK4 need small steps."
        )
        popup.report.write_section(DOC, "thesis_beam_fit", "\n".join(md) + "\n")
        say(f"wrote section 'thesis_beam_fit' of {os.path.relpath(DOC, ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

#!/usr/bin/env python3
"""Write ``docs/thesis.md``: the thesis's numbers, ours, the ratio, and the fitted number
that explains each gap; plots under ``docs/img/``; the fitted arm file
``crates/popup-core/arms/popup-lab-thesis.toml`` (compiled into the core: when the fit
changes it, the script stops and asks for a rebuild, so that nothing below runs on the old
arm).

Parts: the motoreducer fitted to Tables 8–9 and its reflected inertia to the rigid column
of Tables 5–7 (``examples/thesis_drive.py``); the link's FRF of Tables 10–15 and the link
fitted to it (``examples/thesis_link.py``), checked on the engine; the FEM column and the
section-2.3 material against it.

Usage::

    MPLBACKEND=Agg python examples/thesis_report.py          # ≈ 3–5 min on 2 shared cores
    MPLBACKEND=Agg python examples/thesis_report.py --no-arm # keep the arm file as it is
"""

from __future__ import annotations

import argparse
import math
import pickle
import sys
import time
from pathlib import Path
from typing import Any, Dict, List, Sequence, Tuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import thesis_data as td  # noqa: E402
import thesis_drive as tdr  # noqa: E402
import thesis_fem as tf  # noqa: E402
import thesis_link as tl  # noqa: E402

import popup  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "thesis.md"
IMG = ROOT / "docs" / "img"
ARM = ROOT / "crates" / "popup-core" / "arms" / "popup-lab-thesis.toml"
LAB = {"j_m": 0.8, "c_u": 0.1014, "tau_max": 66.83, "omega_i": 6283.0}
"""popup-lab's motoreducer (docs/control.md)."""


def f3(x: float) -> str:
    """Three significant digits, '—' for nan/inf."""
    if x is None or not np.isfinite(x):
        return "—" if x is None or np.isnan(x) else "> grid"
    return f"{x:.3g}"


# ----------------------------------------------------------------------------- arm file
def write_arm(drive: tdr.Drive, link: tl.Link) -> str:
    """The packaged arm file of the fitted thesis arm (every number that differs from
    popup-lab, with its reason)."""
    k_scale = link.k / tl.K_T3
    d_scale = link.c / (k_scale * tl.C_T3)
    m_tube = tl.TUBE_M * link.s_m
    text = f"""# popup-lab-thesis: popup-lab with the numbers the thesis's Simscape model must have had
# to give its Tables 5-15 (docs/thesis.md; written by examples/thesis_report.py).
# Differences from popup-lab (reference-arm.md):
#   motors.armature_kgm2   {drive.j_m:.4g} kg*m^2 per motor (popup-lab 0.8; spec 0.05): the rigid
#                          column of Tables 5-7 against the motoreducer alone (Tables 8-9)
#   links[1] (link 2)      k = {link.k:.4g} N*m/rad at 30 kPa (stiffness_scale {k_scale:.4g} x Table 3's
#                          360), c = {link.c:.4g} N*m*s/rad (damping_scale {d_scale:.4g} on top):
#                          Tables 10-15's resonances 7.85 / 11 / 54.5 rad/s and 2 kg peak
#   link 2 outer piece     {m_tube:.4g} kg (popup-lab 0.38 kg; same 0.57 m tube), so its inertia
#                          about the bending joint is {link.inertia(0.0)[0]:.4g} kg*m^2 (popup-lab 0.0417)
#   motors.tau_max_nm      {drive.tau_max:.4g} N*m per drive (popup-lab 66.83): the fitted motoreducer's limit
# Link 1 and everything else as popup-lab. The controller's motoreducer fitted to Tables 8-9
# (not part of the arm description; popup.arm_motor("popup-lab-thesis") reads these lines):
# motor.torque_per_unit = {drive.c_u:.5g}
# motor.tau_max = {drive.tau_max:.5g}
# motor.current_bandwidth = {drive.omega_i:.5g}
base = "popup-lab"
name = "popup-lab-thesis"
links = [{{}}, {{ stiffness_scale = {k_scale:.5g}, damping_scale = {d_scale:.5g} }}]
bodies = [{{}}, {{}}, {{}}, {{}}, {{}}, {{}}, {{ parts = [{{ mass_kg = {m_tube:.5g} }}] }}]

[motors]
armature_kgm2 = [{drive.j_m:.5g}, {drive.j_m:.5g}, {drive.j_m:.5g}]
tau_max_nm = [{drive.tau_max:.5g}, {drive.tau_max:.5g}, {drive.tau_max:.5g}]
"""
    ARM.write_text(text)
    return text


# ----------------------------------------------------------------------------- plots
def plot_link(link: tl.Link, lab_rows: Dict, fit_rows: Dict, beam_H: np.ndarray, path: Path) -> None:
    """|H| of the link FRF, popup-lab and the fitted link (engine), with the thesis's
    resonance/peak and cut-off points."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(10, 3.2), sharey=True)
    lab = tl.engine_frf(popup.Model("popup-lab", gravity=False).with_links("rigid", "prbm"))
    fit = tl.engine_frf(popup.Model("popup-lab-thesis", gravity=False).with_links("rigid", "prbm"))
    for i, (ax, m, tab) in enumerate(zip(axs, (2.0, 1.0, 0.0), (13, 14, 15))):
        ax.semilogx(tl.W, 20 * np.log10(np.abs(lab[i])), color="0.6", lw=1, label="popup-lab PRBM")
        ax.semilogx(tl.W, 20 * np.log10(np.abs(fit[i])), color="C0", lw=1.2, label="popup-lab-thesis PRBM")
        ax.semilogx(tl.W, 20 * np.log10(np.abs(beam_H[i])), color="C2", lw=0.8, ls="--", label="beam, E fitted")
        for t, mk, g in ((tab - 3, "o", "on"), (tab, "s", "off")):
            cut, pk, res = td.LINK_FRF[t]["prbm"]  # type: ignore[misc]
            ax.plot([res], [pk], mk, mfc="none", color="C3", label=f"thesis PRBM peak, gravity {g}" if i == 0 else None)
            ax.plot([cut], [-3], mk, color="C3", ms=4, label=f"thesis PRBM cut-off, gravity {g}" if i == 0 else None)
        ax.set_title(f"{m:g} kg (Tables {tab - 3}, {tab})")
        ax.set_xlim(1, 1000)
        ax.set_ylim(-30, 45)
        ax.grid(True, which="both", lw=0.3)
        ax.set_xlabel("ω [rad/s]")
    axs[0].set_ylabel("|tip rate / q̇3| [dB]")
    axs[0].legend(fontsize=6, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_5_7(e: Dict[Tuple[str, float, float], float], path: Path) -> None:
    """Cut-off vs sine amplitude, Tables 5–7: the thesis's rigid, FEM and PRBM columns and
    the engine's rigid, beam and PRBM links."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 3, figsize=(10, 3.2), sharey=True)
    amps = list(td.AMPLITUDES)
    style = {"rigid": ("C3", "rigid"), "fem": ("C2", "FEM / beam"), "prbm": ("C0", "PRBM")}
    for ax, p, tab in zip(axs, (2.0, 1.0, 0.0), (5, 6, 7)):
        for k, (col, lab) in style.items():
            ax.loglog(amps, [td.TABLES_5_7[p][k][a] for a in amps], "o", mfc="none", color=col, label=f"thesis {lab}")
            ax.loglog(amps, [e[(k, p, a)] for a in amps], "s-" if k != "fem" else "^--", color=col, ms=4, lw=1, label=f"engine {lab}")
        ax.loglog(amps, [td.TABLE8[a] for a in amps], ":", color="0.5", lw=1, label="thesis Table 8 (motor alone)")
        ax.set_title(f"Table {tab}: {p:g} kg")
        ax.set_xlabel("amplitude A [rad/s]")
        ax.grid(True, which="both", lw=0.3)
    axs[0].set_ylabel("cut-off [rad/s]")
    axs[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_drive(r: tdr.DriveReport, path: Path) -> None:
    """Cut-off vs amplitude (Table 8) and vs Kp (Table 9): thesis and the fitted drive."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axs = plt.subplots(1, 2, figsize=(8, 3.2))
    cs, ours = r.motor.cases, r.motor.ours
    for ax, pre, key in ((axs[0], "T8", lambda c: c.amp), (axs[1], "T9", lambda c: c.kp)):
        sel = [i for i, c in enumerate(cs) if c.name.startswith(pre)]
        x = [key(cs[i]) for i in sel]
        ax.loglog(x, [cs[i].target for i in sel], "o", mfc="none", color="C3", label="thesis")
        ax.loglog(x, [ours[i] for i in sel], "s-", color="C0", ms=4, label="fitted drive")
        ax.grid(True, which="both", lw=0.3)
        ax.set_ylabel("cut-off [rad/s]")
    axs[0].set_xlabel("amplitude A [rad/s] (Kp 5000)")
    axs[1].set_xlabel("velocity Kp (A = 1 rad/s)")
    axs[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# ----------------------------------------------------------------------------- sections
def drive_section(r: tdr.DriveReport) -> List[str]:
    m, j = r.motor, r.jm
    d = j.drive
    L: List[str] = []
    L.append("## Motoreducer: Tables 5–9 (chapter 6.1)\n")
    L.append(
        "Experiment as the thesis defined it: velocity reference A sin ωt, output the feedback joint rate, velocity PI "
        "(Kp 5000, Ki 100 unless stated), cut-off = first −3 dB crossing of the first-harmonic gain. The drive is the "
        "project's cascade (docs/control.md), simulated per table entry by `examples/thesis_drive.py` (a numpy copy of "
        "the core's discrete law on a rigid load: seconds per fit). Fitted by `scipy.optimize.least_squares` on "
        "ln(ours/thesis), 95 % intervals from the Jacobian.\n"
    )
    L.append("**Stage 1, the motoreducer alone (Tables 8 and 9).** Only c_u/J_m and τ_max/J_m are visible without a link.\n")
    L.append("| parameter | fitted (95 % CI) | popup-lab |")
    L.append("|---|---|---|")
    lab_a, lab_b = LAB["c_u"] / LAB["j_m"], LAB["tau_max"] / LAB["j_m"]
    labels = {"a": ("a = c_u/J_m [rad/s² per unit]", lab_a), "b": ("b = τ_max/J_m [rad/s²]", lab_b), "omega_i": ("ω_i current loop [rad/s]", LAB["omega_i"])}
    for n, x, (lo, hi) in zip(m.names, m.x, m.ci):
        L.append(f"| {labels[n][0]} | **{x:.4g}** ({lo:.3g}–{hi:.3g}) | {labels[n][1]:.4g} |")
    L.append("")
    L.append("| entry | thesis [rad/s] | ours [rad/s] | ratio |")
    L.append("|---|---|---|---|")
    for name, th, o, rt in m.table():
        L.append(f"| {name} | {th:g} | {o:.3g} | {rt:.3f} |")
    rms = math.sqrt(np.mean(np.log([t[3] for t in m.table()]) ** 2))
    L.append("")
    L.append(
        f"RMS log residual {100 * rms:.1f} %. The linear loop gain per Kp, a = {m.drive.a:.3f}, is Table 9's small-Kp slope "
        f"(cut-off ≈ a·Kp: 5.6 and 56 rad/s at Kp 10 and 100). With it the Kp = 5000 loop would cross over at "
        f"a·Kp ≈ {m.drive.a * 5000:.0f} rad/s; the 707 rad/s of Table 8 at 0.1 rad/s needs a lag: the current loop at "
        f"ω_i = {m.drive.omega_i:.0f} rad/s (popup-lab's drive, 6283 rad/s with a = {lab_a:.3f}, gives Table 9's Kp = 100 "
        f"as {tdr.linear_cutoff(tdr.Drive(LAB['j_m'], LAB['c_u'], LAB['tau_max'], LAB['omega_i']), tdr.Case('', 0.0, 0.0, 100.0, 2.0, 1.0, 56.0)):.1f} rad/s instead of 56). The 1 and 3 rad/s cut-offs are the torque limit (first harmonic of a bang-bang "
        f"rate, ∝ b/A): b = {m.drive.b:.1f} rad/s². No velocity filter is needed (ω_v = ∞).\n"
    )
    k1, k10 = r.t9_fixed_ki
    L.append(
        f"**Conflict, Table 9's Ki.** Held at Ki = 100, Kp = 1 and 10 give a lightly damped PI loop (ω_n = √(a·Ki) = "
        f"{math.sqrt(m.drive.a * 100):.1f} rad/s) whose cut-off is {k1:.1f} and {k10:.1f} rad/s, not 0.49 and 5.6: the "
        "thesis's proportional trend needs Ki scaled with Kp. The fit uses Ki = Kp/50 (the tuning's 5000/100 ratio); "
        "Kp = 1 then gives a·Kp + the integral's zero, the residual in the table.\n"
    )
    L.append("**Stage 2, the reflected inertia (rigid column of Tables 5–7).** c_u/J_m, τ_max/J_m and ω_i from stage 1; "
             "the load adds link 2 (with the tube mass fitted to Tables 10–15 below) and the payload (0.6 m lever) and their "
             "gravity at q0 = 0°.\n")
    L.append("| entry | thesis [rad/s] | ours [rad/s] | ratio | J_m this entry alone needs [kg·m²] |")
    L.append("|---|---|---|---|---|")
    for (name, th, o, rt), je in zip(j.table(), r.jm_each):
        L.append(f"| {name} | {th:g} | {o:.3g} | {rt:.3f} | {f3(je)} |")
    (lo, hi), = j.ci
    L.append("")
    L.append(
        f"Fitted **J_m = {d.j_m:.3g} kg·m²** (95 %: {lo:.3g}–{hi:.3g}; popup-lab 0.8, reference-arm.md 0.05), hence "
        f"**c_u = {d.c_u:.4g} N·m/unit**, **τ_max = {d.tau_max:.4g} N·m**, ω_i = {d.omega_i:.0f} rad/s. "
        "Without gravity the rigid column gives " + ", ".join(f"{x:.3g}" for x in r.rigid_nograv) + " rad/s (the thesis: "
        "'almost the same').\n"
    )
    L.append(
        "**Conflict, the rigid column.** The entries disagree on J_m (last column): a rigid link's inertia grows with the "
        "payload (≈ 0.015 + m·0.36 kg·m² about the elbow), so the cut-off must fall from 0 to 1 kg as from 1 to 2 kg; the "
        "thesis's 0 kg and 1 kg columns are equal (25 / 75–77 / 580). No single motoreducer reproduces the 0 kg and "
        "the 2 kg rigid entries together; the fitted J_m is the compromise and each entry's residual is above.\n"
    )
    L.append(
        "**PRBM and FEM columns** (49–50 / 151–165 / 707–710 rad/s) equal the motoreducer alone (Table 8): above the "
        "link's first mode (7.85 rad/s with 2 kg, below every cut-off) the link decouples behind its bending joint and "
        "the motor sees J_m alone, so payload does not matter — the thesis's claim 'the load does not affect the "
        "motoreducer' holds for flexible links only. The engine reproduces this decoupling (docs/frequency.md, "
        "Tables 5–8: PRBM = motor alone within 1 %).\n"
    )
    return L


def link_section(fit: tl.LinkFit, lab: Dict, ours: Dict, rigid: Dict, beam_e: Tuple[float, Tuple[float, float]], beam_rows: Dict, thesis_beam_rows: Dict) -> List[str]:
    lk = fit.link
    jt, kl = tl.ratios_from_resonances()
    L: List[str] = ["## The link's FRF: Tables 10–15 (chapter 6.2)\n"]
    L.append(
        "Input q̇3, output the tip's angular rate about the link's bending axis (`dq3 + dd22` of the engine; for a beam "
        "link `dd22` is the tip rotation rate). The ratio is the link's response to its base rotation, independent of "
        "the motor loop: H = (k + c s − S a0 s²)/(J_b s² + c s + k) (`examples/thesis_link.py`), and the engine's "
        "linearised arm (`popup.frequency.linearize`, input `motor_angle`, link 1 rigid, q = (0, π/2, −π/2): link 2 "
        "horizontal, the thesis's q0 = 0°) agrees with it. A rigid link gives |H| = 1 at every frequency (max deviation "
        f"{max(abs(v[1]) for v in rigid.values()):.1e} dB): the thesis's check holds.\n"
    )
    L.append("| table | grav. | kg | thesis cut / peak / res | popup-lab | ratio (res) | popup-lab-thesis | ratio cut / res | peak Δ [dB] |")
    L.append("|---|---|---|---|---|---|---|---|---|")
    for t, e in td.LINK_FRF.items():
        th = e["prbm"]
        a, b = lab[t], ours[t]
        sic = " (sic?)" if (t, "res") in td.LINK_FRF_SIC else ""
        L.append(
            f"| {t} | {'on' if e['gravity'] else 'off'} | {e['payload']:g} | {th[0]:g} / {th[1]:g} dB / {th[2]:g}{sic} | "
            f"{a[0]:.3g} / {a[1]:.1f} dB / {a[2]:.3g} | {a[2] / th[2]:.2f} | {b[0]:.3g} / {b[1]:.1f} dB / {b[2]:.3g} | "
            f"{b[0] / th[0]:.2f} / {b[2] / th[2]:.2f} | {b[1] - th[1]:+.1f} |"
        )
    L.append("")
    L.append("Fitted to the four resonances not marked (sic?) and the two 2 kg peaks (k, c, tube mass; lever 0.57 m held):\n")
    L.append("| parameter | fitted (95 % CI) | reference-arm.md |")
    L.append("|---|---|---|")
    names = {"k": ("k of link 2 [N·m/rad]", "360 (Table 3, 30 kPa)"), "c": ("c of link 2 [N·m·s/rad]", "0.463"), "s_m": ("outer tube mass / 0.38 kg", "1 (0.38 kg)")}
    for n, x, (lo, hi) in zip(fit.names, fit.x, fit.ci):
        L.append(f"| {names[n][0]} | **{x:.3g}** ({lo:.3g}–{hi:.3g}) | {names[n][1]} |")
    L.append(f"| J_b about the bending joint, 0 kg [kg·m²] | {lk.inertia(0)[0]:.4f} | 0.0417 |")
    L.append("")
    L.append(
        f"What the resonances fix: √(k/J_b) at 0 and 2 kg pins J_tube/L² = {jt:.4f} and k/L² = {kl:.0f} N·m/rad/m² "
        f"(L the payload's lever about the bending joint); the 1 kg resonance is then a check (from the 0 and 2 kg ones "
        f"alone: {math.sqrt(kl / (jt + 1.0)):.2f} rad/s, printed 11). With reference-arm.md's lever 0.57 m the thesis's link had **k ≈ {lk.k:.0f} N·m/rad, {lk.k / 360:.2f} × Table 3's k**, "
        f"and a tube {lk.s_m:.2f} × as heavy; keeping Table 3's k = 360 instead needs a lever of "
        f"{math.sqrt(360 / kl):.2f} m (a 0.6 m link cannot have it). Table 3's f_s (15.94 Hz = √(k/J)/2π with J = "
        f"0.0359 kg·m²) is not this link either: k/J = {360 / 0.0359:.0f} s⁻² there against {kl / jt:.0f} s⁻² "
        f"(Table 12's 54.5² rad²/s²) here, a factor {360 / 0.0359 / (kl / jt):.1f}: Table 3 and Tables 10–15 were not made with one link.\n"
    )
    L.append(
        "**Conflicts.** The 1 and 0 kg peaks (8 and 10 dB printed; 17.6 and 5.0 dB fitted) cannot both follow with one "
        "damper: with a viscous c the damping ratio c/(2√(kJ_b)) rises as the payload falls, so the peak must fall "
        "monotonically from 2 to 0 kg; the printed 21 → 8 → 10 dB does not (a coarse frequency grid under-reads a sharp "
        f"1 kg peak). The 0 kg cut-off (147 printed, {ours[15][0]:.0f} ours) is 2.7 × its resonance; the fitted link, whose 0 kg "
        f"mode is heavily damped, gives {ours[15][0] / ours[15][2]:.2f} ×. Table 14's 7.8 and Table 15's 145 rad/s resonances repeat neighbouring numbers "
        "(sic) and are left out. Gravity: with the link horizontal it adds no stiffness about δ = 0; the fitted link "
        f"sags {9.81 * lk.inertia(2.0)[1] / lk.k:.2f} rad with 2 kg (m·g·x/k), which moves the resonance by "
        f"{100 * (ours[10][2] / ours[13][2] - 1):+.0f} % (Table 10 vs 13 above).\n"
    )
    e, (lo, hi) = beam_e
    L.append("**FEM column** (two peaks, 7.8 / 12.5–12.7 / 54.5–55 rad/s): link 2 of `popup-lab-thesis` an Euler–Bernoulli "
             f"beam (`examples/thesis_fem.py`: 4 elements, 1.2 mm wall, λ = 3.896·10⁻⁴ s, the arm's link-2 masses: outer tube "
             f"{tl.TUBE_M * lk.s_m:.3g} kg), the same beam as in Tables 5–7 above:\n")
    L.append("| table | thesis res. [rad/s] | beam, thesis E 0.557 GPa | beam, E fitted | ratio | thesis peak / cut-off | beam, E fitted: peak / cut-off |")
    L.append("|---|---|---|---|---|---|---|")
    for t in (13, 14, 15):
        cut, pk, th = td.LINK_FRF[t]["fem"]  # type: ignore[misc]
        b = beam_rows[t]
        L.append(
            f"| {t} | {th:g} | {thesis_beam_rows[t][2]:.3g} | {b[2]:.3g} | {b[2] / th:.2f} | {pk:g} dB / {'> 1000' if cut is None else f'{cut:g}'} | "
            f"{b[1]:.1f} dB / {f3(b[0])} |"
        )
    L.append("")
    L.append(
        f"The FEM resonances need **E = {e / 1e6:.3g} MPa** ({lo / 1e6:.3g}–{hi / 1e6:.3g}) at 1.2 mm, "
        f"{td.FEM_FIT['fit1']['e_pa'] / e:.0f} × below section 2.3's 0.557 GPa: the thesis's FEM link of chapter 6.2 was not the one of its "
        "section 2.3 fit (its beam was soft like its PRBM link, or its mass larger); Tables 5–7's 2 kg FEM entry says the "
        "same independently (above). One E cannot put all three resonances on the thesis's (ratios above): E scales them "
        "together, their spacing is set by the tube's mass against the payload's (a tube-mass fit as for the PRBM link "
        "would close it; the PRBM fit's tube is kept so that one arm serves both link models). The peaks and "
        f"cut-offs are not fitted: with λ = 3.896·10⁻⁴ s the beam's first mode has ζ = λω/2 ≈ {tf.LAMBDA * beam_rows[13][2] / 2:.3f} (a far sharper peak than "
        f"the thesis's 13.5–24 dB); with 1 and 0 kg the cut-off lies above 1000 rad/s as the thesis's '> 1000'; with 2 kg "
        f"the gain falls below −3 dB between the two modes ({f3(beam_rows[13][0])} rad/s) where the thesis read 430.\n"
    )
    return L


def engine_5_7_section(e: Dict[Tuple[str, float, float], float], r: tdr.DriveReport, beam_e: Tuple[float, Tuple[float, float]], printed: Dict[float, float], printed_res: float) -> List[str]:
    """Tables 5–7 on the engine (``thesis_fem.engine_tables_5_7``): the rigid, FEM (beam)
    and PRBM columns side by side with the thesis's."""
    ef, (elo, ehi) = beam_e
    L = ["**Tables 5–7 on the engine** (`examples/thesis_fem.py`: `popup-lab-thesis` with its drive, one link, gravity on; "
         "stepped sines of the non-linear closed loop, `popup.frequency.simulate`). Link 2 rigid, an Euler–Bernoulli beam "
         f"(the FEM column: 4 elements, 1.2 mm wall, λ = 3.896·10⁻⁴ s, **E = {ef / 1e6:.3g} MPa**, the E that puts the beam's "
         "first resonance on Tables 13–15's FEM column, below; not fitted to these tables) or PRBM (the fitted link):\n"]
    L.append("| kg | A [rad/s] | thesis rigid | engine rigid | ratio | numpy drive model, rigid | thesis FEM | engine beam | ratio | thesis PRBM | engine PRBM | ratio |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|")
    sur = {c.name: o for c, o in zip(r.jm.cases, r.jm.ours)}
    tabs = {2.0: 5, 1.0: 6, 0.0: 7}
    for p in (2.0, 1.0, 0.0):
        for a in td.AMPLITUDES:
            tr_, tf_, tp = (td.TABLES_5_7[p][k][a] for k in ("rigid", "fem", "prbm"))
            er, ef_, ep = (e[(k, p, a)] for k in ("rigid", "fem", "prbm"))
            L.append(
                f"| {p:g} | {a:g} | {tr_:g} | {er:.3g} | {er / tr_:.2f} | {sur.get(f'T{tabs[p]} rigid A={a:g}', math.nan):.3g} | "
                f"{tf_:g} | {ef_:.3g} | {ef_ / tf_:.2f} | {tp:g} | {ep:.3g} | {ep / tp:.2f} |"
            )
    rat = {k: [e[(k, p, a)] / td.TABLES_5_7[p][k][a] for p in (2.0, 1.0, 0.0) for a in td.AMPLITUDES] for k in ("fem", "prbm")}
    rng = {k: f"{100 * (min(v) - 1):+.0f} … {100 * (max(v) - 1):+.0f} %" for k, v in rat.items()}
    L.append("")
    L.append(
        f"The FEM column is reproduced by the beam link within {rng['fem']} and the PRBM column by the PRBM link within "
        f"{rng['prbm']}, neither fitted to these tables (the drive was fitted to Tables 8–9 and the rigid column, the links "
        "to Tables 10–15): the decoupling argument above, on the engine. Both flexible links have their first mode below "
        "the cut-offs, so above it the motor sees J_m alone and both columns equal the motoreducer alone (Table 8: 49.1 / "
        "151.5 / 707); the two columns of the thesis agree within 9 % for the same reason, and ours agree with each other "
        "as closely. The rigid column on the engine agrees with the numpy drive model (the same load: link 2 with the "
        "fitted tube and the payload about the elbow, gravity), which checks the fit's machinery; the rest is the engine's "
        "whole chain (the upright link 1 and the base drives react). All rows run with the thesis's payloads, 0 kg "
        "included (an all-rigid arm without payload used to fail the step check with a NaN mode: nalgebra's eigenvalue "
        "routine read the free q1 rotation's double zero eigenvalue as a complex pair, √(−ε); fixed in the core, "
        "`popup_core::math::eigenvalues`).\n"
    )
    if printed:
        L.append(
            "**Which E the FEM column needs.** With section 2.3's printed E = 0.557 GPa (λ read as ·10⁻⁴ s) the beam's "
            f"first resonance with 2 kg is {printed_res:.3g} rad/s (Table 13's FEM resonance: 7.85), and the 2 kg cut-off is "
            + ", ".join(f"{c:.3g} rad/s at A = {a:g} rad/s" for a, c in printed.items())
            + " (dt = 1e-4/12 s, the step that beam needs)"
            + f" against the thesis's FEM {td.TABLES_5_7[2.0]['fem'][3.0]:g} and rigid {td.TABLES_5_7[2.0]['rigid'][3.0]:g}: "
            "a link that stiff still loads the motor at the torque-limited cut-off. The FEM column, like the FEM link FRF, "
            f"asks for the soft beam (E = {ef / 1e6:.3g} MPa, 95 %: {elo / 1e6:.3g}–{ehi / 1e6:.3g}), not section 2.3's.\n"
        )
    return L


def beam_fit_section(e_fit: float, link: tl.Link) -> List[str]:
    """Section 2.3 with the thesis's numbers: static tip deflection and the relaxation time
    the printed λ gives, side by side with ours (``link``: the fitted PRBM link)."""
    r, L = tl.R2, tl.TUBE_L
    g = 9.81
    f1, f2 = td.FEM_FIT["fit1"], td.FEM_FIT["fit2"]
    e_of_k = lambda k, t: k * L / (3 * math.pi * r**3 * t)  # noqa: E731  EI = kL/3
    rows = []
    for label, e, t, lam, m, tube in (
        ("thesis fit 1", f1["e_pa"], f1["wall_m"], f1["lambda_s"], f1["payload_kg"], tl.TUBE_M),
        ("thesis fit 1, λ read as 3.896·10⁻⁴ s", f1["e_pa"], f1["wall_m"], f1["lambda_s"] * 1e-8, f1["payload_kg"], tl.TUBE_M),
        ("thesis fit 2", f2["e_pa"], f2["wall_m"], f2["lambda_s"], f2["payload_kg"], tl.TUBE_M),
        ("thesis fit 2, λ read as 3.4919·10⁻⁴ s", f2["e_pa"], f2["wall_m"], f2["lambda_s"] * 1e-8, f2["payload_kg"], tl.TUBE_M),
        (f"ours, EI = kL/3 matched to popup-lab's k = {tl.K_T3:g} (λ = c/k)", e_of_k(tl.K_T3, 1.2e-3), 1.2e-3, tl.C_T3 / tl.K_T3, 2.0, tl.TUBE_M),
        (f"ours, EI = kL/3 matched to the fitted thesis link, k = {link.k:.3g} (λ = c/k)", e_of_k(link.k, 1.2e-3), 1.2e-3, link.c / link.k, 2.0, tl.TUBE_M * link.s_m),
        ("ours, fitted to Tables 13–15's FEM resonances (popup-lab-thesis's tube)", e_fit, 1.2e-3, tf.LAMBDA, 2.0, tl.TUBE_M * link.s_m),
    ):
        EI = e * math.pi * r**3 * t
        defl = m * g * L**3 / (3 * EI)
        w1 = math.sqrt(3 * EI / L**3 / (m + 0.24 * tube))
        zeta = lam * w1 / 2
        relax = lam if zeta > 1 else float("nan")
        rows.append((label, e, t, lam, m, EI, defl, w1, zeta, relax))
    out = ["## Section 2.3: the FEM link fitted to the PRBM link\n"]
    out.append("| fit | E [MPa] | wall [mm] | λ [s] | payload [kg] | EI [N·m²] | static tip deflection [mm] | ω₁ [rad/s] | ζ₁ = λω₁/2 | slow time constant [s] |")
    out.append("|---|---|---|---|---|---|---|---|---|---|")
    for (lab, e, t, lam, m, EI, d, w1, z, rx) in rows:
        out.append(f"| {lab} | {e / 1e6:.4g} | {t * 1e3:g} | {lam:.4g} | {m:g} | {EI:.3g} | {d * 1e3:.3g} | {w1:.3g} | {z:.3g} | {'—' if math.isnan(rx) else f'{rx:.3g}'} |")
    k_lab = tl.K_T3
    ei1, ei2 = rows[0][5], rows[2][5]
    ei = 0.5 * (ei1 + ei2)
    out.append("")
    out.append(
        "Cantilever of link 2 (r = 0.055 m, L = 0.57 m, I = π r³ t), tip load under gravity; ω₁ with a "
        "quarter of the tube's mass at the tip. As printed, λ ≈ 3.9·10⁴ s makes every mode overdamped with a slow time "
        "constant ≈ λ ≈ 11 h: in a seconds-long estimation run the beam hardly moves, so the printed E cannot have been "
        "identified from a tip displacement (the 'steady-state error remains' of fit 1); read as ·10⁻⁴ s (the presets "
        f"`thesis-1.2mm`/`thesis-0.8mm` do) the first mode is lightly damped (ζ₁ = {rows[1][8]:.3f} and {rows[3][8]:.3f} on this cantilever). Both printed fits agree on E·t "
        f"({f1['e_pa'] * f1['wall_m']:.2g} and {f2['e_pa'] * f2['wall_m']:.2g} N/m), i.e. EI ≈ {ei:.0f} N·m², a static tip stiffness 3EI/L³ = {3 * ei / L**3:.0f} N/m: "
        f"{3 * ei / L / k_lab:.1f} × popup-lab's PRBM (k/L² = {k_lab / L**2:.0f} N/m at the tip, k = {k_lab:g}) and "
        f"{3 * ei / L / link.k:.0f} × the thesis's own chapter-6 PRBM link fitted above (k ≈ {link.k:.3g}). Our fit of a beam to popup-lab's "
        "PRBM tip response (docs/beam_vs_prbm.md) lands within 3 % of the matched EI = kL/3 row; the thesis's chapter-6 FEM "
        f"resonances ask for E = {e_fit / 1e6:.3g} MPa, {e_fit / e_of_k(link.k, 1.2e-3):.2f} × the k = {link.k:.3g} match and "
        f"{f1['e_pa'] / e_fit:.0f} × below the printed fit 1.\n"
    )
    return out


def _r(a: float, b: float) -> str:
    """Ratio on/off as a signed percentage."""
    return f"{100 * (a / b - 1):+.0f} %" if b > 0 and np.isfinite(a) and np.isfinite(b) else "—"


def ch5_section() -> List[str]:
    """Chapter 5's wrinkling payload: the thesis's coefficient and the classical one."""
    p, r, g, L = 30e3, 0.055, 9.81, 0.6
    mw_t, mw_c = math.pi**2 / 4 * p * r**3, math.pi / 2 * p * r**3
    tube = 0.4 * g * 0.3
    return [
        "## Chapter 5: the payload the wrinkling moment allows\n",
        f"M_w = (π²/4)·p·r³ = {mw_t:.2f} N·m (thesis: 12.32) for link 2 at 30 kPa, and M_w = payload·g·L gives "
        f"{mw_t / (g * L):.2f} kg (thesis: ≈ 2 kg; {(mw_t - tube) / (g * L):.2f} kg once the 0.4 kg tube's own moment is "
        f"taken off). With the classical onset (π/2)·p·r³ = {mw_c:.2f} N·m (popup's default, reference-arm.md) the same "
        f"link carries {mw_c / (g * L):.2f} kg ({(mw_c - tube) / (g * L):.2f} kg with the tube): the thesis's 2 kg payload "
        "is above the classical onset of wrinkling at the root with the link horizontal, which is why the runs below "
        "raise wrinkling alarms (they are logged and the runs go on).\n",
    ]


def ch78_section(res: Dict[str, Any], dr: tdr.DriveReport) -> List[str]:
    """Chapters 4, 7 and 8 from ``examples/thesis_ch78.py``'s results, each claim checked."""
    c7, c8 = res["ch7"], res["ch8"]
    L = ["## Chapters 4, 7 and 8 with the thesis's parameters\n"]
    L.append(
        "Run by `examples/thesis_ch78.py` on `popup-lab-thesis` with its drive (" + f"{res['seconds']:.0f} s" + "); its "
        "docstring gives the set-ups. **Gain mapping:** the thesis's damping PID output enters its velocity loop in drive "
        "units (after the velocity PI); ours is subtracted from the velocity reference, before it, and reaches the drive "
        "as Kp_v·u_d, so K_ours = K_thesis/Kp_v (70 → 0.014 (rad/s)/(m/s²) with Kp_v = 5000; chapter 8: 50 → 0.05 with "
        "Kp_v = 1000). The column 'printed' runs the thesis's numbers as ours, to show that reading is not what the "
        "thesis ran. Square waves (not printed): π/2 amplitude, period 6 s. Bending: x = in the arm's plane (d12, d22), "
        "y = lateral (d11, d21); 'vib' = RMS about the final value after the move.\n"
    )
    L.append("| sim | set-up | damping | vib x [mrad] | vib y [mrad] | sag [mrad] | peak τ2,3 [N·m] | τ2,3 RMS [N·m] | tip acc. RMS [m/s²] | ee osc. RMS [mm] | final q error [mrad] | holding τ2,3 at the target [N·m] | status |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for sid, row in c7.items():
        for v in ("off", "on", "printed", "rigid twin"):
            if v not in row:
                continue
            m = row[v]
            L.append(
                f"| {sid} | {row['sim']} | {v} | {1e3 * m['vib_x']:.2f} | {1e3 * m['vib_y']:.2f} | {1e3 * m['sag']:.1f} | "
                f"{m['tau23']:.1f} | {m['tau_rms23']:.2f} | {m['acc_rms']:.3f} | {1e3 * m['ee_osc']:.1f} | {1e3 * m['q_err']:.0f} | {m['hold23']:.1f} | {m['status']} |"
            )
            L[-1] = L[-1].replace("| nan ", "| — ")
    L.append("")
    claims: List[str] = []
    if "ch4" in c7.get("ch4", {}):
        x = c7["ch4"]["ch4"]
        claims.append(
            f"- **Ch. 4, 'with the PRBM link the joint angle is almost unchanged, the joint velocity oscillates'**: q3 differs from "
            f"the rigid link's run by at most {1e3 * x['dq_max']:.0f} mrad during the π/2 move ({1e3 * x['dq_final']:.1f} mrad at the end), "
            f"its rate by {x['rate_diff']:.3f} rad/s RMS ({100 * x['rate_diff'] / x['rate_rms_r']:.0f} % of the rigid run's rate RMS): "
            f"**{'holds' if x['dq_final'] < 0.01 else 'holds only at the end of the move'}** — the angle ends where the rigid run's does, "
            "but on the way the soft link unloads the motor (above its 7.85 rad/s mode the motor sees J_m alone) and the joint moves "
            "differently."
        )
    damped = [s for s, r in c7.items() if "on" in r]
    cols = (("vib_x", "bending"), ("tau_rms23", "joint torque (RMS)"), ("acc_rms", "tip acceleration (RMS)"), ("ee_osc", "end-effector oscillation"))
    for key, what in cols:
        rs = {s: c7[s]["on"][key] / c7[s]["off"][key] if c7[s]["off"][key] > 0 else math.nan for s in damped}
        lower = [s for s, v in rs.items() if v < 0.95]
        worse = [s for s, v in rs.items() if v > 1.05]
        verdict = "holds" if len(lower) == len(rs) else ("does not hold (changes under 5 %" + (f"; worse in sims {', '.join(worse)}" if worse else "") + ")" if not lower else f"holds (≥ 5 % lower) only in sims {', '.join(lower)}" + (f", worse in sims {', '.join(worse)}" if worse else ""))
        claims.append(f"- **Ch. 7, damping lowers the {what}**: on/off " + ", ".join(f"sim {s} {_r(c7[s]['on'][key], c7[s]['off'][key])}" for s in damped) + f": **{verdict}**.")
    pk = {s: _r(c7[s]["on"]["tau23"], c7[s]["off"]["tau23"]) for s in damped}
    claims.append("  Peak joint torque on/off: " + ", ".join(f"sim {s} {v}" for s, v in pk.items()) + " (the peak is the step's start, where the drive is at its limit either way).")
    grav = [s for s, r in c7.items() if s in ("3", "4", "5", "6", "7")]
    nog = [s for s, r in c7.items() if s in ("1", "2")]
    tw = [s for s in ("3", "4") if "rigid twin" in c7.get(s, {})]
    claims.append(
        "- **Ch. 7, with gravity the deformation settles to a non-zero offset, the tip z differs from the rigid twin's**: final "
        "in-plane bending " + ", ".join(f"sim {s} {1e3 * c7[s]['off']['sag']:.0f}" for s in grav) + " mrad with gravity against "
        + ", ".join(f"sim {s} {1e3 * c7[s]['off']['sag']:.1f}" for s in nog) + " mrad without; final tip z (damping on) − the rigid twin's: "
        + ", ".join(f"sim {s} {1e3 * (c7[s]['on']['ee_z'] - c7[s]['rigid twin']['ee_z']):.0f} mm" for s in tw)
        + ": **holds where the final pose puts a moment on the link** (sim 3 ends with the link vertical: no sag there; without "
        "gravity the last second's mean still carries the decaying first mode, ζ ≈ 0.05 at 7.85 rad/s)."
    )
    if "5" in c7:
        m = c7["5"]["off"]
        claims.append(
            f"- **Ch. 7 sim 5, an input on joint 3 alone deforms both links**: vibration RMS link 1 {1e3 * m['vib_l1']:.2f} mrad, "
            f"link 2 {1e3 * m['vib_l2']:.2f} mrad: **{'holds' if m['vib_l1'] > 1e-3 else 'does not hold'}** "
            f"(link 1 moves {100 * m['vib_l1'] / m['vib_l2']:.0f} % as much as link 2)."
        )
    bad = [f"sim {s} ({c7[s]['printed']['status']}" + (f", vib x {1e3 * c7[s]['printed']['vib_x']:.0f} mrad" if np.isfinite(c7[s]['printed']['vib_x']) else "") + ")" for s in damped if "printed" in c7[s]]
    claims.append(
        "- **The gains as printed, in our units**: " + "; ".join(bad) + ": unstable or far worse than no damping, so the thesis's "
        "numbers were not (rad/s)/(m/s²) subtracted from the velocity reference. Mapped by 1/Kp_v they are small (sims 1–2: "
        "2·10⁻⁴) and change the runs by a few per cent at most, except sim 6 (its Ki = 100, Kd = 20 act)."
    )
    if "6" in c7 and c7["6"]["off"]["q_err"] > 0.1:
        m = c7["6"]["off"]
        claims.append(
            f"- **Sims 6–7 do not reach their target** on the fitted arm: the shoulder's holding torque at the target pose "
            f"(0, 3π/4, π/4) with 2 kg is {m['hold23']:.1f} N·m against the fitted τ_max = {popup.arm_motor('popup-lab-thesis')['tau_max']:.1f} N·m, "
            f"and the π/4 moves need more than the margin: the drive saturates and the arm falls back (final joint error "
            f"{1e3 * m['q_err']:.0f} mrad, with and without damping). τ_max = b·J_m rests on the rigid column's J_m "
            f"(95 % interval {dr.jm.ci[0][0]:.2f}–{dr.jm.ci[0][1]:.2f} kg·m², τ_max {dr.motor.drive.b * dr.jm.ci[0][0]:.0f}–"
            f"{dr.motor.drive.b * dr.jm.ci[0][1]:.0f} N·m), so these two runs only say that the fitted drive is near its limit "
            "there; their damping numbers describe a fall, not the thesis's move."
        )
    L += claims
    L.append("")
    L.append(
        f"**Chapter 8.** The PRBM chain refuses the target: `{c8['chain_refuses']}`. Run with "
        "`Controller(cartesian_arm=\"as_built\")` (thesis Table 1 Jacobian, PRBM plant) as the thesis did; velocity PI "
        "1000 / 10; damping off, sim 1 (Kp 0/50/50) and sim 2 (Kp 30/60/70, Ki = Kd = 0.1), mapped by 1/1000; gap = RMS "
        "distance of the end effector from the rigid twin's over the run.\n"
    )
    L.append("| gravity | kg | damping | vib x [mrad] | vib y [mrad] | τ2,3 RMS [N·m] | tip acc. RMS [m/s²] | gap to rigid twin [mm] | final ee of the plant [m] | Table-1 tip to target [mm] | status |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|")
    keys = [k for k in c8 if isinstance(k, tuple)]
    for k in keys:
        g, p, v = k
        m = c8[k]
        L.append(
            f"| {'on' if g else 'off'} | {p:g} | {v} | {1e3 * m['vib_x']:.2f} | {1e3 * m['vib_y']:.2f} | {m['tau_rms23']:.2f} | "
            f"{m['acc_rms']:.3f} | {1e3 * m['gap_rms']:.0f} | ({', '.join(f'{x:.2f}' for x in m['ee_final'])}) | {1e3 * m['t1_miss']:.0f} | {m['status']} |"
        )
    L.append("")
    off2, s1, s2 = c8[(False, 2.0, "off")], c8[(False, 2.0, "sim 1")], c8[(False, 2.0, "sim 2")]
    ok1 = s1["vib_x"] < off2["vib_x"] and abs(s1["vib_y"] / off2["vib_y"] - 1) < 0.1 if off2["vib_y"] > 0 else False
    L.append(
        f"- **Sim 1, x-bending damped, y-bending unchanged, torques 2-3 and tip accelerations lower** (2 kg, no gravity): vib x "
        f"{_r(s1['vib_x'], off2['vib_x'])}, vib y {_r(s1['vib_y'], off2['vib_y'])}, τ RMS {_r(s1['tau_rms23'], off2['tau_rms23'])}, "
        f"tip acc. {_r(s1['acc_rms'], off2['acc_rms'])}: **{'holds' if ok1 and s1['tau_rms23'] < off2['tau_rms23'] and s1['acc_rms'] < off2['acc_rms'] else 'does not hold as a whole (see the numbers)'}**."
    )
    L.append(
        f"- **Sim 2, y-bending damped too**: vib y {_r(s2['vib_y'], off2['vib_y'])} (sim 1: {_r(s1['vib_y'], off2['vib_y'])}): "
        f"**{'holds' if s2['vib_y'] < min(off2['vib_y'], s1['vib_y']) else 'does not hold'}**."
    )
    gaps = {p: c8[(False, p, "sim 2")]["gap_rms"] for p in (0.0, 1.0, 2.0)}
    mono = gaps[0.0] < gaps[1.0] < gaps[2.0]
    L.append(
        "- **Robustness, the gap to the rigid arm shrinks as the payload falls**: gap (sim 2, no gravity) "
        + ", ".join(f"{p:g} kg {1e3 * x:.0f} mm" for p, x in gaps.items())
        + f": **{'holds' if mono else 'does not hold'}**. With gravity: "
        + ", ".join(f"{p:g} kg {1e3 * c8[(True, p, 'sim 2')]['gap_rms']:.0f} mm" for p in (0.0, 1.0, 2.0)) + "."
    )
    eff = {p: c8[(False, p, "sim 2")]["vib_x"] / c8[(False, p, "off")]["vib_x"] for p in (0.0, 1.0, 2.0)}
    spread = max(eff.values()) - min(eff.values())
    L.append(
        "- **'Payload variation does not change the results'** (the damping's effect, vib x on/off, sim 2): "
        + ", ".join(f"{p:g} kg {_r(v, 1.0)}" for p, v in eff.items())
        + f": **{'holds' if spread < 0.2 and all(v < 1 for v in eff.values()) else 'holds only in part: the same gains act differently on the 0 kg arm, whose modes are higher'}**."
    )
    L.append("")
    return L


def missing_section() -> List[str]:
    return [
        "## Elsewhere\n",
        "- Chapter 3 (set-membership identification): docs/setmembership.md (`examples/thesis_set_membership.py`).\n",
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-arm", action="store_true", help="keep crates/popup-core/arms/popup-lab-thesis.toml as it is")
    ap.add_argument("--cache", action="store_true", help="reuse out/thesis_drive.pkl (the drive fit, ≈ 4 min) if present")
    args = ap.parse_args()
    t0 = time.time()
    IMG.mkdir(parents=True, exist_ok=True)
    lf = tl.fit(("k", "c", "s_m"))
    print("link fit", lf.x, flush=True)
    cache = ROOT / "out" / "thesis_drive.pkl"
    if args.cache and cache.exists():
        dr = pickle.loads(cache.read_bytes())
    else:
        dr = tdr.run(log=True, tube_scale=lf.link.s_m)
        cache.parent.mkdir(exist_ok=True)
        cache.write_bytes(pickle.dumps(dr))
    print("drive fit", dr.jm.drive, flush=True)
    if not args.no_arm:
        text = write_arm(dr.jm.drive, lf.link)
        if text != popup.Arm.packaged_source("popup-lab-thesis"):
            # the arm is compiled into the core: the rest would run on the old numbers
            print(f"{ARM} changed: rebuild the extension (maturin) and rerun with --cache", file=sys.stderr)
            sys.exit(3)
    lab = tl.engine_rows(lambda g: popup.Model("popup-lab", gravity=g).with_links("rigid", "prbm"))
    ours = tl.engine_rows(lambda g: popup.Model("popup-lab-thesis", gravity=g).with_links("rigid", "prbm"))
    rigid = tl.engine_rows(lambda g: popup.Model("popup-lab", gravity=g).with_links("rigid", "rigid"))
    be = tf.fit_beam_e()
    print("beam E", be, flush=True)
    beam_rows = tl.engine_rows(lambda g: tf.beam_model(be[0], g))
    thesis_beam_rows = tl.engine_rows(lambda g: tf.beam_model(td.FEM_FIT["fit1"]["e_pa"], g))
    plot_link(lf.link, lab, ours, tl.engine_frf(tf.beam_model(be[0], False)), IMG / "thesis_link_frf.png")
    plot_drive(dr, IMG / "thesis_drive.png")
    t57 = tf.engine_tables_5_7({"rigid": tf.one_link_model("rigid"), "fem": tf.one_link_model("beam", be[0]), "prbm": tf.one_link_model("prbm")})
    # section 2.3's printed E on the most telling entry (2 kg, A = 3 rad/s); that stiff beam needs dt = 1e-4/12 s
    printed = {3.0: float(tf.engine_cutoffs(tf.one_link_model("beam", td.FEM_FIT["fit1"]["e_pa"], dt=1e-4 / 12), 3.0, [2.0], np.geomspace(10.0, 150.0, 9))[0])}
    print("tables 5-7", t57, printed, flush=True)
    plot_5_7(t57, IMG / "thesis_tables_5_7.png")
    L = [
        "# The thesis's results, reproduced\n",
        f"Generated by `examples/thesis_report.py` (popup {popup.__version__}, @SECONDS@ s on 2 shared cores"
        + (", the drive fit and chapters 7–8 reused from `out/` (`--cache`)" if args.cache else "") + "); "
        "the thesis's numbers are in `examples/thesis_data.py` (as printed, with their tables). Every gap is explained "
        "by a fitted number; the fitted arm ships as `popup.Model(\"popup-lab-thesis\")` "
        "(`crates/popup-core/arms/popup-lab-thesis.toml`, compiled in; every number that differs from popup-lab listed there; "
        "`popup statics --arm popup-lab-thesis` and scenario files take it by name too) with its "
        "drive `Controller(motor=popup.arm_motor(\"popup-lab-thesis\"))`. `popup-lab` itself stays the arm of "
        "reference-arm.md. Checked by `tests/test_thesis.py` (≈ 1 min): Tables 8–9 each within 15 % by the fitted drive, "
        "Tables 10–15's resonances (not sic) within 5 %, the 2 kg peaks within 1.5 dB and the 1–2 kg cut-offs within 12 % by "
        f"the fitted arm on the engine, Tables 13–15's FEM resonances within {100 * tf.TOL_RES:.0f} % and Tables 5–7's 2 kg FEM column within "
        f"{100 * tf.TOL_5_7:.0f} % by the beam link with E refitted, the rigid 0 kg run, and the models' physics against closed forms.\n",
        "![Tables 8 and 9](img/thesis_drive.png)\n",
    ]
    L += drive_section(dr)
    L += engine_5_7_section(t57, dr, be, printed, thesis_beam_rows[13][2])
    L += ["![Tables 5-7](img/thesis_tables_5_7.png)\n"]
    L += ["![Tables 10-15](img/thesis_link_frf.png)\n"]
    L += link_section(lf, lab, ours, rigid, be, beam_rows, thesis_beam_rows)
    L += beam_fit_section(be[0], lf.link)
    L += ch5_section()
    ch = ROOT / "out" / "thesis_ch78.pkl"
    if args.cache and ch.exists():
        L += ch78_section(pickle.loads(ch.read_bytes()), dr)
    else:
        import thesis_ch78

        t1 = time.time()
        r78 = {"ch7": thesis_ch78.run_ch7(), "ch8": thesis_ch78.run_ch8(), "seconds": 0.0}
        r78["seconds"] = time.time() - t1
        ch.write_bytes(pickle.dumps(r78))
        L += ch78_section(r78, dr)
    L += missing_section()
    DOC.write_text("\n".join(L).replace("@SECONDS@", f"{time.time() - t0:.0f}"))
    print(f"wrote {DOC} in {time.time() - t0:.0f} s")


if __name__ == "__main__":
    main()

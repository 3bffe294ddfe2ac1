#!/usr/bin/env python3
"""The link's FRF of the thesis's Tables 10–15, and what the thesis's link must have had.

Tables 10–15 (chapter 6.2): input the feedback joint velocity q̇3, output the tip's
angular velocity about the link's bending axis (for a rigid link output = input, flat,
ratio 1). Both are rates of the same motion, so the ratio does not depend on the motor
loop: it is the link's own response to its base rotation. For one PRBM link (link 2 on
the elbow; a bending joint at a0 = 0.03 m from the elbow axis, the outer piece and the
payload beyond it) and small motion, with δ the bending angle and θ the motor angle:

    J_b (θ̈ + δ̈) + S a0 θ̈ + c δ̇ + k δ = 0,
    H(s) = (θ̇ + δ̇)/θ̇ = (k + c s − S a0 s²) / (J_b s² + c s + k),

J_b the outer piece's and payload's inertia about the bending joint, S their first
moment (the root piece's tangential acceleration a0 θ̈ loads them). At q0 = 0° the
link is horizontal and gravity adds no stiffness about δ = 0 (its moment is cos-shaped),
so gravity on and off give the same FRF. The resonance is ≈ the locked-motor mode
√(k/J_b); the thesis's 7.85 / 11 / 54.5 rad/s for 2 / 1 / 0 kg fix two ratios of
(k, J_tube, lever): J_tube/L² and k/L² (L the payload's lever about the bending joint);
with the lever of reference-arm.md (0.57 m) they give k and J_tube.

Extraction as the thesis did: resonance = frequency of the largest gain, peak = its
height in dB above the flat low-frequency gain (0 dB), cut-off = the first frequency
above the resonance where the gain falls 3 dB below 0 dB.

Usage::

    python examples/thesis_link.py        # fit + engine check (≈ 20 s)
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import thesis_data as td  # noqa: E402

A0 = 0.03
"""Root piece: elbow axis to bending joint [m] (reference-arm.md)."""
LEVER = 0.57
"""Payload lever about link 2's bending joint [m] (frame 7 origin, reference-arm.md)."""
R2 = 0.055
TUBE_M, TUBE_L = 0.38, 0.57
K_T3, C_T3 = 360.0, 0.463
"""Table 3 at 30 kPa: k [N·m/rad], c [N·m·s/rad] of link 2's bending joints."""
W = np.geomspace(0.5, 3000.0, 4000)
R = 1.0 / math.sqrt(2.0)


@dataclass
class Link:
    """One PRBM link: ``k`` [N·m/rad], ``c`` [N·m·s/rad], tube mass scale ``s_m`` (1 =
    reference-arm.md's 0.38 kg outer piece), payload ``lever`` [m]."""

    k: float = K_T3
    c: float = C_T3
    s_m: float = 1.0
    lever: float = LEVER

    def inertia(self, payload: float) -> Tuple[float, float]:
        """(J_b [kg·m²], S [kg·m]) about the bending joint."""
        m = TUBE_M * self.s_m
        xc = TUBE_L / 2
        jb = m * (R2**2 / 2 + TUBE_L**2 / 12) + m * xc**2 + payload * self.lever**2
        return jb, m * xc + payload * self.lever

    def frf(self, payload: float, w: np.ndarray = W) -> np.ndarray:
        """(θ̇ + δ̇)/θ̇ at ``w`` [rad/s] (module docstring)."""
        jb, s = self.inertia(payload)
        iw = 1j * np.asarray(w)
        return (self.k + self.c * iw - s * A0 * iw**2) / (jb * iw**2 + self.c * iw + self.k)

    def locked_mode(self, payload: float) -> float:
        """√(k/J_b) [rad/s]."""
        return math.sqrt(self.k / self.inertia(payload)[0])


def extract(w: np.ndarray, H: np.ndarray) -> Tuple[float, float, float]:
    """(cut-off [rad/s], peak [dB], resonance [rad/s]) as the thesis read them: the largest
    gain (parabola in log ω/dB through its neighbours), its height above 0 dB, and the
    first −3 dB crossing above it (inf: none in the grid)."""
    g = np.abs(H)
    db = 20 * np.log10(g)
    i = int(np.argmax(db))
    if 0 < i < len(w) - 1:
        x = np.log(w[i - 1 : i + 2])
        y = db[i - 1 : i + 2]
        a, b, c = np.polyfit(x - x[1], y, 2)
        xm = -b / (2 * a) if a < 0 else 0.0
        res, peak = float(np.exp(x[1] + xm)), float(c - b * b / (4 * a)) if a < 0 else float(db[i])
    else:
        res, peak = float(w[i]), float(db[i])
    cut = math.inf
    for j in range(i, len(w) - 1):
        if g[j] >= R > g[j + 1]:
            d0, d1, dr = db[j], db[j + 1], 20 * math.log10(R)
            cut = float(math.exp(math.log(w[j]) + (d0 - dr) / (d0 - d1) * math.log(w[j + 1] / w[j])))
            break
    return cut, peak, res


def table_rows(link: Link) -> Dict[int, Tuple[float, float, float]]:
    """Our (cut-off, peak, resonance) for Tables 10–15 (gravity does not enter: module
    docstring)."""
    return {t: extract(W, link.frf(float(e["payload"]))) for t, e in td.LINK_FRF.items()}


FIT_ENTRIES = [(t, "res") for t in td.LINK_FRF if (t, "res") not in td.LINK_FRF_SIC] + [(10, "peak"), (13, "peak")]
"""Entries fitted: the PRBM resonances of Tables 10–15 but the two marked (sic?) (they fix
k and J_b) and the 2 kg peaks (the sharpest, they fix c). The cut-offs and the 0/1 kg peaks
are then predictions."""


def residuals(link: Link) -> np.ndarray:
    """ln(ours/thesis) for frequencies, (ours − thesis)/20·ln 10 for peaks (the ln of the
    gain ratio), over :data:`FIT_ENTRIES`."""
    rows = table_rows(link)
    out = []
    for t, what in FIT_ENTRIES:
        th = td.link_frf_entry(t, "prbm", what)
        i = {"cutoff": 0, "peak": 1, "res": 2}[what]
        o = rows[t][i]
        if what == "peak":
            out.append((o - th) / 20 * math.log(10))
        else:
            out.append(math.log(o / th) if 0 < o < math.inf else math.log(10))
    return np.array(out)


@dataclass
class LinkFit:
    """Fitted link: values, 95 % intervals, the parameter names, residual cost."""

    link: Link
    names: List[str]
    x: np.ndarray
    ci: np.ndarray
    cost: float


def fit(names: Sequence[str] = ("k", "c", "s_m"), base: Link = Link()) -> LinkFit:
    """Least squares (log parameters) of ``names`` (fields of :class:`Link`) to the PRBM
    columns of Tables 10–15; 95 % intervals from the Jacobian."""
    from scipy.stats import t as student

    def mk(x: np.ndarray) -> Link:
        d = dict(base.__dict__)
        d.update(dict(zip(names, np.exp(x))))
        return Link(**d)

    x0 = np.log([getattr(base, n) for n in names])
    # start from the locked-mode estimate of k and J (2 kg and 0 kg resonances)
    sol = least_squares(lambda x: residuals(mk(x)), x0, diff_step=1e-4)
    dof = max(len(FIT_ENTRIES) - len(names), 1)
    s2 = 2 * sol.cost / dof
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * s2
    q = student.ppf(0.975, dof)
    se = np.sqrt(np.diag(cov))
    return LinkFit(mk(sol.x), list(names), np.exp(sol.x), np.exp(np.column_stack([sol.x - q * se, sol.x + q * se])), float(sol.cost))


def ratios_from_resonances() -> Tuple[float, float]:
    """(J_tube/L², k/L² [N·m/rad/m²]) that put √(k/J) at Table 10's and Table 12's PRBM
    resonances (J = J_tube + m L²): the two ratios the frequencies fix."""
    w2, w0 = td.LINK_FRF[10]["prbm"][2], td.LINK_FRF[12]["prbm"][2]  # type: ignore[index]
    # k = w0² Jt = w2² (Jt + 2 L²)  ->  Jt/L² = 2 w2² / (w0² − w2²)
    jt = 2 * w2**2 / (w0**2 - w2**2)
    return jt, w0**2 * jt


def main() -> None:
    ref = Link()
    print("popup-lab link 2 (k = 360, c = 0.463, tube 0.38 kg):")
    for t, r in table_rows(ref).items():
        print(f"  T{t}: ours cut {r[0]:.3g} peak {r[1]:.3g} res {r[2]:.3g} | thesis {td.LINK_FRF[t]['prbm']}")
    jt, kl = ratios_from_resonances()
    print(f"ratios: J_tube/L² = {jt:.4f}, k/L² = {kl:.1f}")
    for names in (("k", "s_m"), ("k", "c", "s_m")):
        f = fit(names)
        print(names, dict(zip(f.names, np.round(f.x, 4))), np.round(f.ci, 4).tolist(), f"cost {f.cost:.4f}")
        for t, r in table_rows(f.link).items():
            print(f"  T{t}: ours cut {r[0]:.3g} peak {r[1]:.3g} res {r[2]:.3g} | thesis {td.LINK_FRF[t]['prbm']}")


if __name__ == "__main__":
    main()


Q_LINK = (0.0, math.pi / 2, -math.pi / 2)
"""Motor angles of the one-link experiment in popup's arm: link 1 straight up (its bending
locked: ``with_links("rigid", ...)``), link 2 horizontal, i.e. the thesis's q0 = 0°."""


def engine_frf(model, payloads: Sequence[float] = (2.0, 1.0, 0.0), w: np.ndarray = W) -> np.ndarray:
    """(θ̇3 + δ̇22)/θ̇3 of the engine's linearised arm (``popup.frequency.linearize``, input
    the motor angle, outputs ``dq3`` and ``dd22`` — for a beam link ``dd22`` is the tip's
    rotation rate), one row per payload [kg]; link 1 as ``model`` has it."""
    from popup import frequency as fr

    lin = fr.linearize(model, Q_LINK, input="motor_angle", outputs=["dq3", "dd22"], payload_kg=list(payloads))
    H = lin.frf(w, joint="q3").H
    return (H[:, :, 0] + H[:, :, 1]) / H[:, :, 0]


def engine_rows(make) -> Dict[int, Tuple[float, float, float]]:
    """Our (cut-off, peak, resonance) of Tables 10–15 from the engine: ``make(gravity)``
    gives the model, with gravity for Tables 10–12 and without for 13–15 (link 1 rigid, link 2
    as the model has it)."""
    out: Dict[int, Tuple[float, float, float]] = {}
    for grav, tabs in ((True, (10, 11, 12)), (False, (13, 14, 15))):
        H = engine_frf(make(grav), [float(td.LINK_FRF[t]["payload"]) for t in tabs])
        for i, t in enumerate(tabs):
            out[t] = extract(W, H[i])
    return out

#!/usr/bin/env python3
"""The thesis's FEM link on the engine: link 2 of ``popup-lab-thesis`` as an
Euler–Bernoulli beam, its E fitted to the FEM resonances of Tables 13–15, and Tables 5–7
(velocity-loop cut-offs) with rigid, PRBM and that beam link on the engine.

**The beam.** ``beam_model``: ``popup-lab-thesis`` (the fitted drive's reflected inertia,
link 2's fitted outer-tube mass), link 1 rigid, link 2 ``beam(4)`` with the section-2.3
material of the 1.2 mm wall (``thesis-1.2mm``: ν, density from the arm's masses), Rayleigh
λ = 3.896·10⁻⁴ s (the printed 3.896·10⁴ s read as ·10⁻⁴, docs/thesis.md) and E free.
``fit_beam_e`` puts its first resonance of the link FRF (input q̇3, output the tip's
rotation rate, ``thesis_link.engine_frf``) on the thesis's FEM column of Tables 13–15
(7.85 / 12.7 / 54.5 rad/s, gravity off), least squares in ln E.

**Tables 5–7.** ``engine_tables_5_7``: the one-link set-up of ``thesis_ch78.py`` (link 1
rigid and upright, base drives that cannot saturate, link 2 horizontal at the thesis's
q0 = 0°), the fitted drive on q3 with the velocity PI 5000 / 100, gravity on; stepped
sines A sin ωt of the q3 velocity reference through the non-linear closed loop
(``popup.frequency.simulate``), gain = first harmonic of q̇3 / A, cut-off = the first
−3 dB crossing (``thesis_drive.first_crossing``).

Usage::

    python examples/thesis_fem.py        # fit E and the FEM column (≈ 1–2 min on 2 cores)
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Dict, Iterable, Optional, Sequence, Tuple

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import thesis_data as td  # noqa: E402
import thesis_drive as tdr  # noqa: E402
import thesis_link as tl  # noqa: E402

import popup  # noqa: E402

ARM = "popup-lab-thesis"
LAMBDA = 3.896e-4
"""Rayleigh λ [s] of the beam: section 2.3's fit-1 value read as ·10⁻⁴ (docs/thesis.md)."""
PRESET = "thesis-1.2mm"
TOL_RES = 0.25
"""Tolerance of the fitted beam's resonances against Tables 13–15's FEM column (relative):
one E cannot place all three (docs/thesis.md)."""
TOL_5_7 = 0.20
"""Tolerance of the engine's FEM column of Tables 5–7 (2 kg) against the thesis's
(relative): the PRBM column on the engine lies within −15 … +4 % of its own."""
FEM_TABLES = (13, 14, 15)
"""Tables whose FEM resonances fix E: gravity off, 2 / 1 / 0 kg."""


def beam_model(e_pa: float, gravity: bool, dt: float = 1e-3, arm: str = ARM) -> popup.Model:
    """``arm`` with link 1 rigid and link 2 a beam of 4 elements (``PRESET``, λ =
    ``LAMBDA``, E = ``e_pa`` [Pa])."""
    return popup.Model(arm, dt=dt, gravity=gravity).with_links("rigid", "beam(4)", preset=PRESET, e_pa=e_pa, lambda_s=LAMBDA)


def fem_resonances(e_pa: float, arm: str = ARM, w: np.ndarray = tl.W) -> np.ndarray:
    """First resonance [rad/s] of the beam link's FRF at 2 / 1 / 0 kg, gravity off."""
    H = tl.engine_frf(beam_model(e_pa, False, arm=arm), [float(td.LINK_FRF[t]["payload"]) for t in FEM_TABLES], w)
    return np.array([tl.extract(w, H[i])[2] for i in range(len(FEM_TABLES))])


def fit_beam_e(arm: str = ARM, w: np.ndarray = tl.W) -> Tuple[float, Tuple[float, float]]:
    """E [Pa] that puts the beam link's first resonance on Tables 13–15's FEM column, least
    squares in ln E, with its 95 % interval (Student t, 2 degrees of freedom)."""
    from scipy.optimize import least_squares
    from scipy.stats import t as student

    th = np.array([td.LINK_FRF[t]["fem"][2] for t in FEM_TABLES])  # type: ignore[index]
    sol = least_squares(lambda x: np.log(fem_resonances(float(np.exp(x[0])), arm, w) / th), [np.log(15e6)], diff_step=1e-3)
    dof = len(th) - 1
    se = math.sqrt(2 * sol.cost / dof / float(sol.jac[:, 0] @ sol.jac[:, 0]))
    q = student.ppf(0.975, dof)
    return float(np.exp(sol.x[0])), (float(np.exp(sol.x[0] - q * se)), float(np.exp(sol.x[0] + q * se)))


def one_link_model(link: str, e_pa: Optional[float] = None, dt: float = 1e-4) -> popup.Model:
    """The one-link plant of Tables 5–7: ``popup-lab-thesis`` with gravity, link 1 rigid,
    link 2 ``"rigid"``, ``"prbm"`` or ``"beam"`` (E = ``e_pa``)."""
    if link == "beam":
        assert e_pa is not None
        return beam_model(e_pa, True, dt=dt)
    return popup.Model(ARM, dt=dt, gravity=True).with_links("rigid", link)


def engine_cutoffs(
    model: popup.Model,
    amplitude: float,
    payloads: Sequence[float],
    w: np.ndarray,
) -> np.ndarray:
    """Cut-off [rad/s] per payload of the q3 velocity loop at sine ``amplitude`` [rad/s]
    over the frequency grid ``w`` (module docstring); nan where the run failed."""
    import thesis_ch78 as c78
    from popup import frequency as fr

    ctrl = c78._controller(td.CH7_VEL, td.CH7_POS, one_link=True)
    ctrl.damping = False
    n = len(payloads)
    f = fr.simulate(model, w, input="velocity", joint="q3", outputs=["dq3"], amplitude=[amplitude] * n, payload_kg=list(payloads), q_motor=c78.ONE_Q0, controller=ctrl)
    g = np.abs(f.H[:, :, 0])
    return np.array([tdr.first_crossing(w, g[b]) for b in range(n)])


def engine_tables_5_7(
    links: Dict[str, popup.Model],
    payloads: Sequence[float] = (2.0, 1.0, 0.0),
    amplitudes: Iterable[float] = td.AMPLITUDES,
    column: Optional[Dict[str, str]] = None,
    npts: int = 15,
) -> Dict[Tuple[str, float, float], float]:
    """Tables 5–7 on the engine: {(link, payload [kg], amplitude [rad/s]): cut-off
    [rad/s]} for each named plant of ``links``; the frequency grid spans half the
    thesis's smallest to three times its largest cut-off of that column (``column[link]``,
    default the link's name: "rigid", "prbm", "fem") at that amplitude, ``npts`` points."""
    out: Dict[Tuple[str, float, float], float] = {}
    for name, m in links.items():
        col = (column or {}).get(name, name)
        for a in amplitudes:
            tg = np.array([td.TABLES_5_7[p][col][a] for p in payloads])
            w = np.geomspace(tg.min() / 2.0, tg.max() * 3.0, npts)
            for p, c in zip(payloads, engine_cutoffs(m, a, payloads, w)):
                out[(name, p, a)] = float(c)
    return out


def main() -> None:
    e, (lo, hi) = fit_beam_e()
    print(f"E fitted to Tables 13-15's FEM resonances on {ARM}: {e / 1e6:.3g} MPa ({lo / 1e6:.3g}-{hi / 1e6:.3g})")
    print("resonances", fem_resonances(e), "thesis", [td.LINK_FRF[t]["fem"][2] for t in FEM_TABLES])
    res = engine_tables_5_7({"fem": one_link_model("beam", e)})
    for (lk, p, a), c in res.items():
        th = td.TABLES_5_7[p]["fem"][a]
        print(f"{lk} {p:g} kg A={a:g}: thesis {th:g}, engine {c:.3g}, ratio {c / th:.3f}")


if __name__ == "__main__":
    main()

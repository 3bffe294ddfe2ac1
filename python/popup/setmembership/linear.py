"""Parameter-uncertainty intervals of structures linear in their parameters (:func:`pui`,
:func:`pui_linear`, :func:`min_bound`)."""

from __future__ import annotations

import math
import time
from typing import Any, List, Optional, Sequence, Tuple

import numpy as np

from ..exceptions import InputError, ParameterError
from .structure import ArrayLike, EpsLike, Structure
from .data import resolve
from .regression import build_regression
from .result import InfeasibleError, PUIResult
from .lp import Scaled, eps_array, residual_scale, run_lp, solve_lp, status_error, thread_count


def pui_core(phi: np.ndarray, y: np.ndarray, eps: EpsLike, names: List[str], *, box: Any = None,
              threads: Optional[int] = None, structure: Optional[Structure] = None, unit: str = "",
              method: str = "", strict: bool = True) -> PUIResult:
    t_all = time.perf_counter()
    n, p = phi.shape
    e = eps_array(eps, n)
    if y.shape != (n,):
        raise InputError(f"y must have shape ({n},), got {y.shape}")
    if not np.all(np.isfinite(phi)) or not np.all(np.isfinite(y)):
        raise InputError("the regression matrix and y must be finite")
    bx = None
    if box is not None:
        lo, hi = (np.broadcast_to(np.asarray(v, dtype=float), (p,)).copy() for v in box)
        if np.any(lo > hi):
            raise ParameterError("box: lower > upper for some parameter")
        bx = (lo, hi)
    S = Scaled(phi, y, e, bx)
    desc = structure.describe() if structure is not None else f"the linear regression ({p} parameters)"
    times: List[float] = []
    nthr = thread_count(threads, 2 * p)
    # 1. minimal bound (minimax fit)
    r0, t0 = solve_lp(*S.minimax_job())
    times.append(t0)
    if r0.status == 2:
        raise InfeasibleError(float(e.max()), math.inf, desc, n, np.full(p, np.nan), unit, "(the prior box excludes every parameter vector)")
    if r0.status != 0:
        raise status_error(r0, "the minimal-bound LP")
    tau = float(r0.x[-1])
    theta_mm = S.theta(r0.x[:p])
    eps_scalar = float(e[0]) if np.all(e == e[0]) else None
    eps_min = tau * (eps_scalar if eps_scalar is not None else float(e.max()))
    if tau > 1.0 + 1e-9:
        raise InfeasibleError(float(e.max()), eps_min, desc, n, theta_mm, unit,
                              "" if eps_scalar is not None else "(per-sample bounds: eps_min scales every bound by the same factor)")
    # 2. the 2p interval LPs, in parallel
    res = run_lp(S.bound_jobs(), nthr)
    zlo = np.empty(p)
    zhi = np.empty(p)
    wit = np.full((2 * p, p), np.nan)
    failed: List[str] = []
    for k, (r, dt_) in enumerate(res):
        times.append(dt_)
        i, sign = divmod(k, 2)
        if r.status == 0:
            val = S.off[i] + float(r.fun) * (1.0 if sign == 0 else -1.0)
            wit[k] = S.theta(r.x)
        elif r.status == 3:
            val = -math.inf if sign == 0 else math.inf
        elif r.status == 2:
            raise InfeasibleError(float(e.max()), eps_min, desc, n, theta_mm, unit,
                                  "(the bound is within the LP tolerance of eps_min: the feasible set is numerically empty)")
        elif not strict:  # numerical failure: fall back on the prior box (or unbounded)
            lim = (bx[0][i] if sign == 0 else bx[1][i]) if bx is not None else (-math.inf if sign == 0 else math.inf)
            val = float(lim) * S.s[i]
            failed.append(names[i])
        else:
            raise status_error(r, f"the bound of {names[i]}")
        (zlo if sign == 0 else zhi)[i] = val
    zhi = np.maximum(zhi, zlo)
    # 3. Chebyshev centre in half-width-normalised coordinates
    job, to_theta1, metric = S.chebyshev_job(zlo, zhi)
    rc, tc = solve_lp(*job)
    times.append(tc)
    notes: List[str] = []
    if rc.status == 0:
        center = to_theta1(rc.x) / S.s
        radius = float(rc.x[-1])
    elif rc.status == 3:
        center = np.full(p, np.nan)
        radius = math.inf
    else:  # numerical failure: fall back on the minimax point
        center = theta_mm.copy()
        radius = math.nan
        notes.append(f"Chebyshev-centre LP failed (HiGHS status {rc.status}): the centre is the minimax point")
    lower, upper = zlo / S.s, zhi / S.s
    return PUIResult(
        names=list(names), lower=lower, upper=upper, center=center, radius=radius, minimax=theta_mm,
        eps=(eps_scalar if eps_scalar is not None else e.copy()), eps_min=eps_min, n=n, n_data=n, structure=structure,
        method=method or "exact: 2p LPs (HiGHS) on the polytope |y - Phi theta| <= eps",
        solve_time=time.perf_counter() - t_all, lp_times=np.asarray(times), threads=nthr, unit=unit, witnesses=wit,
        center_metric=metric,
        notes=notes + ([f"LP failed numerically (HiGHS status 4) for a bound of {', '.join(sorted(set(failed)))}: the prior box (or unbounded) reported"] if failed else []),
    )


def pui_linear(phi: ArrayLike, y: ArrayLike, eps: EpsLike, *, names: Optional[Sequence[str]] = None,
               box: Optional[Tuple[ArrayLike, ArrayLike]] = None, threads: Optional[int] = None) -> PUIResult:
    """PUI of any linear regression ``y = Φ θ + e``, ``|e(t)| <= eps`` (scalar or per
    sample): exact, 2p + 2 LPs.

    Parameters
    ----------
    phi : (n, p) array
    y : (n,) array
    eps : float or (n,) array, > 0
    names : parameter names (default ``theta1..``)
    box : (lower, upper), optional
        Prior bounds on θ (scalars or (p,)), e.g. to keep a poorly excited parameter finite.
    threads : int, optional
        Worker threads for the 2p LPs (default: every core).

    Raises :class:`InfeasibleError` when ``eps`` is below the minimal bound.
    """
    P = np.asarray(phi, dtype=float)
    yy = np.asarray(y, dtype=float)
    if P.ndim != 2:
        raise InputError(f"phi must be (n, p), got shape {P.shape}")
    if P.shape[0] < 1 or P.shape[1] < 1:
        raise InputError(f"phi is empty: shape {P.shape}")
    nm = list(names) if names is not None else [f"theta{i + 1}" for i in range(P.shape[1])]
    if len(nm) != P.shape[1]:
        raise InputError(f"{len(nm)} names for {P.shape[1]} parameters")
    return pui_core(P, yy, eps, nm, box=box, threads=threads)


def min_bound(phi: ArrayLike, y: ArrayLike) -> Tuple[float, np.ndarray]:
    """The minimal bound ``ε_min = min_θ max_t |y(t) − φ(t)ᵀθ|`` and its minimiser (one LP)."""
    P = np.asarray(phi, dtype=float)
    yy = np.asarray(y, dtype=float)
    if P.ndim != 2 or yy.shape != (P.shape[0],):
        raise InputError(f"phi (n, p) and y (n,) expected, got {P.shape} and {yy.shape}")
    scale = residual_scale(P, yy)
    S = Scaled(P, yy, np.full(yy.shape[0], scale), None)
    r, _ = solve_lp(*S.minimax_job())
    if r.status != 0:
        raise status_error(r, "the minimal-bound LP")
    return float(r.x[-1]) * scale, S.theta(r.x[:-1])


def unit_of(name: str) -> str:
    try:
        from ..results import UNITS

        return UNITS.get(name, "")
    except Exception:  # pragma: no cover
        return ""


def pui(data: Any, structure: Structure, eps: EpsLike, *, box: Optional[Tuple[ArrayLike, ArrayLike]] = None,
        threads: Optional[int] = None, skip: int = 0, **window: Any) -> PUIResult:
    """Exact PUI of a FIR or ARX structure.

    Parameters
    ----------
    data : MeasuredRun, SimResult, DataFrame, mapping, IdData or (y, u)
        Channels are taken by the structure's ``inputs``/``output`` names.
    structure : Structure
        From :func:`fir` or :func:`arx`.
    eps : float or (N,) array
        Bound on |e(t)| [output unit] (ARX: on the equation error).
    box : prior bounds on the parameters, optional.
    threads : LP worker threads (default every core).
    skip : int
        Samples left out of the constraints after the lags.
    **window : ``t_start``, ``t_stop``, ``step``, ``derive_rates`` (see :func:`iddata`).
    """
    if structure.kind == "oe":
        raise ParameterError("pui: an OE structure is not linear in its parameters; use oe_pui() (or identify())")
    t = time.perf_counter()
    d = resolve(data, structure, **window)
    reg = build_regression(structure, d.y, d.u, skip)
    e = np.asarray(eps, dtype=float)
    if e.ndim == 1 and e.shape[0] == len(d):
        e = e[reg.rows]
    r = pui_core(reg.phi, reg.y, e, reg.names, box=box, threads=threads, structure=structure, unit=unit_of(d.output),
                  method=f"exact: {2 * structure.n_params + 2} LPs (HiGHS) on the polytope |y - Phi theta| <= eps ({structure.kind.upper()})")
    r.n_data, r.dt, r.notes = len(d), d.dt, list(d.notes)
    r.solve_time = time.perf_counter() - t
    return r

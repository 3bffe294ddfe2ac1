"""Fitting effect parameters to a :class:`~popup.problem.ReplayProblem`: the one
objective, multi-start, intervals and identifiability, shared by :func:`popup.diagnose`,
:func:`popup.improve` and :func:`popup.fit_params`.

Objective
---------
Gaussian maximum likelihood with an unknown noise variance per channel: the profile
log-likelihood of the training samples is ``ℓ = −½ Σ_c n_c ln(mean z_c²)`` (z in noise
units, :mod:`popup.problem`). It is maximised by iteratively reweighted least squares:
bounded trust-region-reflective least squares (``scipy.optimize.least_squares``) on
``z_c / sqrt(v_c)`` with ``v_c = max(mean z_c², 1)`` at the start, then once more with
``v_c`` at the optimum when that changed a weight by more than 2×. A channel's weight is
so the inverse of its whole residual variance: a channel the model cannot explain at all
does not drag the fit, and channels at their noise floor weigh by their noise. The
Jacobian is by forward differences, every column in one batched rollout.

Comparing two models (likelihood ratio, :func:`log_ratio`):
``LR = Σ_c n_eff,c ln(mean z²_c,before / mean z²_c,after)`` with the effective sample
count ``n_eff,c = n_c (1 − ρ_c)/(1 + ρ_c)`` (ρ_c the lag-1 autocorrelation of channel
c's residual after the fit: a free-run residual is not n independent samples).

Intervals and identifiability (:func:`uncertainty`)
--------------------------------------------------
Gauss–Newton covariance ``s² (JᵀJ)⁻¹`` of the weighted problem, inflated by ``n/n_eff``,
or the delete-one-block jackknife variance over :data:`JACKKNIFE_BLOCKS` time blocks
where that is larger (a residual that is not white everywhere); 95 % half-widths.
Before reporting them, the scaled Fisher matrix is checked: its rank and condition
number, the correlations between parameters, parameters at a bound and parameters whose
interval is wider than their own scale. Such parameters are listed as
not identifiable from this run (their interval is reported as ``inf``), instead of a
tight local interval the data cannot support.

Parameters that span decades (:data:`LOG_PARAMS`, e.g. a torsional stiffness from a
soft 5 N·m/rad to a nearly rigid 1.5e4 N·m/rad) are fitted as their logarithm (steps and
trust region in e-folds); values, intervals and the returned Jacobian are in the
parameter's own units. A parameter whose effect grows as it moves below its upper bound
over decades (:data:`LOG_GAP_PARAMS`: wrinkling's stiffness ratio, from a softening of
1e-4, 0.9999, to 0.01) is fitted as the logarithm of that distance, the solver's lower
bound standing for the upper bound itself (no effect): in the ratio itself the solver's
steps (its 0.3 scale, a start nudged off the bound by a fifth of it) jump over a softening
of 7e-4 whose objective is a few 1e-4 wide.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from . import effects as fx
from .problem import ReplayProblem

__all__ = [
    "PARAM_SCALE",
    "SEEDS",
    "BOUNDS",
    "LOG_PARAMS",
    "LOG_GAP_PARAMS",
    "FitOutcome",
    "free_params",
    "params_dict",
    "fit",
    "seed_points",
    "best_start",
    "log_ratio",
    "n_eff",
    "SCORE_THRESHOLD",
    "uncertainty",
    "MAX_ITER_LIMIT",
    "check_max_iter",
]

#: Typical magnitude of each fitted parameter (finite-difference steps and x_scale).
PARAM_SCALE: Dict[Tuple[str, str], float] = {
    ("joint_friction", "tau_c"): 1.0,
    ("joint_friction", "b"): 0.5,
    ("joint_friction", "tau_s"): 1.0,
    ("joint_friction", "v_s"): 0.05,
    ("joint_friction", "v_eps"): 1.0,  # fitted as ln v_eps (LOG_PARAMS)
    ("backlash", "gap"): 1e-3,
    ("backlash", "inertia"): 1.0,  # fitted as ln J (LOG_PARAMS)
    ("backlash", "contact_k"): 1.0,  # fitted as ln k_c (LOG_PARAMS)
    ("backlash", "contact_c"): 10.0,
    ("higher_bending_modes", "k_scale"): 0.5,
    ("higher_bending_modes", "root_ratio"): 1.0,  # fitted as ln r (LOG_PARAMS)
    ("higher_bending_modes", "e_pa"): 1e8,
    ("higher_bending_modes", "lambda_s"): 1e-4,
    ("pressure_leak", "rate"): 0.01,
    ("wrinkling", "ratio"): 0.3,
    ("wrinkling", "mw_scale"): 0.3,
    ("payload_mass", "delta_kg"): 0.3,
    ("payload_mass", "com_offset_m"): 0.02,
    ("sensor_delay", "imu"): 0.005,
    ("sensor_delay", "encoder"): 0.005,
    ("sensor_delay", "torque"): 0.005,
    ("sensor_delay", "mocap"): 0.005,
    ("actuator_saturation", "tau_max"): 2.0,
    ("air_drag", "cd"): 1.0,
    ("torsion", "k_t"): 100.0,  # fitted as ln k_t (LOG_PARAMS)
    ("torsion", "c_t"): 0.5,
}

#: Starting points tried (one batched rollout) before the fit: the effects are not convex
#: in their parameters (thresholds, dead zones, delays, masses that move a resonance); a
#: number applies to every joint/link entry of the parameter, a list gives one per entry.
SEEDS: Dict[str, List[Dict[str, Any]]] = {
    "joint_friction": [{"tau_c": 0.5, "b": 0.1}, {"tau_c": 2.0, "b": 0.5}, {"tau_c": 0.2, "b": 1.0}],
    "backlash": [{"gap": g} for g in (1e-4, 3e-4, 1e-3, 3e-3, 0.01, 0.03)],
    "pressure_leak": [{"rate": 0.005}, {"rate": 0.05}],
    "wrinkling": [{"ratio": r, "mw_scale": m} for r in (0.3, 0.6, 0.99, 0.999) for m in (0.4, 0.7, 1.0)],
    "payload_mass": [{"delta_kg": d} for d in (-1.0, -0.6, -0.3, -0.15, 0.15, 0.3, 0.6, 1.0, 1.5)],
    "sensor_delay": [{"imu": d, "torque": d, "mocap": d} for d in (0.003, 0.01, 0.02, 0.05)],
    "air_drag": [{"cd": 1.0}, {"cd": 5.0}, {"cd": 20.0}],
    # one link compliant, the other nearly rigid (the upper bound), or both; soft to stiff
    # (an entry a structure makes rigid is not fitted: diagnosis's one-link variants)
    "torsion": [{"k_t": [k1, k2], "c_t": 0.2} for k1, k2 in
                [(k, math.inf) for k in (50.0, 200.0, 800.0, 3000.0, 10000.0)] + [(math.inf, k) for k in (50.0, 200.0, 800.0, 3000.0, 10000.0)]
                + [(100.0, 100.0), (500.0, 500.0), (3000.0, 3000.0)]],
    "higher_bending_modes": [{"k_scale": [a, b]} for a, b in ((0.5, 0.5), (1.0, 1.0), (2.0, 2.0), (1.0, 3.0), (3.0, 1.0))],
}

#: Bounds the diagnosis fits within where they are narrower than the registry's: the
#: physically plausible range of a parameter whose registry range reaches far into
#: configurations that need a much smaller step (a torsional damper of 10⁴ N·m·s/rad is an
#: overdamped, stiff mode; the diagnosis would spend its time on it).
BOUNDS: Dict[Tuple[str, str], Tuple[float, float]] = {
    ("torsion", "k_t"): (5.0, 1.5e4),
    ("torsion", "c_t"): (0.0, 2.0),
    ("higher_bending_modes", "k_scale"): (0.1, 5.0),
    # a gear's link side: from an output flange alone to a whole motoreducer's reflected
    # inertia (below 1e-3 kg·m² its free mode needs a step far below a lab rate)
    ("backlash", "inertia"): (1e-3, 1.0),
    # a compliant gear's flanks: from a soft coupling to a stiff harmonic drive's
    # 1e5 N·m/rad; stiffer contacts ring far above a lab rate (and need a tiny step), which
    # the rigid flanks stand for; the damping up to critical for the stiffest flank on a
    # 0.025 kg·m² link side (ζ = 0.5 on 0.1 kg·m²). It was 50 N·m·s/rad: MuJoCo single 742
    # backlash-000 (0.1 kg·m², ζ = 0.5: 68.7) was fitted at 48 and left 14.2 noise units where
    # its truth replays at 1.67 (benchmarks/README.md, session 68); the variant's step is set
    # at a lower damping (diagnosis.rules.FLANK_CHECK_DAMPING), where the step is largest
    ("backlash", "contact_k"): (1e3, 1e5),
    ("backlash", "contact_c"): (0.0, 100.0),
    # the friction sign's width: below ~5e-4 rad/s it is narrower than the velocity noise of
    # a smoothed lab encoder (the sign would flip with the noise), above 0.3 rad/s it is viscous
    ("joint_friction", "v_eps"): (5e-4, 0.3),
    # a link's root joint from half to 8 × its outer joints (4 = a uniform cantilever's split
    # for 2 segments); stiffer roots need ever smaller steps for what they add
    ("higher_bending_modes", "root_ratio"): (0.5, 8.0),
}

#: Positive parameters fitted as their logarithm (module docs).
LOG_PARAMS = {("torsion", "k_t"), ("backlash", "inertia"), ("backlash", "contact_k"), ("joint_friction", "v_eps"), ("higher_bending_modes", "root_ratio")}

#: Parameters at most their upper bound, fitted as the logarithm of their distance below it:
#: a wrinkled stiffness ratio from 0.01 to a softening of 1e-4 (0.9999), which a
#: fit in the ratio itself (steps of its 0.3 scale) jumps over (module docs).
LOG_GAP_PARAMS = {("wrinkling", "ratio")}

#: The smallest distance below the upper bound a :data:`LOG_GAP_PARAMS` entry resolves, as a
#: fraction of its range; the solver's bound there stands for the upper bound itself.
LOG_GAP_MIN = 1e-7

_NUDGE = 0.2


def _is_log(p: fx.EffectParam) -> bool:
    return (p.effect, p.name) in LOG_PARAMS


def _is_log_gap(p: fx.EffectParam) -> bool:
    return (p.effect, p.name) in LOG_GAP_PARAMS


@dataclass
class FitOutcome:
    """A fit of ``free`` entries: values, the full flat vector, residuals (n, C) in noise
    units, the weighted training Jacobian, channel weights and rollouts used."""

    x: np.ndarray
    flat: np.ndarray
    z: np.ndarray
    J: np.ndarray
    weights: np.ndarray
    nfev: int
    starts: List[np.ndarray] = field(default_factory=list)
    r: np.ndarray = field(default_factory=lambda: np.zeros(0))  # weighted training residual (rows of J)
    row_t: np.ndarray = field(default_factory=lambda: np.zeros(0))  # time [s] of each row of J
    start_values: List[float] = field(default_factory=list)


def free_params(effect: str, only: Optional[Sequence[str]] = None) -> List[Tuple[fx.EffectParam, int]]:
    """(parameter, entry) pairs fitted for ``effect``: its ``fit`` parameters, or ``only``;
    bounds narrowed to :data:`BOUNDS` where it has them."""
    out: List[Tuple[fx.EffectParam, int]] = []
    for p in fx.EFFECTS[effect].params.values():
        if (only is None and p.fit) or (only is not None and p.name in only):
            b = BOUNDS.get((effect, p.name))
            if b is not None:
                p = dataclasses.replace(p, lower=max(p.lower, b[0]), upper=min(p.upper, b[1]))
            out.extend((p, i) for i in range(p.length))
    return out


def params_dict(effect: str, flat: np.ndarray) -> Dict[str, List[float]]:
    """``{param: values}`` of ``effect`` in a flat vector."""
    return {k: [float(x) for x in flat[p.slice]] for k, p in fx.EFFECTS[effect].params.items()}


def _weights(ms: np.ndarray) -> np.ndarray:
    return 1.0 / np.sqrt(np.maximum(np.where(np.isfinite(ms), ms, 1.0), 1.0))


MAX_ITER_LIMIT = 10**6
"""Most solver evaluations per start a caller may ask for (``max_iter``)."""


def check_max_iter(max_iter: Any) -> int:
    """``max_iter`` as an int: a count of solver evaluations per start from 0 (the starts
    evaluated, not moved) to :data:`MAX_ITER_LIMIT`; anything else is an InputError naming it."""
    from .model import check_count

    return check_count("max_iter", max_iter, 0, MAX_ITER_LIMIT, "solver evaluations per start")


def fit(
    prob: ReplayProblem,
    base_flat: np.ndarray,
    free: List[Tuple[fx.EffectParam, int]],
    x0: np.ndarray,
    max_iter: int,
    *,
    scale: Optional[np.ndarray] = None,
    mask: Optional[np.ndarray] = None,
    tie: Optional[Sequence[Sequence[int]]] = None,
) -> FitOutcome:
    """Maximum-likelihood fit of the ``free`` entries (module docs) on the samples of
    ``mask`` (default: the problem's training samples). ``tie``: groups of positions in
    ``free`` (entries of one parameter) fitted as one value, started from their mean
    (:func:`tied`); the outcome's ``x`` has every entry, its ``J`` one column per group."""
    from scipy.optimize import least_squares

    train = prob.train if mask is None else mask
    groups = tie_groups(len(free), tie)
    rep = np.empty(len(free), dtype=int)
    for u, g in enumerate(groups):
        rep[g] = u
    free_all, free = free, [free[g[0]] for g in groups]
    lg = np.array([_is_log(p) for p, _ in free], dtype=bool)
    lu = np.array([_is_log_gap(p) for p, _ in free], dtype=bool)
    lo_v = np.array([p.lower for p, _ in free])
    hi_v = np.array([p.upper for p, _ in free])
    sc_v = np.array([PARAM_SCALE.get((p.effect, p.name), 1.0) for p, _ in free]) if scale is None else np.asarray(scale, dtype=float)[[g[0] for g in groups]]
    # the solver's variables: ln v for LOG_PARAMS entries, ln(upper − v) for LOG_GAP_PARAMS
    # entries (scale: one e-fold; the solver's lower bound there is v = upper), else v
    gap_min = np.where(lu, LOG_GAP_MIN * np.where(lu & np.isfinite(hi_v - lo_v), hi_v - lo_v, 1.0), 1.0)
    gap_lo = np.log(gap_min)

    def to_s(v: np.ndarray) -> np.ndarray:
        v = np.asarray(v, dtype=float)
        gap = np.log(np.where(lu, np.maximum(np.where(lu, hi_v, 0.0) - v, gap_min), 1.0))
        return np.where(lg, np.log(np.where(lg, np.clip(v, 1e-300, 1e300), 1.0)), np.where(lu, gap, v))

    def to_v(x: np.ndarray) -> np.ndarray:
        gap = np.where(lu & (x > gap_lo), np.exp(np.where(lu, x, 0.0)), 0.0)
        return np.where(lg, np.exp(np.where(lg, x, 0.0)), np.where(lu, hi_v - gap, x))

    lo = np.where(lu, gap_lo, to_s(lo_v))
    hi = np.where(lu, np.log(np.where(lu, np.maximum(hi_v - lo_v, gap_min), 1.0)), to_s(hi_v))
    sc = np.where(lg | lu, 1.0, sc_v)

    idx = np.array([p.offset + i for p, i in free_all], dtype=int)
    # a start on a bound stalls the trust-region-reflective steps (their scaling is the
    # distance to the bound): start a fraction of the typical scale inside
    fin_lo = np.where(np.isfinite(lo), lo, -1e300)
    fin_hi = np.where(np.isfinite(hi), hi, 1e300)
    nudge = np.minimum(_NUDGE * sc, 0.5 * (fin_hi - fin_lo))
    x_given = to_s(tied(free_all, x0, groups)[[g[0] for g in groups]])
    x0 = np.clip(x_given, fin_lo + nudge, fin_hi - nudge)
    cache: Dict[bytes, np.ndarray] = {}
    n0 = prob.nfev

    def flat_of(x: np.ndarray) -> np.ndarray:
        f = np.array(base_flat, dtype=float)
        f[idx] = to_v(x)[rep]
        return f

    def eval_batch(xs: List[np.ndarray]) -> List[np.ndarray]:
        todo = [x for x in xs if x.tobytes() not in cache]
        if todo:
            z = prob.residuals(prob.simulate(np.array([flat_of(x) for x in todo])))
            for x, zz in zip(todo, z):
                cache[x.tobytes()] = zz
        return [cache[x.tobytes()] for x in xs]

    def vec(z: np.ndarray, w: np.ndarray) -> np.ndarray:
        r = z[train] * w[None, :]
        failed = not np.isfinite(z).any()
        if failed:
            return np.full(r.size, 1e3)
        return np.where(np.isfinite(r), r, 0.0).reshape(-1)

    def solve(x_start: np.ndarray, w: np.ndarray, nfev: int) -> np.ndarray:
        def fun(x: np.ndarray) -> np.ndarray:
            return vec(eval_batch([np.asarray(x, dtype=float)])[0], w)

        def jac(x: np.ndarray) -> np.ndarray:
            return _jac(np.asarray(x, dtype=float), w)

        if nfev <= 0:  # max_iter = 0: the start is evaluated, not moved
            return x_start
        sol = least_squares(fun, x_start, jac=jac, bounds=(lo, hi), x_scale=sc, method="trf", max_nfev=nfev, xtol=1e-6, ftol=1e-6, gtol=1e-8)
        return np.asarray(sol.x, dtype=float)

    def _jac(x: np.ndarray, w: np.ndarray) -> np.ndarray:
        pts, hs = [], []
        for j in range(len(x)):
            h = 1e-4 * max(sc[j], abs(x[j]) * 0.1)
            if x[j] + h > hi[j]:
                h = -h
            xp = x.copy()
            xp[j] += h
            pts.append(xp)
            hs.append(h)
        z0, *zs = eval_batch([x] + pts)
        r0 = vec(z0, w)
        J = np.empty((r0.size, len(x)))
        for j, (zj, h) in enumerate(zip(zs, hs)):
            J[:, j] = (vec(zj, w) - r0) / h
        return J

    ms0, _, _ = prob.channel_stats(eval_batch([x0])[0], train)
    w = _weights(ms0)
    x = solve(x0, w, max_iter)
    ms1, _, _ = prob.channel_stats(eval_batch([x])[0], train)
    w1 = _weights(ms1)
    if max_iter > 0 and np.all(np.isfinite(ms1)) and np.any(np.abs(np.log(w1 / w)) > math.log(2.0)):
        w = w1
        x = solve(x, w, max(5, max_iter // 2))
    # never worse than the start as given: the nudge off a bound moves an entry by a fifth
    # of its scale (a sensor delay fitted at 3 µs starts again at 1 ms), and from there the
    # solver can end in a worse basin than the one it was handed
    if np.all((x_given >= lo) & (x_given <= hi)) and not np.array_equal(x, x_given):
        zg, zx = eval_batch([x_given, x])
        if _nll(prob, zg, train) < _nll(prob, zx, train):
            x = x_given
    z = eval_batch([x])[0]
    ms, _, _ = prob.channel_stats(z, train)
    w = _weights(ms)
    v = to_v(x)
    # the Jacobian in the parameters' own units: d/dv = (1/v) d/d(ln v)
    dsdv = np.where(lg, 1.0 / np.where(lg, v, 1.0), np.where(lu, -1.0 / np.maximum(np.where(lu, hi_v, 0.0) - v, gap_min), 1.0))
    J = _jac(x, w) * dsdv[None, :]
    row_t = np.repeat(np.asarray(prob.time, dtype=float)[train], z.shape[1])
    return FitOutcome(x=v[rep], flat=flat_of(x), z=z, J=J, weights=w, nfev=prob.nfev - n0, r=vec(z, w), row_t=row_t)


def tied(free: List[Tuple[fx.EffectParam, int]], x: np.ndarray, groups: Sequence[Sequence[int]]) -> np.ndarray:
    """``x`` (values of ``free``) with every entry of a group of two or more at the group's
    mean (geometric for a parameter fitted as its logarithm)."""
    out = np.array(x, dtype=float)
    for g in groups:
        if len(g) > 1:
            g = list(g)
            out[g] = math.exp(float(np.mean(np.log(np.clip(out[g], 1e-300, 1e300))))) if _is_log(free[g[0]][0]) else float(np.mean(out[g]))
    return out


def tie_groups(n: int, tie: Optional[Sequence[Sequence[int]]]) -> List[List[int]]:
    """The groups of positions ``0..n-1`` fitted as one value: each group of ``tie`` (in the
    order of its first position), every other position alone; an InputError where a position
    is out of range or in two groups."""
    from .exceptions import InputError

    owner: Dict[int, int] = {}
    for k, g in enumerate(tie or []):
        for j in g:
            if not 0 <= int(j) < n or int(j) in owner:
                raise InputError(f"tie: position {j} of group {k} is {'out of range 0..' + str(n - 1) if not 0 <= int(j) < n else 'in two groups'}")
            owner[int(j)] = k
    out: List[List[int]] = []
    seen: Dict[int, int] = {}
    for j in range(n):
        grp = owner.get(j)
        if grp is None:
            out.append([j])
        elif grp in seen:
            out[seen[grp]].append(j)
        else:
            seen[grp] = len(out)
            out.append([j])
    return out


def _nll(prob: ReplayProblem, z: np.ndarray, train: np.ndarray) -> float:
    """``Σ_c n_c ln mean z²`` over the samples ``train`` (the profile negative
    log-likelihood up to constants; lower is better; inf for a failed run)."""
    ms, n, _ = prob.channel_stats(z, train)
    return float(np.sum(n * np.log(np.maximum(ms, 1e-300)))) if np.all(np.isfinite(ms)) else math.inf


def seed_points(effect: str, free: List[Tuple[fx.EffectParam, int]], x0: np.ndarray, extra: Optional[List[Dict[str, Any]]] = None) -> List[np.ndarray]:
    """``x0`` and the effect's :data:`SEEDS` (plus ``extra``) as start vectors."""
    cands = [np.asarray(x0, dtype=float)]
    for seed in list(SEEDS.get(effect, [])) + list(extra or []):
        x = cands[0].copy()
        for j, (p, i) in enumerate(free):
            if p.effect == effect and p.name in seed:
                v = seed[p.name]
                v = float(v[i]) if np.ndim(v) else float(v)
                x[j] = min(max(v, p.lower), p.upper)
        cands.append(x)
    return cands


def best_start(prob: ReplayProblem, free: List[Tuple[fx.EffectParam, int]], flat: np.ndarray, cands: List[np.ndarray]) -> Tuple[np.ndarray, List[float]]:
    """The candidate start with the highest training likelihood (one batched rollout),
    and every candidate's ``Σ_c n_c ln mean z²`` (lower is better; inf for a failed run)."""
    if len(cands) == 1:
        return cands[0], [math.nan]
    idx = np.array([p.offset + i for p, i in free], dtype=int)
    flats = np.repeat(np.asarray(flat, dtype=float)[None], len(cands), axis=0)
    flats[:, idx] = np.array(cands)
    z = prob.residuals(prob.simulate(flats))
    vals = [_nll(prob, zz, prob.train) for zz in z]
    return cands[int(np.argmin(vals))], vals


def n_eff(n: np.ndarray, rho: np.ndarray) -> np.ndarray:
    """Effective sample counts ``n (1 − ρ)/(1 + ρ)`` (ρ clipped to [0, 0.999])."""
    r = np.clip(np.nan_to_num(rho, nan=0.0), 0.0, 0.999)
    return n * (1.0 - r) / (1.0 + r)


SCORE_THRESHOLD = 10.0
"""BIC improvement (with the effective sample count) above which an effect is significant:
``LR − k ln n_eff > SCORE_THRESHOLD`` for k fitted parameters."""


def log_ratio(prob: ReplayProblem, z_before: np.ndarray, z_after: np.ndarray, mask: np.ndarray) -> Tuple[float, float]:
    """Likelihood ratio statistic ``Σ_c n_eff,c ln(ms_before/ms_after)`` on ``mask`` and the
    total effective sample count (module docs)."""
    ms0, _, _ = prob.channel_stats(z_before, mask)
    ms1, n, rho = prob.channel_stats(z_after, mask)
    if not (np.all(np.isfinite(ms0)) and np.all(np.isfinite(ms1))):
        return -math.inf, float(np.sum(n))
    ne = n_eff(n, rho)
    # two logarithms, not the log of a ratio: a channel recorded without noise (a simulator's
    # exact pressure) and replayed exactly has ms = 0, and ms0/1e-300 overflows
    lr = float(np.sum(ne * (np.log(np.maximum(ms0, 1e-300)) - np.log(np.maximum(ms1, 1e-300)))))
    return lr, max(float(np.sum(ne)), 1.0)


#: Contiguous time blocks of the training rows deleted in turn by the jackknife.
JACKKNIFE_BLOCKS = 20


def _jackknife_var(Js: np.ndarray, r: np.ndarray, row_t: np.ndarray) -> np.ndarray:
    """Delete-one-block jackknife variances of the (scaled) parameters from one
    Gauss-Newton step per block: δ_b = (A − A_b)⁻¹ J_bᵀ r_b (Jᵀr = 0 at the optimum),
    V = (B − 1)/B Σ_b (δ_b − δ̄)² (scaled to the Student-t point of B − 1 degrees of
    freedom). Zeros when the rows are not known."""
    k = Js.shape[1]
    if k == 0 or r.size != Js.shape[0] or row_t.size != Js.shape[0]:
        return np.zeros(k)
    edges = np.quantile(row_t, np.linspace(0.0, 1.0, JACKKNIFE_BLOCKS + 1))
    b = np.clip(np.searchsorted(edges, row_t, side="right") - 1, 0, JACKKNIFE_BLOCKS - 1)
    A = Js.T @ Js
    deltas = []
    for i in range(JACKKNIFE_BLOCKS):
        m = b == i
        if not m.any():
            continue
        Jb = Js[m]
        try:
            deltas.append(np.linalg.lstsq(A - Jb.T @ Jb, Jb.T @ r[m], rcond=None)[0])
        except np.linalg.LinAlgError:
            return np.zeros(k)
    if len(deltas) < 3:
        return np.zeros(k)
    d = np.array(deltas)
    B = d.shape[0]
    v = (B - 1) / B * np.sum((d - d.mean(axis=0)) ** 2, axis=0)
    # a variance from B blocks has B − 1 degrees of freedom: scaled so that 1.96 σ is the
    # Student-t 97.5 % point
    from scipy.stats import t as student_t

    v = v * (float(student_t.ppf(0.975, B - 1)) / 1.96) ** 2
    return np.where(np.isfinite(v), v, 0.0)


def uncertainty(
    outcome: FitOutcome,
    free: List[Tuple[fx.EffectParam, int]],
    names: Sequence[str],
    neff: float,
    scale: Optional[np.ndarray] = None,
) -> Tuple[np.ndarray, Dict[str, Any]]:
    """95 % half-widths (``inf`` for parameters the run cannot pin down) and the
    identifiability report: ``rank``, ``condition``, ``correlated`` (pairs with
    |ρ| > 0.95), ``at_bound``, ``unidentifiable`` (names) and ``text``."""
    J = outcome.J
    k = J.shape[1]
    n = J.shape[0]
    sc = np.array([PARAM_SCALE.get((p.effect, p.name), 1.0) for p, _ in free]) if scale is None else np.asarray(scale, float)
    s2 = 1.0  # the weights make the training residual's variance 1 per channel
    inflate = max(n / max(neff, 1.0), 1.0)
    Js = J * sc[None, :]
    F = Js.T @ Js
    sv = np.linalg.svd(Js, compute_uv=False) if k else np.zeros(0)
    tol = (sv[0] if sv.size else 0.0) * max(Js.shape) * np.finfo(float).eps * 1e4
    rank = int(np.sum(sv > tol)) if sv.size else 0
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    try:
        cov_s = np.linalg.pinv(F) * s2 * inflate
    except np.linalg.LinAlgError:
        cov_s = np.full((k, k), np.inf)
    var = np.clip(np.diag(cov_s), 0.0, None)
    # a block jackknife (one Gauss-Newton step per deleted block of time) as well: it sees
    # what the Gauss-Newton covariance assumes away (a residual that is not white noise
    # everywhere, a model error that varies along the run); the wider of the two is kept
    var = np.maximum(var, _jackknife_var(Js, outcome.r, outcome.row_t))
    half = 1.96 * np.sqrt(var) * sc
    d = np.sqrt(np.where(var > 0, var, np.nan))
    corr = cov_s / np.outer(d, d)
    lo = np.array([p.lower for p, _ in free])
    hi = np.array([p.upper for p, _ in free])
    x = outcome.x
    at_bound = [names[j] for j in range(k) if (np.isfinite(lo[j]) and abs(x[j] - lo[j]) <= 1e-3 * sc[j]) or (np.isfinite(hi[j]) and abs(hi[j] - x[j]) <= 1e-3 * sc[j])]
    col = np.linalg.norm(Js, axis=0)
    bad = set()
    for j in range(k):
        if not col[j] > 1e-9 * max(float(np.max(col)) if k else 0.0, 1e-300):
            bad.add(j)  # the run does not see this parameter at all
        elif half[j] > max(abs(x[j]), sc[j]) * 2.0:
            bad.add(j)
    pairs = []
    for a in range(k):
        for b in range(a + 1, k):
            c = corr[a, b]
            if np.isfinite(c) and abs(c) > 0.95:
                pairs.append((names[a], names[b], float(c)))
                if abs(c) > 0.995:
                    bad.update((a, b))
    if rank < k:
        # the weakest directions of a rank-deficient problem
        _, _, vt = np.linalg.svd(Js, full_matrices=False)
        for v in vt[rank:]:
            bad.add(int(np.argmax(np.abs(v))))
    half = np.array([math.inf if j in bad else float(h) for j, h in enumerate(half)])
    unident = [names[j] for j in sorted(bad)]
    parts = []
    if unident:
        parts.append(f"not identifiable from this run: {', '.join(unident)}")
    if pairs:
        parts.append("strongly correlated: " + ", ".join(f"{a}~{b} ({c:+.3f})" for a, b, c in pairs))
    if at_bound:
        parts.append(f"at a bound: {', '.join(at_bound)}")
    info = {
        "rank": rank,
        "n_params": k,
        "condition": cond,
        "correlated": [list(p) for p in pairs],
        "at_bound": at_bound,
        "unidentifiable": unident,
        "text": "; ".join(parts) if parts else f"all {k} parameter(s) identifiable (rank {rank}, condition {cond:.3g})",
    }
    return half, info

"""Output-error structures (:func:`oe_pui`): the simulated response, the denominators swept,
and :func:`identify`."""

from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union
from scipy.signal import lfilter

import numpy as np

from ..exceptions import InputError, ParameterError
from .structure import ArrayLike, EpsLike, Structure
from .data import resolve
from .regression import build_regression, shift
from .result import InfeasibleError, PUIResult
from .lp import minimax, thread_count
from .linear import pui, pui_core, unit_of


# ============================================================== output error
def _poly_stable(f: np.ndarray, margin: float = 1e-9) -> bool:
    if f.size == 0:
        return True
    return bool(np.all(np.abs(np.roots(np.r_[1.0, f])) < 1.0 - margin))


def _reflect(f: np.ndarray) -> np.ndarray:
    """Monic polynomial with the roots outside (or on) the unit circle reflected inside."""
    if f.size == 0:
        return f
    r = np.roots(np.r_[1.0, f])
    a = np.abs(r)
    r = np.where(a > 1.0, r / np.maximum(a, 1e-300) ** 2, r)  # 1/conj(r): same spectrum magnitude
    a = np.abs(r)
    r = np.where(a > 0.999, r * (0.999 / np.maximum(a, 1e-300)), r)
    return np.real(np.poly(r))[1:]


def simulate(structure: Structure, theta: ArrayLike, u: ArrayLike, e: Optional[ArrayLike] = None) -> np.ndarray:
    """The output of a structure from rest, (N,).

    * FIR: ``y = Σ B_j u_j + c + e``;
    * ARX: ``A y = Σ B_j u_j + c + e`` (``e`` the equation error);
    * OE: ``y = Σ B_j/F_j (u_j − u_j(0)) + c + e`` (the inputs as deviations from their
      first sample, the convention of :func:`oe_pui`).

    ``u``: (N,) or (N, m); ``e``: optional (N,) noise.
    """
    s = structure
    pc = s.split(theta)
    uu = np.asarray(u, dtype=float)
    if uu.ndim == 1:
        uu = uu[:, None]
    if uu.ndim != 2 or uu.shape[1] != s.n_inputs:
        raise InputError(f"u must be (N, {s.n_inputs}), got shape {np.shape(u)}")
    N = uu.shape[0]
    ee = np.zeros(N) if e is None else np.asarray(e, dtype=float)
    if ee.shape != (N,):
        raise InputError(f"e must have shape ({N},), got {ee.shape}")
    if s.kind == "oe":
        y = np.full(N, pc["c"]) + ee
        for j, name in enumerate(s.inputs):
            x = lfilter(np.r_[np.zeros(s.nk[j]), pc["b"][name]], np.r_[1.0, pc["f"][name]], uu[:, j] - uu[0, j])
            y = y + x
        return y
    v = np.full(N, pc["c"]) + ee
    for j, name in enumerate(s.inputs):
        if s.nb[j]:
            v = v + lfilter(np.r_[np.zeros(s.nk[j]), pc["b"][name]], [1.0], uu[:, j])
    if s.kind == "arx":
        return lfilter([1.0], np.r_[1.0, pc["a"]], v)
    return v


class _OE:
    """Pieces of the OE problem on fixed data (inputs as deviations, from rest)."""

    def __init__(self, s: Structure, y: np.ndarray, u: np.ndarray, skip: int) -> None:
        self.s = s
        self.y = y
        self.du = u - u[0]
        self.rows = np.arange(int(skip), y.shape[0])
        self.nb_total = sum(s.nb)
        self.nf_total = sum(s.nf)

    def numerator_regression(self, F: List[np.ndarray]) -> Tuple[np.ndarray, List[np.ndarray]]:
        """Columns q^-(nk+k)/F_j u_j (all rows) and the filtered inputs v_j = u_j/F_j."""
        s = self.s
        cols = []
        vs = []
        for j in range(s.n_inputs):
            v = lfilter([1.0], np.r_[1.0, F[j]], self.du[:, j])
            vs.append(v)
            for k in range(s.nb[j]):
                cols.append(shift(v, s.nk[j] + k))
        if s.offset:
            cols.append(np.ones_like(self.y))
        return np.column_stack(cols), vs

    def outputs(self, F: List[np.ndarray], theta_bc: np.ndarray) -> Tuple[np.ndarray, List[np.ndarray]]:
        """ŷ and the per-input contributions x_j for denominators F and (b, c)."""
        s = self.s
        xs = []
        i = 0
        yhat = np.full_like(self.y, theta_bc[-1] if s.offset else 0.0)
        for j in range(s.n_inputs):
            b = theta_bc[i : i + s.nb[j]]
            i += s.nb[j]
            x = lfilter(np.r_[np.zeros(s.nk[j]), b], np.r_[1.0, F[j]], self.du[:, j])
            xs.append(x)
            yhat = yhat + x
        return yhat, xs

    def sensitivity(self, F: List[np.ndarray], xs: List[np.ndarray]) -> np.ndarray:
        """∂ŷ/∂f_ji = −q^-i x_j / F_j, (N, nf_total)."""
        cols = []
        for j in range(self.s.n_inputs):
            if self.s.nf[j] == 0:
                continue
            g = lfilter([1.0], np.r_[1.0, F[j]], xs[j])
            for i in range(1, self.s.nf[j] + 1):
                cols.append(-shift(g, i))
        return np.column_stack(cols) if cols else np.zeros((self.y.shape[0], 0))

    def bc_names(self) -> List[str]:
        return [n for n in self.s.names if not n.startswith("f_")]

    def f_names(self) -> List[str]:
        return [n for n in self.s.names if n.startswith("f_")]

    def split_f(self, f: np.ndarray) -> List[np.ndarray]:
        out = []
        i = 0
        for j in range(self.s.n_inputs):
            out.append(np.asarray(f[i : i + self.s.nf[j]], dtype=float))
            i += self.s.nf[j]
        return out


def oe_pui(data: Any, structure: Structure, eps: float, *, denominators: Optional[Union[Mapping[str, ArrayLike], Sequence[ArrayLike]]] = None,
           iterations: int = 30, tol: float = 1e-3, sweep: int = 0, seed: int = 0, threads: Optional[int] = None,
           skip: int = 0, **window: Any) -> PUIResult:
    """Intervals of an output-error structure (the thesis's problem), by the scheme in
    the module docs: equation-error start, sequential-LP denominator F̂ (a local minimiser
    of the output-error bound), exact numerator intervals given F̂, first-order joint
    intervals, optional sweep of denominators verified by exact LPs.

    Parameters
    ----------
    data : MeasuredRun, SimResult, DataFrame, mapping, IdData or (y, u)
    structure : Structure
        From :func:`oe`.
    eps : float
        Bound on the output error |e(t)| [output unit].
    denominators : mapping ``{input: [f_1, …]}`` or one array per input, optional
        Fix the denominators (no iteration): the result is then exact given them
        (:attr:`PUIResult.approximation` says so; the f's are reported as point
        intervals).
    iterations : int
        Maximum sequential-LP iterations for F̂ (each: one step LP, one exact LP).
    tol : float
        Stop when the predicted decrease of the output-error bound is below ``tol``
        (relative), or when two accepted steps in a row decrease it by less.
    sweep : int
        Random convex combinations of the first-order end points' denominators to verify,
        besides those end points themselves (0: no sweep); see the module docs.
    seed : int
        Seed of the sweep.
    threads : LP worker threads (default every core).
    skip : int
        Samples left out of the constraints at the start (the filters still see them).
    **window : ``t_start``, ``t_stop``, ``step``, ``derive_rates`` (see :func:`iddata`).

    Raises :class:`InfeasibleError` when even F̂ needs a bound above ``eps``
    (``eps_min`` is then ``ε_min(F̂)``, an upper bound on the exact minimal bound).
    :attr:`PUIResult.iterations` records every denominator step (output-error bound,
    trust region, accepted or not).
    """
    s = structure
    if s.kind != "oe":
        raise ParameterError(f"oe_pui needs an OE structure, got {s.kind.upper()}; use pui()")
    t_all = time.perf_counter()
    d = resolve(data, s, **window)
    if isinstance(skip, bool) or not float(skip).is_integer() or skip < 0:
        raise ParameterError(f"skip must be a whole number >= 0, got {skip!r}")
    e_ = np.asarray(eps, dtype=float)
    if e_.ndim != 0 or not math.isfinite(float(e_)) or float(e_) <= 0:
        raise ParameterError(f"oe_pui: eps must be one finite bound > 0, got {eps!r}")
    eps = float(e_)
    if isinstance(iterations, bool) or int(iterations) < 0:
        raise ParameterError(f"iterations must be >= 0, got {iterations!r}")
    if isinstance(sweep, bool) or int(sweep) < 0:
        raise ParameterError(f"sweep must be >= 0, got {sweep!r}")
    P = _OE(s, d.y, d.u, int(skip))
    n = P.rows.shape[0]
    if n < s.n_params:
        raise InputError(f"too few samples for {s.describe()}: {n} rows in the constraints for {s.n_params} parameters")
    unit = unit_of(d.output)
    desc = s.describe()
    times: List[float] = []
    hist: List[Dict[str, Any]] = []
    rows = P.rows
    y = d.y[rows]

    def fit_given(F: List[np.ndarray], strict: bool = True) -> Tuple[float, np.ndarray, np.ndarray]:
        W, _ = P.numerator_regression(F)
        v, th, t = minimax(W[rows], y, strict=strict)
        times.append(t)
        return v, th, W

    fixed = denominators is not None
    if fixed:
        F = _given_denominators(s, denominators)  # type: ignore[arg-type]
        e_best, bc, _ = fit_given(F)
        hist.append({"iteration": 0, "eps_oe": e_best, "step": 0.0, "accepted": True, "source": "given"})
    else:
        # 1. equation-error start: ARX with a common denominator of order max(nf)
        na = max(s.nf) if s.nf else 0
        ee = Structure("arx", s.inputs, s.output, s.nb, s.nk, na=na, offset=s.offset)
        du_full = P.du
        reg = build_regression(ee, d.y, du_full, 0)
        _, th_ee, t_ee = minimax(reg.phi, reg.y)
        times.append(t_ee)
        A = _reflect(th_ee[:na])
        F = [A[: s.nf[j]] if s.nf[j] <= na else np.r_[A, np.zeros(s.nf[j] - na)] for j in range(s.n_inputs)]
        F = [_reflect(f) for f in F]
        e_best, bc, _ = fit_given(F)
        hist.append({"iteration": 0, "eps_oe": e_best, "step": 0.0, "accepted": True, "source": "equation error"})
        # 2. sequential LP on the true output-error bound
        rho = 0.2
        it = 0
        small = 0
        while it < int(iterations) and P.nf_total > 0 and rho > 1e-7:
            it += 1
            yhat, xs = P.outputs(F, bc)
            Wb, _ = P.numerator_regression(F)
            Gf = P.sensitivity(F, xs)
            M = np.hstack([Gf, Wb])[rows]
            hi_ = np.r_[np.full(P.nf_total, rho), np.full(M.shape[1] - P.nf_total, np.inf)]
            v_lin, step, t_s = minimax(M, y, (-hi_, hi_), strict=False)
            times.append(t_s)
            if not math.isfinite(v_lin):  # the step LP failed numerically: a smaller region
                hist.append({"iteration": it, "eps_oe": math.nan, "step": math.nan, "trust_region": rho,
                             "accepted": False, "predicted": math.nan, "source": "step LP failed"})
                rho *= 0.25
                continue
            df = step[: P.nf_total]
            if e_best - v_lin <= tol * e_best:  # first-order stationary: no predicted decrease
                hist.append({"iteration": it, "eps_oe": e_best, "step": 0.0, "trust_region": rho, "accepted": False,
                             "predicted": v_lin, "source": "converged"})
                break
            Fc = P.split_f(np.concatenate(F) + df) if P.nf_total else F
            ok = all(_poly_stable(f) for f in Fc)
            e_new = math.inf
            if ok:
                e_new, bc_new, _ = fit_given(Fc, strict=False)
                ok = math.isfinite(e_new)
            accepted = ok and e_new < e_best
            hist.append({"iteration": it, "eps_oe": e_new if ok else math.nan, "step": float(np.max(np.abs(df))) if df.size else 0.0,
                         "trust_region": rho, "accepted": bool(accepted), "predicted": v_lin, "source": "sequential LP"})
            if accepted:
                gain = (e_best - e_new) / e_best
                F, bc, e_best = Fc, bc_new, e_new
                small = small + 1 if gain < tol else 0
                if small >= 2:
                    break
                if np.max(np.abs(df)) >= 0.99 * rho:
                    rho = min(2.0 * rho, 1.0)
            else:
                rho *= 0.25
    # 3. exact numerator intervals given F̂
    W, _ = P.numerator_regression(F)
    Fhat = np.concatenate(F) if P.nf_total else np.zeros(0)
    eps_min = e_best
    if eps_min > eps * (1.0 + 1e-9):
        th_full = np.concatenate([Fhat, bc])
        detail = ("(with the denominators given)" if fixed else
                  "(with the denominators of the iteration: a local optimum of a nonconvex problem, so this eps_min is "
                  "an upper bound on the exact one)")
        raise InfeasibleError(eps, eps_min, desc, n, th_full, unit, detail)
    bc_names = P.bc_names()
    try:
        cond = pui_core(W[rows], y, eps, bc_names, threads=threads, unit=unit,
                         method="exact given the denominators: LPs on |y - Phi(F) (b, c)| <= eps")
    except InfeasibleError as ex:
        raise InfeasibleError(eps, ex.eps_min, desc, n, np.concatenate([Fhat, ex.minimax]), unit, "(given the denominators)") from None
    times += list(cond.lp_times)
    nthr = cond.threads
    f_names = P.f_names()
    if fixed:
        lower = np.concatenate([Fhat, cond.lower])
        upper = np.concatenate([Fhat, cond.upper])
        center = np.concatenate([Fhat, cond.center])
        radius = cond.radius
        metric = cond.center_metric
        method = "OE with given denominators: exact numerator/offset intervals by LP"
        approx = ""
        notes = ["the denominators are given: their intervals are points; the rest is exact given them"]
        sw = None
    else:
        # 4. first-order joint intervals around F̂ (exact in b, c)
        _, xs = P.outputs(F, bc)
        Gf = P.sensitivity(F, xs)
        M = np.hstack([Gf, W])[rows]
        # prior: F_j stable, so |f_ji| <= C(nf_j, i) (coefficients of a monic polynomial
        # with every root in the unit disc)
        cmax = np.concatenate([[math.comb(s.nf[j], i) for i in range(1, s.nf[j] + 1)] for j in range(s.n_inputs)] + [[]])
        inf_ = np.full(M.shape[1] - P.nf_total, np.inf)
        lin = pui_core(M, y, eps, f_names + bc_names, threads=threads, unit=unit, strict=False,
                        box=(np.r_[-cmax - Fhat, -inf_], np.r_[cmax - Fhat, inf_]))
        times += list(lin.lp_times)
        lower = np.concatenate([Fhat + lin.lower[: P.nf_total], lin.lower[P.nf_total:]])
        upper = np.concatenate([Fhat + lin.upper[: P.nf_total], lin.upper[P.nf_total:]])
        center = np.concatenate([Fhat + lin.center[: P.nf_total], lin.center[P.nf_total:]])
        radius = lin.radius
        metric = lin.center_metric
        # widen to the exact conditional intervals (verified feasible points)
        lower[P.nf_total:] = np.minimum(lower[P.nf_total:], cond.lower)
        upper[P.nf_total:] = np.maximum(upper[P.nf_total:], cond.upper)
        lower[: P.nf_total] = np.minimum(lower[: P.nf_total], Fhat)
        upper[: P.nf_total] = np.maximum(upper[: P.nf_total], Fhat)
        sw = None
        if sweep:
            assert lin.witnesses is not None
            dF = lin.witnesses[:, : P.nf_total]
            sw = _sweep(P, rows, y, eps, Fhat, dF[np.all(np.isfinite(dF), axis=1)], int(sweep), seed, threads, times)
            if sw["feasible"]:
                lower = np.minimum(lower, sw["lower"])
                upper = np.maximum(upper, sw["upper"])
        method = ("OE: equation-error start, sequential-LP denominator (local), exact numerator LPs given it, "
                  "first-order joint intervals" + (f", sweep of {int(sweep)} denominators" if sweep else ""))
        approx = ("denominator F̂ is a local minimiser of the output-error bound; the intervals are those of the model "
                  "linearised in F around F̂ (exact in b and c), widened to every point verified feasible "
                  "(the exact numerator intervals given F̂" + (" and the sweep" if sweep else "") + "). The exact OE "
                  "feasible set is not convex: these are not guaranteed outer bounds.")
        notes = [f"first-order intervals: {note}" for note in lin.notes]
    res = PUIResult(
        names=s.names, lower=lower, upper=upper, center=center, radius=radius,
        minimax=np.concatenate([Fhat, bc]), eps=eps, eps_min=eps_min, n=n, n_data=len(d), structure=s,
        method=method, approximation=approx, solve_time=time.perf_counter() - t_all, lp_times=np.asarray(times),
        threads=nthr, dt=d.dt, unit=unit, notes=list(d.notes) + notes + ["OE: inputs as deviations from their first sample, filters from rest"],
        conditional=cond, denominators={u: np.r_[1.0, f] for u, f in zip(s.inputs, F)}, iterations=hist, sweep=sw,
        center_metric=metric,
    )
    return res


def _given_denominators(s: Structure, den: Union[Mapping[str, ArrayLike], Sequence[ArrayLike]]) -> List[np.ndarray]:
    if isinstance(den, Mapping):
        missing = [u for u in s.inputs if u not in den]
        if missing:
            raise InputError(f"denominators: missing {missing}")
        seq = [den[u] for u in s.inputs]
    else:
        seq = list(den)
        if len(seq) != s.n_inputs:
            raise InputError(f"denominators: one per input ({s.n_inputs}) expected, got {len(seq)}")
    out = []
    for j, f in enumerate(seq):
        a = np.atleast_1d(np.asarray(f, dtype=float))
        if a.shape == (s.nf[j] + 1,) and a[0] == 1.0:
            a = a[1:]
        if a.shape != (s.nf[j],):
            raise InputError(f"denominator of {s.inputs[j]!r}: {s.nf[j]} coefficients f_1.. (or [1, f_1, ..]) expected, got {a.shape}")
        if not _poly_stable(a, 0.0):
            raise ParameterError(f"denominator of {s.inputs[j]!r} is unstable (a root on or outside the unit circle)")
        out.append(a)
    return out


def _sweep(P: _OE, rows: np.ndarray, y: np.ndarray, eps: float, Fhat: np.ndarray, dF: np.ndarray, m: int, seed: int,
           threads: Optional[int], times: List[float]) -> Dict[str, Any]:
    """Candidates F̂ + ΔF: the denominators of the first-order witnesses ``dF`` (K, nf)
    and ``m`` random convex combinations of them (Dirichlet weights). Keep the stable
    ones whose exact minimal bound is <= eps, bound their numerators by exact LPs, and
    return the hull of those verified points."""
    rng = np.random.default_rng(seed)
    p = len(P.s.names)
    lo = np.full(p, math.inf)
    hi = np.full(p, -math.inf)
    pts = np.unique(np.round(dF, 12), axis=0) if dF.size else np.zeros((0, P.nf_total))
    if pts.shape[0] and m:
        wts = rng.dirichlet(np.ones(pts.shape[0]), size=m)
        pts = np.vstack([pts, wts @ pts])
    cands = []
    for df in pts:
        F = P.split_f(Fhat + df)
        if all(_poly_stable(x) for x in F):
            cands.append(F)
    nthr = thread_count(threads, max(1, len(cands)))

    def check(F: List[np.ndarray]) -> Tuple[List[np.ndarray], float, float]:
        W, _ = P.numerator_regression(F)
        v, _, t = minimax(W[rows], y)
        return F, v, t

    if nthr > 1 and len(cands) > 1:
        with ThreadPoolExecutor(max_workers=nthr) as ex:
            checked = list(ex.map(check, cands))
    else:
        checked = [check(F) for F in cands]
    feasible = 0
    for F, v, t in checked:
        times.append(t)
        if v > eps:
            continue
        W, _ = P.numerator_regression(F)
        try:
            r = pui_core(W[rows], y, eps, P.bc_names(), threads=threads)
        except InfeasibleError:
            continue
        times.extend(r.lp_times)
        feasible += 1
        fv = np.concatenate(F) if P.nf_total else np.zeros(0)
        lo = np.minimum(lo, np.concatenate([fv, r.lower]))
        hi = np.maximum(hi, np.concatenate([fv, r.upper]))
    return {"drawn": int(pts.shape[0]), "stable": len(cands), "feasible": feasible, "lower": lo, "upper": hi}


# ============================================================== dispatch
def identify(data: Any, structure: Structure, eps: EpsLike, **kwargs: Any) -> PUIResult:
    """:func:`pui` for FIR/ARX, :func:`oe_pui` for OE."""
    if structure.kind == "oe":
        return oe_pui(data, structure, eps, **kwargs)  # type: ignore[arg-type]
    return pui(data, structure, eps, **kwargs)

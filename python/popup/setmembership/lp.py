"""The linear programs of the parameter-uncertainty intervals, with their scaling."""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable, List, Optional, Tuple
from scipy.optimize import linprog

import numpy as np
import scipy.sparse as sp

from ..exceptions import ConvergenceError, InputError, ParameterError
from .structure import EpsLike


# ============================================================== LP core
def thread_count(threads: Optional[int], jobs: int) -> int:
    if threads is None or threads == 0:
        threads = os.cpu_count() or 1
    if isinstance(threads, bool) or int(threads) < 1:
        raise ParameterError(f"threads must be >= 1 (or 0/None: every core), got {threads!r}")
    return max(1, min(int(threads), jobs))


def solve_lp(c: np.ndarray, A: Any, b: np.ndarray, bounds: Any) -> Tuple[Any, float]:
    """One LP by HiGHS (simplex); when it stops on numerical trouble (status 4) retried
    with HiGHS's interior point method, then both without presolve."""
    t = time.perf_counter()
    r = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method="highs")
    for method, opts in (("highs-ipm", {}), ("highs-ipm", {"presolve": False}), ("highs-ds", {"presolve": False})):
        if r.status != 4:
            break
        r = linprog(c, A_ub=A, b_ub=b, bounds=bounds, method=method, options=opts)
    return r, time.perf_counter() - t


def run_lp(jobs: List[Tuple[np.ndarray, Any, np.ndarray, Any]], threads: int) -> List[Tuple[Any, float]]:
    if threads <= 1 or len(jobs) <= 1:
        return [solve_lp(*j) for j in jobs]
    with ThreadPoolExecutor(max_workers=threads) as ex:
        return list(ex.map(lambda j: solve_lp(*j), jobs))


def eps_array(eps: EpsLike, n: int) -> np.ndarray:
    e = np.asarray(eps, dtype=float)
    if e.ndim == 0:
        e = np.full(n, float(e))
    if e.shape != (n,):
        raise InputError(f"eps must be a scalar or one bound per sample ({n}), got shape {e.shape}")
    if not np.all(np.isfinite(e)) or np.any(e <= 0):
        raise ParameterError(f"the noise bound eps must be finite and > 0, got {eps if np.ndim(eps) == 0 else 'an array with ' + str(e.min())}")
    return e


def _orth(M: np.ndarray) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """``(Q, T⁻¹)`` with ``M = Q T``, Q with (nearly) orthonormal columns, by Cholesky QR
    done twice (CholeskyQR2: two Gram matrices, two small inverses; only matrix
    products, which stay fast when the BLAS is oversubscribed, unlike LAPACK's
    Householder QR). None when M is (numerically) rank deficient."""
    p = M.shape[1]
    Q = M
    Tinv = np.eye(p)
    for _ in range(2):
        try:
            L = np.linalg.cholesky(Q.T @ Q)
            d = np.abs(np.diag(L))
            if not np.all(np.isfinite(d)) or d.min() <= 1e-7 * d.max():
                raise np.linalg.LinAlgError("ill-conditioned Gram matrix")
        except np.linalg.LinAlgError:
            break
        Rinv = np.linalg.inv(L.T)
        Q = Q @ Rinv
        Tinv = Tinv @ Rinv
    else:
        return _checked(M, Tinv)
    # too ill-conditioned for Cholesky QR (cond > ~1e7): Householder QR
    R = np.linalg.qr(M, mode="r")
    d = np.abs(np.diag(R))
    if not d.size or d.min() <= 1e-13 * d.max():
        return None
    return _checked(M, np.linalg.inv(R))


def _checked(M: np.ndarray, Tinv: np.ndarray) -> Optional[Tuple[np.ndarray, np.ndarray]]:
    """``(M T⁻¹, T⁻¹)`` when ``M T⁻¹`` is close to orthonormal (the change of variables is
    then exact to rounding and worth it), else None (numerically rank deficient)."""
    Q = M @ Tinv
    if not np.all(np.isfinite(Q)) or np.max(np.abs(Q.T @ Q - np.eye(M.shape[1]))) > 1e-3:
        return None
    return Q, Tinv


class Scaled:
    """The FPS ``|y − Φθ| <= ε`` (and an optional box on θ) as well-conditioned LPs.

    Rows are divided by ε (constraints ``|b − A₁θ₁| <= 1``, ``b = y/ε``), columns by their
    largest magnitude s (``θ₁ = s θ``), and θ₁ is re-parameterised by the QR factor of
    ``A₁ = Q R``: ``z = R θ₁``, so the constraint matrix of every LP is ``±Q`` (orthonormal
    columns) however collinear the regressors are (an ARX on a slowly varying output:
    cond(Φ) ~ 1e7). The objective ``θ₁ᵢ = (R⁻¹ z)ᵢ`` is a row of ``R⁻¹``. Exact for any
    invertible R (R only has to make the LP well conditioned): :func:`_orth`.
    Rank-deficient Φ: no re-parameterisation (the LPs report unbounded).
    """

    def __init__(self, phi: np.ndarray, y: np.ndarray, eps: np.ndarray, box: Optional[Tuple[np.ndarray, np.ndarray]]) -> None:
        A1 = phi / eps[:, None]
        s = np.max(np.abs(A1), axis=0)
        s[~(s > 0)] = 1.0
        A1 = A1 / s
        self.s = s
        self.p = p = phi.shape[1]
        self.A1 = A1
        self.b0 = y / eps
        qt = _orth(A1)
        self.whitened = qt is not None
        if qt is not None:
            Q, self.Tinv = qt
            z0 = Q.T @ self.b0  # least squares: the LP variables are the offsets from it
        else:
            Q, self.Tinv = A1, np.eye(p)
            z0 = np.zeros(p)
        self.Q = Q
        self.A = sp.csr_matrix(Q)
        self.off = self.Tinv @ z0  # θ₁ of the least-squares fit
        self.b = self.b0 - Q @ z0
        rows, rhs = [], []
        if box is not None:
            lo, hi = box
            for i in range(p):
                if np.isfinite(hi[i]):
                    rows.append(self.Tinv[i])
                    rhs.append(hi[i] * s[i] - self.off[i])
                if np.isfinite(lo[i]):
                    rows.append(-self.Tinv[i])
                    rhs.append(-lo[i] * s[i] + self.off[i])
        Bm = np.array(rows).reshape(len(rows), p)
        nb_ = np.linalg.norm(Bm, axis=1) if len(rows) else np.ones(0)
        nb_[nb_ == 0] = 1.0
        self.B = sp.csr_matrix(Bm / nb_[:, None])  # unit rows
        self.hb = np.asarray(rhs, dtype=float) / nb_
        self.box = box
        self.G = sp.vstack([self.A, -self.A, self.B], format="csr")
        self.h = np.concatenate([self.b + 1.0, 1.0 - self.b, self.hb])
        self.free: List[Tuple[Optional[float], Optional[float]]] = [(None, None)] * p

    def theta(self, z: np.ndarray) -> np.ndarray:
        """Parameters θ from LP variables z."""
        return (self.off + self.Tinv @ z) / self.s

    def minimax_job(self) -> Tuple[np.ndarray, Any, np.ndarray, Any]:
        n = self.A.shape[0]
        one = sp.csr_matrix(np.ones((n, 1)))
        zb = sp.csr_matrix((self.B.shape[0], 1))
        G = sp.vstack([sp.hstack([self.A, -one]), sp.hstack([-self.A, -one]), sp.hstack([self.B, zb])], format="csr")
        c = np.zeros(self.p + 1)
        c[-1] = 1.0
        return c, G, np.concatenate([self.b, -self.b, self.hb]), self.free + [(0.0, None)]

    def bound_jobs(self) -> List[Tuple[np.ndarray, Any, np.ndarray, Any]]:
        jobs = []
        for i in range(self.p):
            for sign in (1.0, -1.0):
                jobs.append((sign * self.Tinv[i], self.G, self.h, self.free))
        return jobs

    def chebyshev_job(self, lo1: np.ndarray, hi1: np.ndarray) -> Tuple[Tuple[np.ndarray, Any, np.ndarray, Any], Callable[[np.ndarray], np.ndarray], str]:
        """The largest ball inside the FPS (and the box), as an LP ``max r``.

        Whitened (the usual case): the ball in the LP variables z, i.e. in the metric
        ``‖Φ(θ − θ')/ε‖₂`` of the regressors (units- and parameterisation-free, and round
        however collinear the regressors): rows ``±q_tᵀ z + r ‖q_t‖ <= 1 ∓ b_t``.
        Otherwise (numerically rank-deficient Φ): the ball in coordinates v with ``θ₁ = m
        + W v`` (m, W: midpoints and half-widths of the intervals, 1 where unbounded).
        Returns the job, the map from its solution to θ₁, and the metric's name."""
        p = self.p
        if self.whitened:
            qn = np.sqrt(np.einsum("ij,ij->i", self.Q, self.Q))
            bn = np.ones(self.B.shape[0])  # unit rows
            G = sp.vstack([sp.hstack([self.G, sp.csr_matrix(np.r_[qn, qn, bn][:, None])])], format="csr")
            c = np.zeros(p + 1)
            c[-1] = -1.0
            return (c, G, self.h, self.free + [(0.0, None)]), (lambda x: self.off + self.Tinv @ x[:p]), "regressors"
        fin = np.isfinite(lo1) & np.isfinite(hi1)
        m = np.where(fin, 0.5 * (lo1 + hi1), 0.0)
        w = np.where(fin, 0.5 * (hi1 - lo1), 1.0)
        w = np.maximum(w, 1e-12 * max(float(np.max(w)), 1e-300))
        AW = self.A1 * w
        norms = np.sqrt(np.einsum("ij,ij->i", AW, AW))
        qt = _orth(AW)
        if qt is not None:
            M, Rinv = qt
        else:
            Rinv = np.eye(p)
            M = AW
        Am = self.A1 @ m
        blocks = [np.hstack([M, norms[:, None]]), np.hstack([-M, norms[:, None]])]
        rhs = [self.b0 + 1.0 - Am, 1.0 - self.b0 + Am]
        fi = np.flatnonzero(fin)
        if fi.size:  # the ball inside the interval box: |v_i| + r <= 1
            Rf = Rinv[fi]
            one = np.ones((fi.size, 1))
            blocks += [np.hstack([Rf, one]), np.hstack([-Rf, one])]
            rhs += [np.ones(fi.size), np.ones(fi.size)]
        G = sp.csr_matrix(np.vstack(blocks))
        c = np.zeros(p + 1)
        c[-1] = -1.0
        job = (c, G, np.concatenate(rhs), [(None, None)] * p + [(0.0, None)])
        return job, (lambda x: m + w * (Rinv @ x[:p])), "half-widths"


def status_error(r: Any, what: str) -> ConvergenceError:
    return ConvergenceError(f"HiGHS failed on {what}: status {r.status}: {r.message}")


def residual_scale(phi: np.ndarray, y: np.ndarray) -> float:
    """A scale for the rows of a minimax LP: the largest least-squares residual (so the
    LP tolerance is relative to the minimal bound, not to |y|), or max |y| (when the
    regressors are numerically rank deficient)."""
    s = np.max(np.abs(phi), axis=0)
    s[~(s > 0)] = 1.0
    qt = _orth(phi / s)
    big = max(float(np.max(np.abs(y))), 1e-300)
    if qt is None:
        return big
    Q = qt[0]
    r = float(np.max(np.abs(y - Q @ (Q.T @ y))))
    return r if r > 1e-12 * big else big


def minimax(phi: np.ndarray, y: np.ndarray, box: Optional[Tuple[np.ndarray, np.ndarray]] = None,
             strict: bool = True) -> Tuple[float, np.ndarray, float]:
    """min_θ max |y − Φθ| with an optional box on θ: (value, θ, LP time). ``strict=False``:
    a failed LP gives (inf, NaN, time) instead of raising."""
    scale = residual_scale(phi, y)
    S = Scaled(phi, y, np.full(y.shape[0], scale), box)
    r, t = solve_lp(*S.minimax_job())
    if r.status != 0:
        if not strict:
            return math.inf, np.full(phi.shape[1], np.nan), t
        raise status_error(r, "a minimax LP of the output-error iteration")
    return float(r.x[-1]) * scale, S.theta(r.x[:-1]), t

"""Smoothing of measured encoder angles for an encoder replay, at the noise floor.

An encoder replay (:meth:`popup.Model.replay`) drives the motor joints through the natural
cubic spline that *interpolates* every encoder sample, so q̈ (and with it the replayed motor
torques and IMU accelerations) carries the second derivative of the encoder's error:
quantisation (a step Δ, error variance Δ²/12 while the angle moves) and any white noise,
amplified by 1/h² at sample spacing h. :func:`smooth_encoder` replaces the samples by the
values of a cubic *smoothing* spline on the same stamps, with its smoothing chosen from
the error level estimated in the data::

    sm = popup.smoothing.smooth_encoder(t_enc, q_enc)
    res = model.replay(t_enc, sm.q)      # q̈ no longer follows the encoder's error
    sm.method, sm.sigma, sm.resolution   # what was done, for notes

Method
------
Per joint:

1. **Quantisation step** (``resolution=None``): the distinct values of the joint, sorted;
   their consecutive differences must all be whole multiples of one step (within 2 % of
   it). The step is the greatest common step of the smallest distinct differences
   (Euclid's algorithm with that tolerance, so a ramp that never visits neighbouring
   levels still gives its step), refined as (sum of the differences) / (sum of their
   multiples), and checked against every difference. Fewer than 2 distinct values, or a
   difference that is not whole: not quantised. A few samples of a smooth motion with
   nearly equal increments also fit a coarse "step" (their smallest difference), so a
   step is kept only if the samples carry its error: the RMS of the order-8 divided
   differences (step 2) is at least 1 % of Δ/√12 (a quantised angle that moves shows
   about Δ/√12 there). A step is accepted only if it is larger
   than 10⁶ machine epsilons of the largest |angle| (not float rounding).
2. **White noise**: normalised divided differences of order k over k + 1 consecutive
   samples, ``d_i = Σ_j w_ij y_j / ‖w_i‖`` with the divided-difference weights
   ``w_ij = 1 / Π_{l≠j} (t_j − t_l)`` (exact for any stamps, uniform or not). They
   annihilate polynomials of degree < k, and for white noise of std σ every ``d_i`` has
   variance σ², whatever the stamps. The robust estimate is
   ``σ̂_k = sqrt(median(d²) / 0.4549)`` (0.4549 = median of χ²₁), so that the windows where
   the motion itself still shows (fast chirps at low rates, the joins of the segments of a
   trajectory) do not count. Noise is *detected* when ``σ̂_8 ≥ 0.6 σ̂_6`` (white noise has
   the same level at every order; a smooth signal's differences fall off by ~(ω h)² per two
   orders) and ``σ̂_8`` is above the float floor (10³ machine epsilons of the largest
   |angle|).
3. **Error variance** used: the nominal level ``max(Δ²/12, σ̂_8²)`` (Δ²/12 for a
   quantised joint, σ̂_8² for detected noise; the differences see the quantisation error
   too wherever the angle moves, so the two are not added), but no more than the *rough*
   error power actually in the samples, ``mean(d²)`` of the order-8 differences: where the
   angle is held, or creeps by less than a step per sample, the quantisation error is a
   constant or slowly varying offset that neither the differences nor any smoother can
   see, and counting it in would over-smooth the moves (a 1e-4 rad step on the lab
   trajectory: the rough power is 0.45–0.8 × Δ²/12). A given ``noise`` (white, std per
   joint) is added to ``Δ²/12`` instead. σ = 0 (exact encoder): the joint is returned
   unchanged, bit for bit.
4. **Smoothing spline** (Reinsch): the natural cubic spline g with knots at every stamp
   minimising ``Σ (y_i − g(t_i))² + λ ∫ g''(t)² dt`` — the same curve as
   :func:`scipy.interpolate.make_smoothing_spline` with ``lam = λ`` — computed as
   ``(R + λ QᵀQ) γ = Qᵀ y``, ``g = y − λ Q γ`` (Green & Silverman 1994, §2.3.3; R, Q the
   tridiagonal/banded matrices of the stamps), one symmetric pentadiagonal solve by LAPACK
   (:func:`scipy.linalg.solveh_banded`), O(N).
5. **λ by the discrepancy principle**: the λ at which the mean squared residual
   ``mean((y − g)²)`` equals σ² (Brent's method on log λ, 1 % in λ; the mean squared
   residual grows monotonically with λ). The data are then fitted exactly as closely as
   their error allows: a residual of the size of the error, no more. So the smoothing
   removes at most ~σ of the true angle (bias in q̈ at angular frequency ω at most
   ~σ ω², e.g. 1.1e-6 rad at 8 Hz: 3e-3 rad/s²), while the error's q̈, dominated by the
   highest frequencies, is cut off. λ is bracketed between a cutoff of one sample
   (``ω_c = π / h̄``, essentially the interpolant) and 0.05 Hz (a straight line); at an end
   of the bracket that end is used. ``params["cutoff_hz"]`` is the equivalent cutoff
   ``(1 / (λ h̄))^(1/4) / 2π`` (the smoother's gain is ~1/(1 + (f/f_c)⁴) for uniform
   stamps).
6. **Ends.** The smoothing spline is natural: g'' = 0 at the first and last stamp. That is
   right for a record that starts and ends at rest (and the replay's default start state,
   at rest, assumes it anyway); for a record cut mid-motion (q̈ ≠ 0 at its ends) the curve
   bends to q̈ = 0 over a few smoother time scales ``τ = (λ h̄)^(1/4)`` (a few ms), where
   the engine's own natural spline does so over one sample. Nothing is done about it
   (padding the ends by a local polynomial helped a record cut mid-chirp but hurt starts
   along minimum-jerk moves): start and end records at rest.

What the replay sees: the smoothing spline is itself a natural cubic spline with knots at
the stamps, so the engine's natural spline through its values at the stamps is the same
curve — q, q̇, q̈ of the replay are those of the smoothing spline, and nothing is lost by
handing the engine samples instead of a spline.

Assumptions: the encoder error is independent from sample to sample (quantisation of a
moving angle, white noise); the true motion has little content near the sample rate (the
discrepancy principle keeps anything larger than the error anyway); the stamps are
exact (stamp jitter is fine as long as the stamps say when each angle was taken).
Deterministic: no random numbers, same bits for the same input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from .exceptions import InputError

__all__ = ["SmoothedEncoder", "smooth_encoder", "smooth_at", "detect_resolution", "estimate_noise"]

_MEDIAN_CHI2_1 = 0.454936423119572  # median of a chi-squared variable with 1 degree of freedom
_STEP_TOL = 0.02  # a difference is a whole number of steps within 2 % of a step
_GCD_TERMS = 32  # distinct differences the common step is taken from (then checked on all)
_NOISE_ORDERS = (6, 8)
_NOISE_RATIO = 0.6
_LOG_TOL = math.log(1.01)


@dataclass(frozen=True)
class SmoothedEncoder:
    """What :func:`smooth_encoder` returns.

    Attributes
    ----------
    q : (N, 3) array
        Smoothed angles on the input stamps [rad] (the input itself, bit for bit, for a
        joint without detectable error).
    sigma : (3,) array
        Encoder error std used per joint [rad] (0: exact, left unchanged).
    resolution : float or None
        Quantisation step [rad], detected or given (the largest of the joints' steps if
        they differ; per joint in ``params["resolution"]``); None: not quantised.
    method : str
        One sentence saying what was done (for the notes of a comparison).
    params : dict
        Per joint (lists of 3): ``resolution`` (step or None), ``noise`` (white-noise std
        estimated or given [rad], None when not detected), ``rough`` (RMS of the order-8
        divided differences [rad], step 3 of the module docs), ``lam`` (smoothing parameter λ
        of ``Σ (y − g)² + λ ∫ g''²``, as scipy's ``make_smoothing_spline(lam=)``; None when
        unchanged), ``cutoff_hz`` (the equivalent cutoff ``(1/(λ h̄))^(1/4) / 2π`` of the
        smoother, None when unchanged), ``rms_residual`` [rad]; and ``mean_dt`` [s].
    """

    q: np.ndarray
    sigma: np.ndarray
    resolution: Optional[float]
    method: str
    params: Dict[str, Any] = field(default_factory=dict)


# --------------------------------------------------------------------- checks
def _check(t: Any, q: Any) -> Tuple[np.ndarray, np.ndarray]:
    try:
        tt = np.asarray(t, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"input t: not an array of numbers ({e})") from None
    try:
        qq = np.asarray(q, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise InputError(f"input q: not an array of numbers ({e})") from None
    if tt.ndim != 1:
        raise InputError(f"input t: expected shape (N,), got {tt.shape}")
    if qq.ndim != 2 or qq.shape[1] != 3 or qq.shape[0] != tt.shape[0]:
        raise InputError(f"input q: expected shape ({tt.shape[0]}, 3) to match t, got {qq.shape}")
    if not np.all(np.isfinite(tt)):
        raise InputError("input t: time stamps must be finite")
    if not np.all(np.isfinite(qq)):
        raise InputError("input q: angles must be finite")
    if tt.shape[0] > 1 and not np.all(np.diff(tt) > 0):
        i = int(np.argmin(np.diff(tt) > 0))
        raise InputError(f"input t: time must be strictly increasing: t[{i + 1}] = {tt[i + 1]} <= t[{i}] = {tt[i]}")
    return tt, qq


# ------------------------------------------------------------- quantisation
def _common_step(a: float, b: float, floor: float) -> float:
    """Greatest common step of two differences ``a >= b > 0`` (Euclid's algorithm, a
    remainder within 2 % of the step counts as none; stops at ``floor``)."""
    while b > floor:
        r = math.fmod(a, b)
        if r <= _STEP_TOL * b or r >= (1.0 - _STEP_TOL) * b:
            return b
        a, b = b, r
    return b


def detect_resolution(y: Any) -> Optional[float]:
    """Quantisation step of one encoder channel [rad], or None.

    The largest step of which every difference between consecutive distinct values is a
    whole multiple (within 2 % of the step): the greatest common step of the smallest
    distinct differences (Euclid's algorithm with that tolerance), refined as the sum of the
    differences over the sum of their multiples, and checked against every difference.
    None for fewer than 2 distinct values, when some difference is not a whole multiple,
    or for a step within float rounding of the values (10⁶ machine epsilons of the
    largest |value|). The values alone cannot tell a short smooth motion with nearly
    equal increments from a coarse grid; :func:`smooth_encoder` also checks that the
    samples carry the step's error."""
    v = np.asarray(y, dtype=np.float64).reshape(-1)
    u = np.unique(v)
    if u.size < 2:
        return None
    floor = 1e6 * np.finfo(float).eps * max(float(np.max(np.abs(u))), 1e-300)
    d = np.diff(u)
    d_min = float(d.min())
    if d_min <= floor:
        return None
    # the distinct differences (as multiples of the smallest, to 1e-4), smallest first
    _, first = np.unique(np.round(d / d_min, 4), return_index=True)
    g = d_min
    for i in first[1:_GCD_TERMS]:
        g = _common_step(float(d[i]), g, floor)
        if g <= floor:
            return None
    # refine on the small differences first (their multiples are sure), then on all
    for lim in (16.0, 1024.0, math.inf):
        sel = d <= lim * g
        if not sel.any():
            continue
        k = float(np.rint(d[sel] / g).sum())
        if not k >= 1.0:
            return None
        g = float(d[sel].sum()) / k
    m = d / g
    if not np.all(np.abs(m - np.rint(m)) <= _STEP_TOL):
        return None
    return g


# ------------------------------------------------------------------- noise
def _divided_differences(t: np.ndarray, y: np.ndarray, k: int) -> np.ndarray:
    """Normalised k-th divided differences over every k + 1 consecutive samples of each
    column of ``y`` (N, C): (N − k, C), each with variance σ² for white noise of std σ."""
    from numpy.lib.stride_tricks import sliding_window_view

    tw = sliding_window_view(t, k + 1)  # (M, k+1)
    diff = tw[:, :, None] - tw[:, None, :]
    idx = np.arange(k + 1)
    diff[:, idx, idx] = 1.0
    w = 1.0 / np.prod(diff, axis=2)  # (M, k+1)
    w /= np.sqrt(np.sum(w * w, axis=1, keepdims=True))
    yw = sliding_window_view(y, k + 1, axis=0)  # (M, C, k+1)
    yw = yw - yw[:, :, :1]  # Σ w = 0: subtracting the window's first value is exact and saves digits
    return np.einsum("mck,mk->mc", yw, w)


def estimate_noise(t: Any, q: Any) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """White-noise std per joint of encoder angles ``q`` (N, C) at stamps ``t`` (N,)
    [rad], from normalised divided differences of orders 6 and 8 (module docs, step 2).

    Returns ``(sigma (C,), detected (C,) bool, rough (C,))``: ``sigma`` the robust
    (median) order-8 estimate, ``detected`` whether it is noise (same level at orders 6
    and 8, above the float floor) rather than the motion itself, ``rough`` the RMS of the
    order-8 differences (the rough error power actually present, holds included). All
    zero for fewer than 10 samples."""
    tt = np.asarray(t, dtype=np.float64)
    qq = np.asarray(q, dtype=np.float64)
    if qq.ndim == 1:
        qq = qq[:, None]
    kmax = max(_NOISE_ORDERS)
    c = qq.shape[1]
    if tt.shape[0] < kmax + 2:
        return np.zeros(c), np.zeros(c, dtype=bool), np.zeros(c)
    est = []
    for k in _NOISE_ORDERS:
        d = _divided_differences(tt, qq, k)
        est.append(np.sqrt(np.median(d * d, axis=0) / _MEDIAN_CHI2_1))
    rough = np.sqrt(np.mean(d * d, axis=0))
    lo, hi = est[0], est[-1]
    floor = 1e3 * np.finfo(float).eps * np.maximum(np.max(np.abs(qq), axis=0), 1.0)
    detected = (hi > floor) & (hi >= _NOISE_RATIO * lo)
    return hi, detected, rough


# ---------------------------------------------------------- smoothing spline
class _Reinsch:
    """The cubic smoothing spline of one set of stamps (Green & Silverman's Reinsch
    algorithm): banded R, Q; ``fit(y, lam)`` gives the residual y − g."""

    def __init__(self, t: np.ndarray) -> None:
        h = np.diff(t)
        self.n = t.shape[0]
        h0, h1 = h[:-1], h[1:]  # interior knot j+1 sits between h_j and h_{j+1}
        self.q0, self.q1, self.q2 = 1.0 / h0, -1.0 / h0 - 1.0 / h1, 1.0 / h1
        m = self.n - 2
        # R (tridiagonal) and QᵀQ (pentadiagonal), upper band storage for solveh_banded
        self.r_diag = (h0 + h1) / 3.0
        self.r_off = h1[:-1] / 6.0
        qq = np.zeros((3, m))
        qq[2] = self.q0**2 + self.q1**2 + self.q2**2
        qq[1, 1:] = self.q1[:-1] * self.q0[1:] + self.q2[:-1] * self.q1[1:]
        qq[0, 2:] = self.q2[:-2] * self.q0[2:]
        self.qtq = qq

    def qt(self, y: np.ndarray) -> np.ndarray:
        return self.q0 * y[:-2] + self.q1 * y[1:-1] + self.q2 * y[2:]

    def q_times(self, g: np.ndarray) -> np.ndarray:
        out = np.zeros(self.n)
        out[:-2] += self.q0 * g
        out[1:-1] += self.q1 * g
        out[2:] += self.q2 * g
        return out

    def residual(self, qty: np.ndarray, lam: float) -> np.ndarray:
        from scipy.linalg import solveh_banded

        ab = lam * self.qtq
        ab[2] += self.r_diag
        ab[1, 1:] += self.r_off
        gamma = solveh_banded(ab, qty, check_finite=False)
        return lam * self.q_times(gamma)


def _discrepancy(sp: _Reinsch, y: np.ndarray, var: float, lam_lo: float, lam_hi: float) -> Tuple[float, np.ndarray]:
    """λ in [lam_lo, lam_hi] with mean((y − g)²) = var, and its residual."""
    from scipy.optimize import brentq

    qty = sp.qt(y)
    cache: Dict[float, np.ndarray] = {}

    def f(x: float) -> float:
        r = sp.residual(qty, math.exp(x))
        cache[x] = r
        ms = float(np.mean(r * r))
        return math.log(max(ms, 1e-300)) - math.log(var)

    a, b = math.log(lam_lo), math.log(lam_hi)
    fa = f(a)
    if fa >= 0.0:
        return lam_lo, cache[a]
    fb = f(b)
    if fb <= 0.0:
        return lam_hi, cache[b]
    x = brentq(f, a, b, xtol=_LOG_TOL, rtol=1e-12, maxiter=100)
    if x not in cache:
        f(x)
    return math.exp(x), cache[x]


# ----------------------------------------------------------------- public
def smooth_at(t: Any, y: Any, lam: float) -> np.ndarray:
    """The cubic smoothing spline of samples ``y`` (N,) on stamps ``t`` at a given λ (step 4
    of the module docs; e.g. ``params["lam"][j]`` of a :class:`SmoothedEncoder`), at the stamps."""
    tt = np.asarray(t, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if tt.ndim != 1 or yy.shape != tt.shape or tt.shape[0] < 3:
        raise InputError(f"smooth_at: t and y must be (N,) with N >= 3, got {tt.shape} and {yy.shape}")
    sp = _Reinsch(tt)
    return yy - sp.residual(sp.qt(yy), float(lam))


def smooth_encoder(t: Any, q: Any, *, resolution: Optional[float] = None, noise: Any = None) -> SmoothedEncoder:
    """Smooth measured encoder angles for an encoder replay (module docs: the method).

    Parameters
    ----------
    t : (N,) array
        Time stamps [s], strictly increasing (uniform or not).
    q : (N, 3) array
        Encoder angles at the joint outputs [rad], finite.
    resolution : float, optional
        Quantisation step [rad]: None detects it per joint from the values; 0 says the
        encoder is not quantised; > 0 is used for every joint.
    noise : float or (3,) array, optional
        White-noise std of the encoder per joint [rad] (on top of the quantisation):
        None estimates it from the data; 0 says there is none.

    Returns
    -------
    SmoothedEncoder
        ``q`` on the same stamps, the error std ``sigma`` used per joint, the
        ``resolution``, a one-sentence ``method`` and per-joint ``params``. ``q`` is the
        input unchanged for N < 5, for N < 10 unless ``resolution`` or ``noise`` is given
        (too few samples to estimate the error), and when no error is detected.

    Raises
    ------
    InputError
        ``t`` not (N,), ``q`` not (N, 3), non-finite values, non-increasing stamps, a
        negative or non-finite ``resolution``/``noise``.
    """
    tt, qq = _check(t, q)
    n = tt.shape[0]
    if resolution is not None:
        try:
            res_given = float(resolution)
        except (TypeError, ValueError):
            raise InputError(f"input resolution: expected a step [rad] >= 0 or None, got {resolution!r}") from None
        if not (math.isfinite(res_given) and res_given >= 0.0):
            raise InputError(f"input resolution: expected a finite step [rad] >= 0, got {resolution!r}")
    noise_given: Optional[np.ndarray] = None
    if noise is not None:
        try:
            noise_given = np.broadcast_to(np.asarray(noise, dtype=np.float64), (3,)).copy()
        except (TypeError, ValueError):
            raise InputError(f"input noise: expected a std [rad] or 3 of them (one per joint), got {noise!r}") from None
        if not (np.all(np.isfinite(noise_given)) and np.all(noise_given >= 0.0)):
            raise InputError(f"input noise: expected finite stds [rad] >= 0, got {noise!r}")

    n_min = max(_NOISE_ORDERS) + 2  # for the error estimates (step 2)
    if n < 5 or (n < n_min and resolution is None and noise is None):
        return SmoothedEncoder(
            q=qq.copy(),
            sigma=np.zeros(3),
            resolution=None if not resolution else float(resolution),
            method=f"encoder angles replayed as measured (only {n} samples: too few to estimate their error).",
            params={"resolution": [None] * 3, "noise": [None] * 3, "rough": [0.0] * 3, "lam": [None] * 3, "cutoff_hz": [None] * 3, "rms_residual": [0.0] * 3, "mean_dt": float((tt[-1] - tt[0]) / max(n - 1, 1))},
        )

    # 1) quantisation
    if resolution is None:
        steps: List[Optional[float]] = [detect_resolution(qq[:, j]) for j in range(3)]
    else:
        steps = [res_given if res_given > 0 else None] * 3
    # 2) white noise
    est, det, rough = estimate_noise(tt, qq)
    if resolution is None and n >= n_min:
        # a step whose error the samples do not carry is not a quantisation (module docs)
        steps = [s if s is not None and rough[j] >= 0.01 * s / math.sqrt(12.0) else None for j, s in enumerate(steps)]
    if noise_given is None:
        white: List[Optional[float]] = [float(est[j]) if det[j] else None for j in range(3)]
    else:
        white = [float(noise_given[j]) if noise_given[j] > 0 else None for j in range(3)]
    # 3) error variance
    var = np.zeros(3)
    for j in range(3):
        vq = 0.0 if steps[j] is None else steps[j] ** 2 / 12.0  # type: ignore[operator]
        vw = 0.0 if white[j] is None else white[j] ** 2  # type: ignore[operator]
        if noise_given is not None:
            var[j] = vq + vw
        else:
            # the nominal level, but no more than the rough error actually in the samples
            # (a held angle's quantisation error is a constant offset: no smoother sees it)
            var[j] = max(vq, vw)
            if n >= n_min:
                var[j] = min(var[j], float(rough[j]) ** 2)
            if math.sqrt(var[j]) <= 1e3 * np.finfo(float).eps * max(float(np.max(np.abs(qq[:, j]))), 1.0):
                var[j] = 0.0  # nothing rough above float rounding (e.g. a uniform ramp: on a grid, but exact)
    sigma = np.sqrt(var)

    # 4–5) smoothing spline with λ by the discrepancy principle
    hbar = float((tt[-1] - tt[0]) / (n - 1))
    lam_lo = 1.0 / (hbar * (math.pi / hbar) ** 4)  # cutoff at one sample: the interpolant, nearly
    lam_hi = 1.0 / (hbar * (2 * math.pi * 0.05) ** 4)  # cutoff 0.05 Hz
    out = qq.copy()
    lams: List[Optional[float]] = [None] * 3
    cut: List[Optional[float]] = [None] * 3
    rms = [0.0] * 3
    sp: Optional[_Reinsch] = None
    for j in range(3):
        if var[j] <= 0.0:
            continue
        if sp is None:
            sp = _Reinsch(tt)
        lam, r = _discrepancy(sp, qq[:, j], float(var[j]), lam_lo, lam_hi)
        out[:, j] = qq[:, j] - r
        lams[j] = lam
        cut[j] = (1.0 / (lam * hbar)) ** 0.25 / (2 * math.pi)
        rms[j] = float(np.sqrt(np.mean(r * r)))

    known = [s for s in steps if s is not None]
    res_out = max(known) if known else None
    params: Dict[str, Any] = {
        "resolution": steps,
        "noise": white,
        "rough": [float(r) for r in rough],
        "lam": lams,
        "cutoff_hz": cut,
        "rms_residual": rms,
        "mean_dt": hbar,
    }
    if sp is None:
        method = "encoder angles replayed as measured (no quantisation or noise detected in them)."
        return SmoothedEncoder(q=qq.copy(), sigma=sigma, resolution=res_out, method=method, params=params)
    parts = []
    if known:
        parts.append(f"quantisation step {res_out:.3g} rad {'given' if resolution is not None else 'detected'}")
    wn = [w for w in white if w is not None]
    if wn:
        parts.append(f"white noise {max(wn):.2g} rad {'given' if noise_given is not None else 'estimated'}")
    cuts = ", ".join("–" if c is None else f"{c:.3g}" for c in cut)
    method = (
        f"encoder angles smoothed by a cubic smoothing spline per joint ({'; '.join(parts)}; "
        f"error std {', '.join(f'{s:.2g}' for s in sigma)} rad; λ by the discrepancy principle, "
        f"mean squared residual = error variance; equivalent cutoff {cuts} Hz)."
    )
    return SmoothedEncoder(q=out, sigma=sigma, resolution=res_out, method=method, params=params)

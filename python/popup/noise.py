"""The noise floor of a measured channel, estimated from the data alone.

A measured channel is ``y(t) = s(t) + ε(t)``: a signal smooth on the scale of the sampling
plus white sensor noise ε of standard deviation σ. The k-th divided difference over
k + 1 consecutive stamps, ``D = Σ_i w_i y_i`` with ``w_i = 1/Π_{j≠i}(t_i − t_j)``,
annihilates every polynomial of degree < k, so it removes the smooth part (up to
``s⁽ᵏ⁾ h^k``) and keeps the noise with variance ``σ² Σ w_i²``: ``D²/Σ w_i²`` is an
unbiased estimate of σ² for any white noise distribution (Gaussian, quantisation), on
uniform and on jittered stamps alike. :func:`noise_std` averages it over every window of
k + 1 finite samples (windows across a gap longer than ``max_gap`` median steps are left
out), robustly by default: windows whose D²/Σw² exceeds 50 × the median are left out
(for Gaussian noise that is χ²₁ > 22.7, probability 2e-6; uniform quantisation noise
never gets there), so that the sparse windows where the residual jumps (Coulomb friction
switching sign, an impact, a logging glitch) do not count; ``robust=False`` keeps them. Applied to a model's residual ``y − ŷ`` rather than to ``y`` itself, what is left
of the smooth part is only the model's (smooth) systematic error, so the estimate holds
for fast signals too.

Coloured noise (a sensor with its own low-pass filter) is underestimated at stride 1: its
high-frequency content is what neighbouring samples see. With ``correlation_s`` the
differences are also taken over samples 2, 4, 8 … apart until the estimate stops growing
(the noise decorrelates over the stride; a smooth systematic error leaks only as
(ω·stride·h)⁴), which recovers a 1-pole low-pass noise at 20–100 Hz within ~20 % on a model residual.
A low-pass just below the Nyquist frequency leaves nothing correlated over a few samples
but takes out the band stride-1 differences weigh most (0.8–0.9 × σ at 0.9–0.95 ×
Nyquist): a first growth significant against white noise's own scatter followed by a
plateau from stride 2 on is taken as that, and the stride-2 value is σ.

Under a large misfit (a hidden effect's error in the band where the noise decorrelates)
one channel alone cannot tell its noise's colour from that error; :func:`noise_stds` takes
it from the channels of the same sensor kind that resolve it.
"""

from __future__ import annotations

import math
from typing import Any, List, NamedTuple, Sequence, Tuple

import numpy as np

from .exceptions import InputError

__all__ = ["noise_std", "noise_stds", "DIFFERENCE_ORDER", "CORRELATION_S"]

DIFFERENCE_ORDER = 4
"""Order k of the divided differences (removes cubics; the smooth part leaks ~ h⁴)."""
CORRELATION_S = 0.05
"""Longest stride × step [s] the noise floor of a channel is looked for at (coloured noise
of a sensor low-pass down to ~20 Hz at 200 Hz and more; a 4th difference over 4 × 50 ms
leaks a smooth systematic error at 2 Hz by ~1 % of its amplitude, and a stride is only
kept when the estimate reaches a plateau)."""
_OUTLIER = 50.0
_PLATEAU = 1.1
_NEAR_PLATEAU = 1.3
#: first growth of noise coloured by a low-pass below 0.3 × the rate (≥ 2.4 seen)
_COLOURED = 1.5
#: standard deviation × √n of ln(stride-2 / stride-1 estimate) on white noise of n samples
#: (from the 4th difference's autocorrelation: 2 × 1.15; 1.55 measured)
_WHITE_SCATTER = 1.6
#: a first growth this many of those standard deviations above 1, followed by a plateau,
#: is noise coloured at the sample scale (white noise: both strides unbiased)
_SAMPLE_COLOUR_SD = 3.0


def _terms(t: np.ndarray, y: np.ndarray, k: int, max_gap: float, med: float) -> np.ndarray:
    """D²/Σw² of every window of k + 1 consecutive samples of (t, y) (module docs)."""
    n = t.size - k
    if n < 1:
        return np.zeros(0)
    span = t[k:] - t[:-k]
    keep = span <= max_gap * k * med
    d = np.zeros(n)
    w2 = np.zeros(n)
    for i in range(k + 1):
        ti = t[i : i + n]
        prod = np.ones(n)
        for j in range(k + 1):
            if j != i:
                prod *= (ti - t[j : j + n]) / med  # scaled by the median step: no over/underflow
        w = 1.0 / prod
        d += w * y[i : i + n]
        w2 += w * w
    keep &= np.isfinite(d) & (w2 > 0)
    return d[keep] ** 2 / w2[keep]


def _estimate(t: np.ndarray, y: np.ndarray, k: int, max_gap: float, med: float, stride: int, robust: bool) -> float:
    # windows of samples `stride` apart: the interleaved subsequences pooled
    u = np.concatenate([_terms(t[r::stride], y[r::stride], k, max_gap, med * stride) for r in range(stride)])
    if u.size < 2:
        return math.nan
    if robust:
        # sparse jumps (Coulomb friction switching, backlash impacts, logging glitches)
        # would dominate the mean: windows beyond 50 × the median (χ²₁ > 22.7, probability
        # 2e-6 for Gaussian noise, never for quantisation) are left out
        u = u[u <= _OUTLIER * float(np.median(u))]
    return float(math.sqrt(np.mean(u)))


class _Strides(NamedTuple):
    """The estimates of one channel at strides 1, 2, 4 … (``seq``), the one taken
    (``sigma``) and whether its colour was resolved (``resolved``: white, or a plateau
    reached; else the stride-1 value was kept although the estimate grew)."""

    sigma: float
    seq: Tuple[float, ...]
    resolved: bool


def _strides(t: np.ndarray, y: np.ndarray, k: int, max_gap: float, robust: bool, correlation_s: float) -> _Strides:
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    if t.size - k < 2:
        return _Strides(math.nan, (), True)
    med = float(np.median(np.diff(t)))
    if not med > 0:
        return _Strides(math.nan, (), True)
    est = _estimate(t, y, k, max_gap, med, 1, robust)
    if not (correlation_s > 0 and math.isfinite(est) and est > 0):
        return _Strides(est, (est,), True)
    # the estimates at strides 1, 2, 4 …; coloured noise: growth ratios that fall to a
    # plateau; the signal's curvature: ratios that do not fall (→ 2^k)
    seq = [est]
    stride = 1
    while 2 * stride * med <= correlation_s * (1 + 1e-9) and t.size // (2 * stride) > 4 * (k + 2):
        stride *= 2
        nxt = _estimate(t, y, k, max_gap, med, stride, robust)
        if not (math.isfinite(nxt) and nxt > 0):
            break
        seq.append(nxt)
    out = tuple(seq)
    sig = math.exp(_SAMPLE_COLOUR_SD * _WHITE_SCATTER / math.sqrt(t.size))
    if len(seq) > 2 and sig < seq[1] / seq[0] < _COLOURED and seq[2] / seq[1] <= _PLATEAU:
        # a significant first growth, then a plateau from stride 2 on: noise coloured at the
        # sample scale (a low-pass near the Nyquist frequency, whose zero there the stride-1
        # differences weigh most: 0.83-0.91 × σ at 0.9-0.95 × Nyquist); a smooth systematic
        # error would have grown faster at the next stride instead (×16 per stride)
        return _Strides(seq[1], out, True)
    growth, last = math.inf, 0
    for i in range(1, len(seq)):
        g = seq[i] / seq[i - 1]
        if g <= _PLATEAU:
            return _Strides(seq[i] if i > 1 else seq[0], out, True)
        if i == 1 and g < _COLOURED:
            return _Strides(seq[0], out, True)  # white noise plus the signal's curvature
        if g >= growth:
            break  # the signal's curvature takes over
        growth, last = g, i
    # no plateau: the last estimate before the signal took over, if it was close to one
    if last and growth <= _NEAR_PLATEAU:
        return _Strides(seq[last], out, True)
    return _Strides(seq[0], out, len(seq) < 2)


def noise_std(t: Any, y: Any, *, order: int = DIFFERENCE_ORDER, max_gap: float = 3.0, robust: bool = True,
              correlation_s: float = 0.0) -> float:
    """White-noise standard deviation of ``y`` sampled at ``t`` (same unit as ``y``);
    NaN samples are skipped. Returns NaN with fewer than ``order + 2`` finite samples.

    ``correlation_s`` [s] > 0 also finds noise coloured by a sensor's own low-pass filter
    (correlation time up to about half of it): the estimate is repeated on windows of
    samples 2, 4, 8 … apart (stride × step ≤ ``correlation_s``); when the estimate grows
    with the stride, each growth smaller than the last (coloured noise decorrelating) up
    to a plateau (growth below 10 %), the plateau is the noise; where the signal's own
    curvature takes over first (growth that speeds up), the last estimate before it, if
    its growth was below 30 %. Otherwise, and for white noise, the stride-1 value
    (:func:`noise_stds` then takes the colour from the channel's sibling sensors).

    >>> import numpy as np
    >>> t = np.arange(20000) / 500.0
    >>> y = np.sin(3 * t) + np.random.default_rng(0).normal(0, 0.01, t.size)
    >>> round(noise_std(t, y), 3)
    0.01
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    return _strides(t, y, int(order), max_gap, robust, correlation_s).sigma


def noise_stds(t: Any, ys: Sequence[Any], kinds: Sequence[str], *, order: int = DIFFERENCE_ORDER, max_gap: float = 3.0,
               robust: bool = True, correlation_s: float = CORRELATION_S) -> List[float]:
    """:func:`noise_std` of each channel of ``ys`` (sampled at ``t``), with the colour of a
    channel whose own estimate did not resolve it taken from the channels of its sensor
    kind (``kinds[i]``, e.g. :data:`popup.results.SENSORS`) that did.

    A channel with a systematic error in the band where its noise decorrelates (at 100 Hz a
    1-pole low-pass at 23 Hz, with an 11 Hz replay error beside it) shows an estimate that
    keeps growing with the stride: no plateau, so :func:`noise_std` keeps its stride-1 value,
    which a low-pass with its zero at the Nyquist frequency puts at 0.4 × σ. The ratio
    σ / (stride-1 estimate) depends only on the noise's autocorrelation, the sensor's
    filter, not on its level; a lab sets the axes (the units) of one kind of sensor alike,
    so the median ratio of the resolved channels of its kind, where it shows a coloured
    noise (at least the growth ``_COLOURED`` of a low-pass below 0.3 × the rate), is applied
    to the unresolved one's stride-1 value, but never beyond what any of its own longer
    strides allows: there its estimate is the noise's share at that stride (the kin's
    profile, estimate/σ) plus a systematic error, which only adds. A channel with no
    resolved kin keeps :func:`noise_std`'s value."""
    t = np.asarray(t, dtype=np.float64)
    if len(kinds) != len(ys):
        raise InputError(f"input kinds: {len(kinds)} sensor kinds for {len(ys)} channels; give one kind per channel")
    res = [_strides(t, np.asarray(y, dtype=np.float64), int(order), max_gap, robust, correlation_s) for y in ys]
    out = [r.sigma for r in res]
    for i, r in enumerate(res):
        if r.resolved or not (len(r.seq) > 1 and r.seq[0] > 0):
            continue
        kin = [q for j, q in enumerate(res) if j != i and kinds[j] == kinds[i] and q.resolved and len(q.seq) > 1
               and math.isfinite(q.sigma) and q.seq[0] > 0]
        if not kin:
            continue
        ratio = float(np.median([q.sigma / q.seq[0] for q in kin]))
        if ratio < _COLOURED:
            continue  # kin with white noise (or nearly): the stride-1 value stands
        # every stride bounds σ from above: its estimate is the noise's share there (the
        # kin's profile, estimate/σ) plus a systematic error that only adds
        bound = math.inf
        for k in range(1, len(r.seq)):
            prof = [q.seq[k] / q.sigma for q in kin if k < len(q.seq)]
            if prof:
                bound = min(bound, r.seq[k] / max(float(np.median(prof)), 1e-12))
        out[i] = float(max(min(r.seq[0] * ratio, bound), r.seq[0]))
    return out

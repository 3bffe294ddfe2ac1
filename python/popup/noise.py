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

Coloured noise (a sensor with its own low-pass filter) is underestimated by this
estimator: its high-frequency content is what the differences see.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["noise_std", "DIFFERENCE_ORDER"]

DIFFERENCE_ORDER = 4
"""Order k of the divided differences (removes cubics; the smooth part leaks ~ h⁴)."""
_OUTLIER = 50.0


def noise_std(t: Any, y: Any, *, order: int = DIFFERENCE_ORDER, max_gap: float = 3.0, robust: bool = True) -> float:
    """White-noise standard deviation of ``y`` sampled at ``t`` (same unit as ``y``);
    NaN samples are skipped. Returns NaN with fewer than ``order + 2`` finite samples.

    >>> import numpy as np
    >>> t = np.arange(20000) / 500.0
    >>> y = np.sin(3 * t) + np.random.default_rng(0).normal(0, 0.01, t.size)
    >>> round(noise_std(t, y), 3)
    0.01
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(y)
    t, y = t[ok], y[ok]
    k = int(order)
    n = t.size - k
    if n < 2:
        return math.nan
    h = np.diff(t)
    med = float(np.median(h))
    if not med > 0:
        return math.nan
    # windows [s, s + k]
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
    if keep.sum() < 2:
        return math.nan
    u = d[keep] ** 2 / w2[keep]
    if robust:
        # sparse jumps (Coulomb friction switching, backlash impacts, logging glitches)
        # would dominate the mean: windows beyond 50 × the median (χ²₁ > 22.7, probability
        # 2e-6 for Gaussian noise, never for quantisation) are left out
        u = u[u <= _OUTLIER * float(np.median(u))]
    return float(math.sqrt(np.mean(u)))

"""Interval coverage of the fit's uncertainty (popup.estimate): the Gauss-Newton covariance
inflated by n/n_eff, and the block jackknife next to it, checked against the truth over
families of linear problems (the diagnosis linearises its fits the same way)."""

from __future__ import annotations

import numpy as np
import pytest

from popup import estimate as est

N = 2000


def _design(t):
    return np.column_stack([np.sin(2 * np.pi * 0.3 * t), np.cos(2 * np.pi * 0.7 * t) * t / t[-1], np.ones(t.size)])


def _noise(kind, rng, t):
    w = rng.normal(size=t.size)
    if kind == "white":
        return w
    if kind.startswith("ar"):
        rho = float(kind[2:])
        e = np.empty(t.size)
        e[0] = w[0]
        for i in range(1, t.size):
            e[i] = rho * e[i - 1] + np.sqrt(1 - rho**2) * w[i]
        return e
    # heteroskedastic: thirty times the noise where the first regressor is large, late in the run
    return w * np.where((t > t[-1] * 0.6) & (np.abs(np.sin(2 * np.pi * 0.3 * t)) > 0.7), 30.0, 1.0)


def _coverage(kind, trials, seed):
    """Share of runs whose 95 % intervals cover every true θ: Gauss-Newton inflated by
    n/n_eff (lag-1 autocorrelation of the residual), and the wider of it and the jackknife."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / 500.0
    X = _design(t)
    theta = np.array([0.5, -1.0, 0.2])
    gn_hits = both_hits = 0
    for _ in range(trials):
        y = X @ theta + _noise(kind, rng, t)
        th, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ th
        s2 = float(np.mean(r**2))
        rho = float(np.corrcoef(r[:-1], r[1:])[0, 1])
        inflate = N / float(est.n_eff(np.array([N]), np.array([rho]))[0])
        J = -X / np.sqrt(s2)  # the weighted problem: residual variance 1
        gn = np.diag(np.linalg.inv(J.T @ J)) * max(inflate, 1.0)
        jk = est._jackknife_var(J, r / np.sqrt(s2), t)
        gn_hits += bool(np.all(np.abs(th - theta) <= 1.96 * np.sqrt(gn)))
        both_hits += bool(np.all(np.abs(th - theta) <= 1.96 * np.sqrt(np.maximum(gn, jk))))
    return gn_hits / trials, both_hits / trials


# three parameters jointly, each at 95 %: about 0.86 when independent (300 runs: ±0.02)
@pytest.mark.parametrize("kind", ["white", "ar0.9"])
def test_intervals_keep_their_level_on_stationary_noise(kind):
    gn, both = _coverage(kind, 300, 1)
    assert 0.82 <= both <= 0.97 and both >= gn, (gn, both)


def test_the_jackknife_covers_what_the_gauss_newton_covariance_assumes_away():
    gn, both = _coverage("hetero", 300, 2)
    # noise thirty times larger in a part of the run: Gauss-Newton (one variance per
    # channel) under-covers, the jackknife brings the level back
    assert gn < 0.82, gn
    assert both >= 0.9 and both - gn >= 0.1, (gn, both)


def test_the_likelihood_ratio_is_finite_when_a_noise_free_channel_is_replayed_exactly():
    """Found by the slow pressure-leak test: the popup engine writes p1 p2 without noise, the
    fitted leak replays them exactly (mean square 0), and ln(ms0/ms1) overflowed (a
    RuntimeWarning, an error under pytest, so the leak was reported "not tested")."""

    class Stats:  # the part of a ReplayProblem that log_ratio reads
        def channel_stats(self, z, mask):
            ms = np.mean(np.asarray(z)[mask] ** 2, axis=0)
            return ms, np.full(ms.shape, float(mask.sum())), np.zeros(ms.shape)

    n = 400
    rng = np.random.default_rng(0)
    mask = np.ones(n, dtype=bool)
    before = np.column_stack([rng.normal(0, 2.0, n), np.full(n, 3e9)])  # p channel 3e9 noise units off
    after = np.column_stack([rng.normal(0, 1.0, n), np.zeros(n)])  # ... and exact after the fit
    lr, ne = est.log_ratio(Stats(), before, after, mask)
    assert np.isfinite(lr) and lr > 0 and ne == 2 * n
    expected = n * (np.log(np.mean(before[:, 0] ** 2)) - np.log(np.mean(after[:, 0] ** 2))) + n * (np.log(9e18) - np.log(1e-300))
    assert lr == pytest.approx(expected, rel=1e-12)

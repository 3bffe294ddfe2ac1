"""Joint motion the encoder does not show: a servo that yields to the links inside a reading.

A motor joint held by a servo of finite stiffness k [N·m/rad] moves by about −τ/k under
its torque τ. The encoder records that motion only where it crosses a reading. With a
coarse encoder (a 12-bit motor encoder behind a 100:1 gear reads 1.5e-5 rad at the joint)
the links' ringing moves a held joint by a fraction of a reading, unseen, and the replay
holds it still. That motion is the servo's compliance in series with the links' bending:
it lowers their modes by a few 1e-4, and over tens of cycles of ringing the replay drifts
out of phase by more than a quiet IMU's noise. A tiny change of the links' dynamics (a
fraction of a gram of payload, near-neutral wrinkling) then fits the misfit as well, and
would be added as an effect the run does not have.

Method (:func:`fit_unseen_motion`)
----------------------------------
**Holds.** Per motor joint, the stretches of at least :data:`HOLD_MIN_S` where the smoothed
angle moves slower than :data:`HOLD_READINGS_PER_S` readings per second and the readings
stay on at most :data:`HOLD_LEVELS` neighbouring levels. There the servo holds the joint and its motion is all
inside a reading: the readings only flip when it crosses a level, and the smoothing turns
each flip into a step of one reading. In a hold the readings are replaced by their mean
and smoothed again with the joint's own λ (:func:`popup.smoothing.smooth_at`), and the
motion −c_j (τ_j − mean τ_j over the hold) is added, with τ the model's own replayed motor
torque and c_j = 1/k_j ≥ 0 [rad/(N·m)] the servo's compliance (smoothed with the same λ, so
that it starts and ends with the hold). Outside the holds the encoder sees the joint move.
The flattening alone is worse than the readings (the motion it leaves out is what rings
the links); the two go together.

**Fit.** The channels respond linearly to motion this small: one replay per joint gives
the response, and the c_j minimise the noise-weighted training residual (bounded linear
least squares). Each c_j is bounded so that the motion stays inside a reading,
max |c_j (τ_j − mean τ_j)| ≤ :data:`UNSEEN_READINGS` × w_j (w_j
:attr:`ReplayProblem.encoder_width`), so a play, a payload or any effect larger than the
encoder's resolution is never absorbed. The result is kept only when, against the replay
of the readings as smoothed, it passes the likelihood-ratio test an effect must pass
(:data:`popup.estimate.SCORE_THRESHOLD`, k the number of nonzero c_j) and lowers the
systematic error of the training samples; otherwise the replay
is unchanged, bit for bit. An exact encoder (w = 0), a reference replay and an unsmoothed
encoder get nothing.

Where it is used: :func:`popup.diagnose` and :func:`popup.improve`, on the nominal model
and again after each effect the loop adds (the torque changes with the model). In a round
with no effect added yet, every candidate is refitted from its fit on the replay without
the motion (:func:`popup.diagnosis.candidate.screen_without_unseen`), and the
:data:`popup.diagnosis.rules.UNSEEN_TOP` leading candidates after that are also refitted on
the motion their own model gives
(:func:`popup.diagnosis.candidate.refit_with_own_unseen`, from the nominal model's motion
and from none), scored against the same nominal replay: fitted on the nominal model, the
compliance takes part of a missing softening (a near-threshold wrinkling on popup's engine
was pulled to another basin and a payload ranked first), and a fit started from it stays in
its basin (a 0.4 g payload and a wrinkling each ranked below the other; a near-threshold
torsion, held at its stiffness cap, ranked 9th). The
comparison (:func:`popup.compare`) and :func:`popup.fit_params` replay the encoder as
smoothed. On MuJoCo runs with 12-bit encoders and servos of 1.8e6 N·m/rad (compliance
5.6e-7 rad/(N·m)) the fitted compliances are 0.13-2.9 × that, median 1.01 ×, and the replays
go from 1.3-4.2 × their noise to 1.0-1.5 × (eight of nine at their floors); on popup's engine (rigid joints)
nothing is fitted (docs/effects.md, benchmarks/README.md).
"""

from __future__ import annotations

import math
from typing import List, Tuple

import numpy as np

from . import estimate as est
from .problem import ReplayProblem
from .smoothing import smooth_at

__all__ = ["fit_unseen_motion", "holds", "replayed_torque", "UNSEEN_READINGS", "HOLD_MIN_S", "HOLD_READINGS_PER_S", "HOLD_LEVELS"]

UNSEEN_READINGS = 1.0
"""The unseen motion stays within this many readings of the held angle."""
HOLD_MIN_S = 0.1
"""Shortest hold [s]."""
HOLD_READINGS_PER_S = 100.0
"""A joint whose smoothed angle moves slower than this many readings per second is held."""
HOLD_LEVELS = 3
"""Most neighbouring levels the readings of a hold visit (a gravity-loaded joint's ringing
can move it by about a reading either way)."""


def replayed_torque(prob: ReplayProblem) -> np.ndarray:
    """(n_enc, 3) the model's replayed motor torques [N·m] on the encoder stamps."""
    res = prob.nominal_result()
    t, tau = np.asarray(res.time, dtype=float), np.asarray(res.tau, dtype=float)
    return np.column_stack([np.interp(prob.t_enc, t, tau[:, j]) for j in range(3)])


def holds(prob: ReplayProblem) -> List[List[Tuple[int, int]]]:
    """Per motor joint, the holds (module docs) as ``[start, end)`` encoder-sample ranges."""
    t, q, raw = prob.t_enc, prob.q_base, np.asarray(prob.q_enc_raw)
    w = np.asarray(prob.encoder_width, dtype=float)
    out: List[List[Tuple[int, int]]] = [[], [], []]
    if prob.closed or prob.smoothing is None or len(t) < 3:
        return out
    for j in range(3):
        if not w[j] > 0:
            continue
        slow = np.abs(np.gradient(q[:, j], t)) < HOLD_READINGS_PER_S * w[j]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], slow.astype(np.int8), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            if t[b - 1] - t[a] >= HOLD_MIN_S and np.ptp(raw[a:b, j]) <= (HOLD_LEVELS - 1 + 0.001) * w[j]:
                out[j].append((int(a), int(b)))
    return out


def fit_unseen_motion(prob: ReplayProblem) -> ReplayProblem:
    """``prob`` with the unseen motion of its held motor joints in the replayed angles
    (module docs), or ``prob`` itself (its correction removed, if it had one) when that is
    not significant. The compliances found are :attr:`ReplayProblem.compliance`
    [rad/(N·m)] and a note says so."""
    if prob.closed or prob.smoothing is None:
        return prob
    plain = prob.with_unseen_motion(np.zeros(3), np.zeros_like(prob.q_corr)) if np.any(prob.q_corr != 0) else prob
    try:
        return _fit(plain)
    except Exception as e:  # noqa: BLE001 - the replay as smoothed is still a valid replay
        plain.notes.append(f"unseen joint motion (popup.unseen) not fitted: {type(e).__name__}: {e}")
        return plain


def _fit(plain: ReplayProblem) -> ReplayProblem:
    hs = holds(plain)
    joints = [j for j in range(3) if hs[j]]
    if not joints:
        return plain
    t, raw = plain.t_enc, np.asarray(plain.q_enc_raw, dtype=float)
    assert plain.smoothing is not None
    lams = plain.smoothing.params.get("lam", [None] * 3)
    tau = replayed_torque(plain)
    w = np.asarray(plain.encoder_width, dtype=float)
    flat = plain.q_base.copy()
    delta = np.zeros_like(flat)
    for j in joints:
        y = raw[:, j].copy()
        for a, b in hs[j]:
            y[a:b] = raw[a:b, j].mean()
            delta[a:b, j] = tau[a:b, j] - tau[a:b, j].mean()
        if lams[j] is not None:
            flat[:, j] = smooth_at(t, y, lams[j])
            delta[:, j] = smooth_at(t, delta[:, j], lams[j])
        else:
            flat[:, j] = y
    peak = np.max(np.abs(delta), axis=0)
    cmax = np.where(peak > 0, UNSEEN_READINGS * w / np.where(peak > 0, peak, 1.0), 0.0)
    joints = [j for j in joints if cmax[j] > 0]
    if not joints:
        return plain
    base = plain.with_unseen_motion(np.zeros(3), flat - plain.q_base)
    y0 = base.nominal_simulation()
    zf = base.residuals(y0)
    sig = base.sigma
    cols = []
    for j in joints:
        q = flat.copy()
        q[:, j] -= cmax[j] * delta[:, j]
        y = base.replay_angles(q)
        cols.append((y - y0) / sig / cmax[j])
    ok = base.train[:, None] & np.isfinite(zf) & np.all([np.isfinite(c) for c in cols], axis=0)
    # each channel weighed by its whole residual variance (the fit's objective, estimate docs)
    ms, _, _ = base.channel_stats(zf, base.train)
    wgt = 1.0 / np.sqrt(np.maximum(np.nan_to_num(ms, nan=1.0), 1.0))
    A = np.column_stack([(c * wgt)[ok] for c in cols])
    b = -(zf * wgt)[ok]
    from scipy.optimize import lsq_linear

    sol = lsq_linear(A, b, bounds=(0.0, cmax[joints]), method="bvls")
    c = np.zeros(3)
    c[joints] = np.clip(sol.x, 0.0, cmax[joints])
    k = int(np.count_nonzero(c))
    if k == 0:
        return plain
    cand = plain.with_unseen_motion(c, flat - plain.q_base - delta * c[None, :])
    z0 = plain.residuals(plain.nominal_simulation())
    z1 = cand.residuals(cand.nominal_simulation())
    lr, neff = est.log_ratio(plain, z0, z1, plain.train)
    if not (lr - k * math.log(neff) > est.SCORE_THRESHOLD and plain.error(z1, plain.train)[0] < plain.error(z0, plain.train)[0]):
        return plain
    held = sum(t[e - 1] - t[s] for j in joints for s, e in hs[j])
    cand.notes.append("unseen joint motion (popup.unseen): compliance " + ", ".join(f"{v:.3g}" for v in c)
                      + f" rad/(N·m) per motor joint, in {held:.3g} s of holds")
    return cand

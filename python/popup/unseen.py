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
Per motor joint j a compliance c_j = 1/k_j ≥ 0 [rad/(N·m)], the replayed angle moved to
``q_j − c_j (τ_j − mean τ_j)`` with τ the model's own replayed motor torque (its mean, a
static deflection, the encoder does see). The channels respond linearly to motion this
small: one replay per joint gives the response, and the c_j minimise the noise-weighted
training residual (bounded linear least squares). Each c_j is bounded so that the motion
stays inside a reading: RMS of ``c_j (τ_j − mean τ_j)`` ≤ ``w_j / √12`` (w_j
:attr:`ReplayProblem.encoder_width`, the RMS error of a uniform reading), so a play, a
payload or any effect larger than the encoder's resolution is never absorbed. The
compliances are kept only when they pass the likelihood-ratio test an effect must pass
(:data:`popup.estimate.SCORE_THRESHOLD`, k the number of nonzero c_j) and lower the
replay's error on the training samples; otherwise the replay is unchanged, bit for bit.
An exact encoder (w = 0), a reference replay and an unsmoothed encoder get nothing.

Where it is used: :func:`popup.diagnose` and :func:`popup.improve`, on the nominal model
and again after each effect the loop adds (the torque changes with the model). The
comparison (:func:`popup.compare`) and :func:`popup.fit_params` replay the encoder as
smoothed. On a MuJoCo run (12-bit encoders, servos of 1.8e6 N·m/rad) the fitted joint-2
compliance was 7.1e-7 (the truth 5.6e-7) and the replay went from 1.27 to 1.04 × its floor.
"""

from __future__ import annotations

import math
import numpy as np

from . import estimate as est
from .problem import ReplayProblem

__all__ = ["fit_unseen_motion", "unseen_bound", "replayed_torque", "UNSEEN_READINGS"]

UNSEEN_READINGS = 1.0
"""The unseen motion's RMS is at most this many RMS errors of a uniform reading (w/√12)."""


def replayed_torque(prob: ReplayProblem) -> np.ndarray:
    """(n_enc, 3) the model's replayed motor torques [N·m] on the encoder stamps, less their mean."""
    res = prob.nominal_result()
    t, tau = np.asarray(res.time, dtype=float), np.asarray(res.tau, dtype=float)
    out = np.column_stack([np.interp(prob.t_enc, t, tau[:, j]) for j in range(3)])
    return out - out.mean(axis=0)


def unseen_bound(prob: ReplayProblem, tau: np.ndarray) -> np.ndarray:
    """(3,) the largest compliance [rad/(N·m)] per joint whose motion under the demeaned
    torques ``tau`` stays inside a reading (module docs); 0 for an exact encoder."""
    w = np.asarray(prob.encoder_width, dtype=float)
    s = np.sqrt(np.mean(tau * tau, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where((w > 0) & (s > 0), UNSEEN_READINGS * w / (math.sqrt(12.0) * s), 0.0)
    return np.nan_to_num(c)


def fit_unseen_motion(prob: ReplayProblem) -> ReplayProblem:
    """``prob`` with the unseen motion of its motor joints added to the replayed angles
    (module docs), or ``prob`` itself when none is significant. The compliances found are
    :attr:`ReplayProblem.compliance` [rad/(N·m)] and a note says so."""
    if prob.closed or prob.smoothing is None:
        return prob
    base_prob = prob.with_unseen_motion(np.zeros(3), np.zeros_like(prob.q_corr)) if np.any(prob.q_corr != 0) else prob
    tau = replayed_torque(base_prob)
    cmax = unseen_bound(base_prob, tau)
    joints = [j for j in range(3) if cmax[j] > 0]
    if not joints:
        return base_prob
    y0 = base_prob.nominal_simulation()
    z0 = base_prob.residuals(y0)
    sig = base_prob.sigma
    cols = []
    for j in joints:
        q = base_prob.q_base.copy()
        q[:, j] -= cmax[j] * tau[:, j]
        try:
            y = base_prob._replay_channels(q)
        except Exception:  # noqa: BLE001 - a joint the engine refuses to move is left alone
            return base_prob
        cols.append((y - y0) / sig / cmax[j])
    ok = base_prob.train[:, None] & np.isfinite(z0) & np.all([np.isfinite(c) for c in cols], axis=0)
    # each channel weighed by its whole residual variance (the fit's objective, estimate docs)
    ms, _, _ = base_prob.channel_stats(z0, base_prob.train)
    wgt = 1.0 / np.sqrt(np.maximum(np.nan_to_num(ms, nan=1.0), 1.0))
    A = np.column_stack([(c * wgt)[ok] for c in cols])
    b = -(z0 * wgt)[ok]
    from scipy.optimize import lsq_linear

    sol = lsq_linear(A, b, bounds=(0.0, cmax[joints]), method="bvls")
    c = np.zeros(3)
    c[joints] = np.clip(sol.x, 0.0, cmax[joints])
    k = int(np.count_nonzero(c))
    if k == 0:
        return base_prob
    cand = base_prob.with_unseen_motion(c, -tau * c[None, :])
    z1 = cand.residuals(cand.nominal_simulation())
    lr, neff = est.log_ratio(base_prob, z0, z1, base_prob.train)
    if not (lr - k * math.log(neff) > est.SCORE_THRESHOLD):
        return base_prob
    cand.notes.append("unseen joint motion (popup.unseen): compliance " + ", ".join(f"{v:.3g}" for v in c)
                      + " rad/(N·m) per motor joint, motion inside a reading")
    return cand


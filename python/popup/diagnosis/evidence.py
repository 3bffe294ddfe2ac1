"""The residual signature of each effect (``effects.md``), measured on the nominal residual:
the evidence a suspect carries beside its fit."""

from __future__ import annotations

import math
from typing import Any, Dict, Sequence, Tuple

import numpy as np

from .. import effects as fx
from ..compare import Comparison
from ..problem import ReplayProblem


def evidence_for(effect: str, cmp: Comparison, prob: ReplayProblem) -> Dict[str, Any]:
    sig = fx.SIGNATURES.get(effect, "")
    res = cmp.residuals
    t = res.index.to_numpy()
    ev: Dict[str, Any] = {"signature": sig, "statistic": "", "value": math.nan, "text": ""}
    try:
        dq = {j: _rate(prob, j, t) for j in range(3)}
        if effect == "joint_friction":
            best = (0.0, "", 0.0, 0.0)
            for j in range(3):
                c = f"tau{j + 1}"
                if c not in res:
                    continue
                e = res[c].to_numpy()
                ok = np.isfinite(e)
                X = np.column_stack([np.tanh(dq[j] / 1e-2), dq[j], np.ones_like(e)])[ok]
                coef, *_ = np.linalg.lstsq(X, e[ok], rcond=None)
                r2 = 1.0 - float(np.var(e[ok] - X @ coef)) / max(float(np.var(e[ok])), 1e-300)
                if r2 > best[0]:
                    best = (r2, c, float(coef[0]), float(coef[1]))
            ev.update(statistic="R² of torque residual on sign(q̇), q̇", value=best[0],
                      text=f"{best[1]} residual ≈ {best[2]:.3g}·sign(q̇) + {best[3]:.3g}·q̇ explains {100 * best[0]:.0f} % of its variance" if best[1] else "no torque channel")
        elif effect == "backlash":
            e2 = _e2(cmp, ["ee_x", "ee_y", "ee_z", "imu2_ax", "imu2_ay", "imu2_az"])
            near = np.zeros(len(t), bool)
            for j in range(3):
                s = np.sign(dq[j])
                flips = np.nonzero((s[1:] * s[:-1]) < 0)[0]
                for f in flips:
                    near |= (t >= t[f]) & (t <= t[f] + 0.3)
            ratio = _share_ratio(e2, near)
            ev.update(statistic="error share / sample share within 0.3 s after velocity reversals", value=ratio,
                      text=f"the 0.3 s after velocity reversals carry {ratio:.2f}× their share of the tip error")
        elif effect == "higher_bending_modes":
            f1 = _first_mode_hz(prob)
            psd = cmp.psd
            f = psd.index.to_numpy()
            tot = psd.sum(axis=1).to_numpy() if psd is not None else np.zeros(1)
            above = float(tot[f > 1.5 * f1].sum() / max(tot.sum(), 1e-300)) if psd is not None else math.nan
            ev.update(statistic="share of residual power above 1.5× the first bending mode", value=above,
                      text=f"{100 * above:.0f} % of the residual power lies above 1.5 × {f1:.2f} Hz (first locked mode)")
        elif effect == "pressure_leak":
            e2 = _e2(cmp, list(res.columns))
            thirds = np.array_split(np.arange(len(t)), 3)
            m = [float(np.mean(e2[ix])) for ix in thirds]
            growth = m[2] / max(m[0], 1e-300)
            ev.update(statistic="mean squared error last third / first third", value=growth,
                      text=f"the squared residual grows {growth:.2f}× from the first to the last third of the run")
        elif effect == "wrinkling":
            c = cmp.conditions
            rows = c[c["binning"] == "|M|/M_w"]
            hi = rows[rows["bin"].isin(["0.8-1", ">1"])]
            ratio = float(hi["error_share"].sum() / max(hi["sample_share"].sum(), 1e-300)) if len(hi) and hi["sample_share"].sum() > 0 else math.nan
            ev.update(statistic="error share / sample share where |M|/M_w > 0.8", value=ratio,
                      text=f"samples with |M| > 0.8·M_w carry {ratio:.2f}× their share of the error" if math.isfinite(ratio) else "no sample near M_w")
        elif effect == "payload_mass":
            chans = [c for c in ("tau2", "tau3", "ee_z") if c in res]
            means = {c: float(np.nanmean(res[c])) / max(float(np.nanstd(prob.measured[:, prob.channels.index(c)])), 1e-300) for c in chans}
            c = max(means, key=lambda k: abs(means[k])) if means else ""
            ev.update(statistic="mean residual / measured std of the gravity-loaded channels", value=abs(means.get(c, 0.0)),
                      text=f"{c} has a bias of {means.get(c, 0.0):+.2f} std (gravity load or sag)" if c else "no gravity-loaded channel")
        elif effect == "sensor_delay":
            d = cmp.delay
            if d is not None and len(d):
                d2 = d[~d["at_limit"]]
                if len(d2):
                    gain = (1 - d2["rmse_at_delay"] / d2["rmse_at_zero"]).astype(float)
                    c = str(gain.idxmax())
                    ev.update(statistic="best aligning shift [s] of the channel it helps most", value=float(d2.loc[c, "delay_s"]),
                              text=f"{c}: shifting the measurement by {1e3 * float(d2.loc[c, 'delay_s']):.1f} ms lowers its RMSE by {100 * float(gain[c]):.0f} %")
        elif effect == "actuator_saturation":
            sat: Tuple[float, str] = (0.0, "")
            for j in range(3):
                c = f"tau{j + 1}"
                if c not in res:
                    continue
                y = prob.measured[:, prob.channels.index(c)]
                at = np.abs(y) >= 0.98 * np.nanmax(np.abs(y))
                e2 = res[c].to_numpy() ** 2
                r = _share_ratio(np.where(np.isfinite(e2), e2, 0.0), at)
                if r > sat[0]:
                    sat = (r, c)
            ev.update(statistic="error share / sample share while |τ| is within 2 % of its maximum", value=sat[0],
                      text=f"{sat[1]}: samples at the torque maximum carry {sat[0]:.2f}× their share of its error" if sat[1] else "no torque channel")
        elif effect == "air_drag":
            c = cmp.conditions
            rows = c[(c["binning"] == "tip speed") & (c["bin"] == "high")]
            ratio = float(rows["ratio"].iloc[0]) if len(rows) else math.nan
            ev.update(statistic="error share / sample share in the fastest tip-speed tercile", value=ratio,
                      text=f"the fastest third of the tip speeds carries {ratio:.2f}× its share of the error")
        elif effect == "torsion":
            e2 = _e2(cmp, [c for c in ("ee_y", "imu1_ay", "imu2_ay") if c in res])
            moving = np.abs(dq[0]) > 0.05 * max(float(np.max(np.abs(dq[0]))), 1e-9)
            ratio = _share_ratio(e2, moving)
            ev.update(statistic="lateral error share / sample share while q1 moves", value=ratio,
                      text=f"lateral channels carry {ratio:.2f}× their share of the error while q1 turns")
    except Exception as e:  # noqa: BLE001 - evidence must never break a diagnosis
        ev["text"] = f"evidence not computed: {e}"
    return ev


def _rate(prob: ReplayProblem, j: int, t: np.ndarray) -> np.ndarray:
    return np.interp(t, prob.t_enc, np.gradient(prob.q_enc[:, j], prob.t_enc))


def _e2(cmp: Comparison, chans: Sequence[str]) -> np.ndarray:
    res = cmp.residuals
    tot = np.zeros(len(res))
    for c in chans:
        if c in res:
            y = cmp.measured.channel(c)
            s = float(np.nanstd(y)) or 1.0
            e = res[c].to_numpy() / s
            tot += np.where(np.isfinite(e), e * e, 0.0)
    return tot


def _share_ratio(e2: np.ndarray, mask: np.ndarray) -> float:
    if not mask.any() or mask.all():
        return math.nan
    return float(e2[mask].sum() / max(e2.sum(), 1e-300)) / float(mask.mean())


def _first_mode_hz(prob: ReplayProblem) -> float:
    try:
        modes = [float(x) for x in np.asarray(prob.model.locked_modes(list(prob.q_enc[0])), float) if x > 0]
        return min(modes) / (2 * math.pi) if modes else math.nan
    except Exception:  # noqa: BLE001
        return math.nan

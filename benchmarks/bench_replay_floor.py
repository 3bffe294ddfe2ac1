"""Replay at the noise floor: how far above the sensor noise does an encoder replay with the
TRUE model leave each channel, raw (the engine's natural spline interpolating the encoder
samples) and smoothed (:func:`popup.smoothing.smooth_encoder`)?

Printed is RMSE(measured − replay) / true noise std (:data:`popup.synth.NOISE`), 1.00 =
at the noise floor, as the worst channel of each group (``tau1..3``, ``ee_x..z``,
``imu1_a*``, ``imu2_a*``); the truth and the replayed model are ``popup-lab`` with 1 kg.

**A. Encoder floor** — the synthetic runs of :func:`popup.synth.measured_run`: the truth
replays the *exact* angles at the stamps (the same natural spline), the encoder is
quantised (after its own white noise, when there is some), white sensor noise is added.
With jittered stamps both simulations are sampled at the mean rate and interpolated
linearly onto the stamps (as :func:`popup.compare.compare` does), which cancels between
them; so the only difference between truth and replay is the encoder's error. The
``ideal`` column is the ratio of the truth itself (the noise draw: a perfect replay).

**B. Continuous truth** — the arm moves along the continuous trajectory (truth simulated
at ``dt = 0.1 ms`` from 10 kHz exact angles, read at the stamps), the replay model
(``dt = 1 ms``) sees only the quantised encoder at the stamps, and its output is put onto
the stamps linearly (``lin``, as compare does today) or by a cubic spline through the
simulated samples (``cub``). Shows what else sets the floor besides the encoder.

**C. Record starting mid-motion** — as B, but the record begins while the arm moves
(at 2 s or 4 s into the chirp, q̈ ≠ 0): the replay starts at rest (the default) or in the
truth's state there (joint angles and rates, as an ``[initial]`` table gives them); the
exact encoder from the truth's state shows the engine's own natural-spline end.

    python benchmarks/bench_replay_floor.py            # everything, about 20 s on 2 cores
    python benchmarks/bench_replay_floor.py --quick    # a few families of A, 4 s runs
    python benchmarks/bench_replay_floor.py --channels # A: every channel, not just groups
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from scipy.interpolate import CubicSpline

import popup
from popup.smoothing import smooth_encoder
from popup.synth import ENCODER_RESOLUTION, NOISE

CHANNELS: Tuple[str, ...] = ("tau1", "tau2", "tau3", "ee_x", "ee_y", "ee_z", "imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az")
GROUPS: Dict[str, Tuple[str, ...]] = {"tau": CHANNELS[:3], "ee": CHANNELS[3:6], "imu1": CHANNELS[6:9], "imu2": CHANNELS[9:12]}
POSE = np.array([0.0, -math.pi / 2 + 0.6, 0.5])


def noise_std(ch: str) -> float:
    return NOISE["tau"] if ch.startswith("tau") else NOISE["ee"] if ch.startswith("ee_") else NOISE["imu"]


# ------------------------------------------------------------ excitations
@lru_cache(maxsize=4)
def _lab_spline(duration: float, seed: int) -> CubicSpline:
    t, q = popup.synth.lab_trajectory(duration, rate=20_000.0, seed=seed)
    return CubicSpline(t, q, axis=0)


def chirp(t: np.ndarray, duration: float, f_max: float, amp: Sequence[float], f0: float = 0.2, deriv: int = 0) -> np.ndarray:
    """Linear chirp f0 → f_max over ``duration`` about :data:`POSE` with a sin² envelope
    (at rest at both ends), amplitude per joint ``amp`` [rad]; ``deriv`` 0, 1 or 2 gives
    the angle or its exact first or second derivative."""
    s = t / duration
    k = (f_max - f0) / duration
    ph = 2 * math.pi * (f0 * t + 0.5 * k * t**2)
    w = 2 * math.pi * (f0 + k * t)  # dφ/dt
    e = np.sin(math.pi * s) ** 2
    de = math.pi / duration * np.sin(2 * math.pi * s)
    dde = 2 * (math.pi / duration) ** 2 * np.cos(2 * math.pi * s)
    sn, cs = np.sin(ph), np.cos(ph)
    if deriv == 0:
        base = e * sn
    elif deriv == 1:
        base = de * sn + e * w * cs
    else:
        dw = 2 * math.pi * k
        base = dde * sn + 2 * de * w * cs + e * (dw * cs - w * w * sn)
    out = np.outer(base, np.asarray(amp, dtype=float))
    return out + (POSE if deriv == 0 else 0.0)


#: name: (duration [s], description)
EXCITATIONS: Dict[str, Tuple[float, str]] = {
    "lab": (12.0, "popup.synth.lab_trajectory, seed 1 (moves, holds, q1 reversals, 0.2-3 Hz chirp of q2/q3)"),
    "chirp1-5Hz": (8.0, "q1 chirp 0.2-5 Hz, 0.01 rad, sin² envelope"),
    "chirp123-8Hz": (8.0, "chirp 0.2-8 Hz of every joint, 0.005/0.0025/0.005 rad, sin² envelope"),
}


def excitation(name: str, t: np.ndarray, seed: int = 1) -> np.ndarray:
    """Exact angles (N, 3) [rad] of an excitation at the times ``t``."""
    dur = EXCITATIONS[name][0]
    if name == "lab":
        return np.asarray(_lab_spline(dur, seed)(t))
    if name == "chirp1-5Hz":
        return chirp(t, dur, 5.0, (0.01, 0.0, 0.0))
    if name == "chirp123-8Hz":
        return chirp(t, dur, 8.0, (0.005, 0.0025, 0.005))
    raise KeyError(name)


# ---------------------------------------------------------------- families
@dataclass(frozen=True)
class Family:
    rate: float
    jitter: float  # ± fraction of the mean interval
    step: Optional[float]  # quantisation step [rad]
    enc_noise: float  # encoder white noise std [rad], before quantisation
    excitation: str

    def label(self) -> str:
        st = "exact" if not self.step else f"{self.step:.1e}"
        return f"{self.excitation:<13}{self.rate:>5.0f} Hz jit {self.jitter:>3.0%} step {st:<7} noise {self.enc_noise:.0e}"


def stamps(rate: float, duration: float, jitter: float, seed: int, start: float = 0.0) -> np.ndarray:
    """Sample stamps at ``rate`` over ``[start, duration]``, interior ones jittered by
    ± ``jitter`` of the interval (uniform)."""
    n = int(round((duration - start) * rate)) + 1
    t = start + np.arange(n) / rate
    if jitter > 0:
        rng = np.random.default_rng(seed + 1000)
        t[1:-1] += rng.uniform(-jitter, jitter, n - 2) / rate
    return t


def encoder(fam: Family, x: np.ndarray, seed: int) -> np.ndarray:
    """The measured encoder: white noise, then quantisation."""
    rng = np.random.default_rng(seed)
    q = x + (rng.normal(0.0, fam.enc_noise, x.shape) if fam.enc_noise > 0 else 0.0)
    return np.round(q / fam.step) * fam.step if fam.step else q


def ratios(truth: Callable[[str], np.ndarray], replay: Callable[[str], np.ndarray], n: int, seed: int) -> Dict[str, float]:
    """RMSE(truth + sensor noise − replay) / noise std per channel (same noise draw for a
    given seed)."""
    rng = np.random.default_rng(seed + 7)
    out = {}
    for ch in CHANNELS:
        s = noise_std(ch)
        e = truth(ch) + rng.normal(0.0, s, n) - replay(ch)
        out[ch] = float(np.sqrt(np.mean(e * e)) / s)
    return out


def run_family(model: popup.Model, fam: Family, seed: int = 1, duration: Optional[float] = None) -> Dict[str, object]:
    """Section A: one synthetic run of the family; ratios per channel for the truth itself
    (``ideal``), the raw and the smoothed replay."""
    dur = EXCITATIONS[fam.excitation][0] if duration is None else duration
    t = stamps(fam.rate, dur, fam.jitter, seed)
    x = excitation(fam.excitation, t, seed)
    q = encoder(fam, x, seed)
    t0 = time.perf_counter()
    sm = smooth_encoder(t, q)
    smooth_ms = (time.perf_counter() - t0) * 1e3
    batch = model.rollout(encoder_t=t, encoder_q=np.stack([x, q, sm.q]), sample_rate=fam.rate, threads=0)
    ts = batch[0].channel("t")
    uniform = ts.shape == t.shape and bool(np.allclose(ts, t, rtol=0, atol=1e-9))

    def at(b: int) -> Callable[[str], np.ndarray]:
        return lambda ch: (np.asarray(batch[b].channel(ch)) if uniform else np.interp(t, ts, batch[b].channel(ch)))

    n = t.shape[0]
    return {
        "smooth": sm,
        "smooth_ms": smooth_ms,
        "ideal": ratios(at(0), at(0), n, seed),
        "raw": ratios(at(0), at(1), n, seed),
        "smoothed": ratios(at(0), at(2), n, seed),
    }


def families(quick: bool) -> List[Family]:
    R = ENCODER_RESOLUTION
    fams: List[Family] = []
    for exc in ("lab", "chirp1-5Hz", "chirp123-8Hz"):
        for rate in (200.0, 500.0, 1000.0):
            for jit in (0.0, 0.2):
                fams.append(Family(rate, jit, R, 0.0, exc))
    for rate in (500.0, 1000.0):
        for step in (1e-6, 1e-5, 1e-4):
            fams.append(Family(rate, 0.0, step, 0.0, "lab"))
        for nz in (2e-6, 1e-5):
            fams.append(Family(rate, 0.2, R, nz, "lab"))
            fams.append(Family(rate, 0.0, R, nz, "chirp123-8Hz"))
        fams.append(Family(rate, 0.2, None, 3e-6, "chirp1-5Hz"))
    fams.append(Family(1000.0, 0.0, None, 0.0, "lab"))
    if quick:
        keep = {(1000.0, 0.0, "lab"), (1000.0, 0.2, "chirp123-8Hz"), (200.0, 0.0, "chirp123-8Hz"), (500.0, 0.0, "chirp1-5Hz")}
        fams = [f for f in fams if (f.rate, f.jitter, f.excitation) in keep]
    return fams


def worst(r: Dict[str, float], group: str) -> float:
    return max(r[c] for c in GROUPS[group])


# ----------------------------------------------------- B, C: continuous truth
_TRUTH: Dict[Tuple[str, int], Tuple[np.ndarray, popup.SimResult]] = {}


def continuous_truth(exc: str, seed: int) -> Tuple[np.ndarray, popup.SimResult]:
    """The truth along the continuous trajectory: 10 kHz exact angles, dt = 0.1 ms."""
    key = (exc, seed)
    if key not in _TRUTH:
        dur = EXCITATIONS[exc][0]
        tf = np.arange(int(round(dur * 10_000)) + 1) / 10_000.0
        fine = popup.Model("popup-lab", payload_kg=1.0, dt=1e-4)
        _TRUTH[key] = (tf, fine.replay(tf, excitation(exc, tf, seed), sample_rate=10_000.0))
    return _TRUTH[key]


def run_continuous(
    model: popup.Model, fam: Family, seed: int = 1, start: float = 0.0, true_start: bool = False
) -> Dict[str, Dict[str, float]]:
    """Sections B and C: raw and smoothed replay against the continuous truth, aligned
    linearly (``lin``) or by a cubic spline (``cub``); ``start``: the record begins there;
    ``true_start``: the replay starts in the truth's state there (not at rest)."""
    tf, tr = continuous_truth(fam.excitation, seed)
    t = stamps(fam.rate, EXCITATIONS[fam.excitation][0], fam.jitter, seed, start=start)
    x = excitation(fam.excitation, t, seed)
    q = encoder(fam, x, seed)
    sm = smooth_encoder(t, q)
    iq: Optional[np.ndarray] = None
    iv: Optional[np.ndarray] = None
    if true_start:  # joint angles and rates of the truth at the first stamp
        at0 = lambda ch: float(np.interp(t[0], tr.channel("t"), tr.channel(ch)))  # noqa: E731
        iq = np.array([at0(n) for n in model.joint_names])
        iv = np.array([at0(("dq" + n[1:]) if n.startswith("q") else "d" + n) for n in model.joint_names])
    batch = model.rollout(encoder_t=t, encoder_q=np.stack([q, sm.q]), sample_rate=fam.rate, threads=0, initial_q=iq, initial_v=iv)
    ts = batch[0].channel("t")
    tt = tr.channel("t")

    def truth(ch: str) -> np.ndarray:
        return np.interp(t, tt, tr.channel(ch))  # 10 kHz: linear interpolation errs by ~1e-3 of the noise

    def lin(b: int) -> Callable[[str], np.ndarray]:
        return lambda ch: np.interp(t, ts, batch[b].channel(ch))

    def cub(b: int) -> Callable[[str], np.ndarray]:
        return lambda ch: CubicSpline(ts, batch[b].channel(ch))(t)

    n = t.shape[0]
    out = {
        "raw lin": ratios(truth, lin(0), n, seed),
        "smoothed lin": ratios(truth, lin(1), n, seed),
        "smoothed cub": ratios(truth, cub(1), n, seed),
    }
    return out


# --------------------------------------------------------------------- main
def main() -> None:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few families of section A, 4 s runs")
    ap.add_argument("--channels", action="store_true", help="section A: print every channel")
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    model = popup.Model("popup-lab", payload_kg=1.0)
    print(f"popup {popup.__version__} ({popup.build_profile}); model popup-lab, payload 1 kg, dt {model.dt:g} s; sensor noise {NOISE}; encoder step {ENCODER_RESOLUTION:.3e} rad")
    for name, (dur, desc) in EXCITATIONS.items():
        print(f"  {name}: {dur:g} s, {desc}")
    t_all = time.perf_counter()

    print("\nA. encoder floor: RMSE(measured - replay) / noise std, worst channel per group, raw -> smoothed")
    print(f"{'family':<55}{'ideal':>6}" + "".join(f"{g:>14}" for g in GROUPS) + f"{'cutoff Hz':>11}{'ms':>5}")
    top = {"raw": 0.0, "smoothed": 0.0}
    for fam in families(a.quick):
        r = run_family(model, fam, seed=a.seed, duration=4.0 if a.quick else None)
        sm = r["smooth"]
        ideal = max(r["ideal"].values())  # type: ignore[attr-defined]
        cells = ""
        for g in GROUPS:
            rw, sv = worst(r["raw"], g), worst(r["smoothed"], g)  # type: ignore[arg-type]
            top["raw"], top["smoothed"] = max(top["raw"], rw), max(top["smoothed"], sv)
            cells += f"{rw:>7.2f}->{sv:<5.2f}"
        cut = [c for c in sm.params["cutoff_hz"] if c is not None]  # type: ignore[attr-defined]
        cuts = "-" if not cut else f"{min(cut):.0f}-{max(cut):.0f}"
        print(f"{fam.label():<55}{ideal:>6.2f}{cells}{cuts:>11}{r['smooth_ms']:>5.0f}")
        if a.channels:
            for k in ("raw", "smoothed"):
                print(f"    {k:<9}" + " ".join(f"{c}={r[k][c]:.3f}" for c in CHANNELS))  # type: ignore[index]
    print(f"worst channel of section A: raw {top['raw']:.2f}, smoothed {top['smoothed']:.2f}")
    if a.quick:
        print(f"{time.perf_counter() - t_all:.0f} s")
        return

    R = ENCODER_RESOLUTION
    variants = ("raw lin", "smoothed lin", "smoothed cub")
    print("\nB. continuous truth (dt 0.1 ms, read at the stamps), encoder quantised; worst channel per group tau/ee/imu1/imu2;")
    print("   replay put onto the stamps linearly (lin, as compare does) or by a cubic spline (cub)")
    print(f"{'family':<55}" + "".join(f"{v:>26}" for v in variants))
    for exc in ("lab", "chirp123-8Hz"):
        for rate in (200.0, 500.0, 1000.0):
            for jit in (0.0, 0.2):
                fam = Family(rate, jit, R, 0.0, exc)
                rc = run_continuous(model, fam, seed=a.seed)
                print(f"{fam.label():<55}" + "".join(f"{' '.join(f'{worst(rc[v], g):.2f}' for g in GROUPS):>26}" for v in variants))

    print("\nC. record starting mid-motion (chirp123-8Hz, continuous truth, cubic alignment), worst channel per group tau/ee/imu1/imu2")
    print(f"   {'':<24}{'exact encoder, true state':>28}{'smoothed, from rest':>28}{'smoothed, true state':>28}")
    for start in (0.0, 2.0, 4.0):
        for rate in (200.0, 1000.0):
            row: List[str] = []
            for step, true_start in ((None, True), (R, False), (R, True)):
                rc = run_continuous(model, Family(rate, 0.0, step, 0.0, "chirp123-8Hz"), seed=a.seed, start=start, true_start=true_start)
                row.append(" ".join(f"{worst(rc['smoothed cub'], g):.2f}" for g in GROUPS))
            print(f"   starts at {start:3.1f} s, {rate:>5.0f} Hz" + "".join(f"{c:>28}" for c in row))
    print(f"\n{time.perf_counter() - t_all:.0f} s")


if __name__ == "__main__":
    main()

"""popup.smoothing: encoder smoothing for a replay at the noise floor.

Families of synthetic encoders (random smooth motions and chirps up to 8 Hz; 200/500/1000 Hz,
uniform or ±20 % jittered stamps; quantisation 1e-6..1e-4 rad; white noise) against the
exact angles and their exact q̈; then replays of :func:`popup.synth.measured_run` runs with
the true model, where the smoothed encoder must leave every channel at ≤ 1.1 × its noise.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy.interpolate import CubicSpline, make_smoothing_spline

import popup
from popup.exceptions import InputError
from popup.smoothing import SmoothedEncoder, detect_resolution, estimate_noise, smooth_at, smooth_encoder
from popup.synth import ENCODER_RESOLUTION, NOISE

R = ENCODER_RESOLUTION
CHANNELS = ("tau1", "tau2", "tau3", "ee_x", "ee_y", "ee_z", "imu1_ax", "imu1_ay", "imu1_az", "imu2_ax", "imu2_ay", "imu2_az")
POSE = np.array([0.0, -math.pi / 2 + 0.6, 0.5])


# ------------------------------------------------------------------ helpers
def stamps(rate: float, duration: float, jitter: float = 0.0, seed: int = 0) -> np.ndarray:
    n = int(round(duration * rate)) + 1
    t = np.arange(n) / rate
    if jitter:
        t[1:-1] += np.random.default_rng(seed).uniform(-jitter, jitter, n - 2) / rate
    return t


def trajectory(kind: str, t: np.ndarray, seed: int):
    """Exact angles and q̈ (N, 3) under a sin² window (at rest at both ends): ``smooth``
    = four random sines of 0.1-3 Hz per joint; ``chirp-F`` = a linear chirp 0.2 → F Hz of
    random amplitude 5-50 mrad per joint."""
    rng = np.random.default_rng(seed)
    u = t - t[0]
    T = float(u[-1])
    env = np.sin(np.pi * u / T) ** 2
    de = np.pi / T * np.sin(2 * np.pi * u / T)
    dde = 2 * (np.pi / T) ** 2 * np.cos(2 * np.pi * u / T)
    q = np.zeros((t.size, 3))
    a = np.zeros((t.size, 3))
    for j in range(3):
        if kind == "smooth":
            f = df = ddf = 0.0
            for _ in range(4):
                amp, w, ph = rng.uniform(0.05, 0.4), 2 * np.pi * rng.uniform(0.1, 3.0), rng.uniform(0, 2 * np.pi)
                f = f + amp * np.sin(w * u + ph)
                df = df + amp * w * np.cos(w * u + ph)
                ddf = ddf - amp * w * w * np.sin(w * u + ph)
        else:
            fmax = float(kind.split("-")[1])
            amp, k = rng.uniform(0.005, 0.05), (fmax - 0.2) / T
            ph, w = 2 * np.pi * (0.2 * u + 0.5 * k * u**2), 2 * np.pi * (0.2 + k * u)
            f, df, ddf = amp * np.sin(ph), amp * w * np.cos(ph), amp * (2 * np.pi * k * np.cos(ph) - w * w * np.sin(ph))
        q[:, j] = POSE[j] + env * f
        a[:, j] = dde * f + 2 * de * df + env * ddf
    return q, a


def measure(x: np.ndarray, step, noise: float, seed: int) -> np.ndarray:
    """An encoder: white noise, then quantisation."""
    y = x + (np.random.default_rng(seed + 1).normal(0.0, noise, x.shape) if noise else 0.0)
    return np.round(y / step) * step if step else y


def qdd_rms(t: np.ndarray, q: np.ndarray, a: np.ndarray) -> float:
    """Worst joint's RMS q̈ error at the stamps of the natural spline through ``q`` (what
    the replay uses)."""
    e = CubicSpline(t, q, bc_type="natural")(t, 2) - a
    return float(np.sqrt(np.mean(e * e, axis=0)).max())


def noise_std(ch: str) -> float:
    return NOISE["tau"] if ch.startswith("tau") else NOISE["ee"] if ch.startswith("ee_") else NOISE["imu"]


# ------------------------------------------------------------ the estimates
@pytest.mark.parametrize("step", [1e-6, R, 1e-5, 3.3e-5, 1e-4])
@pytest.mark.parametrize("rate,jitter", [(200.0, 0.0), (500.0, 0.2), (1000.0, 0.0), (1000.0, 0.2)])
def test_detects_the_quantisation_step(step, rate, jitter):
    seed = int(rate) + int(1e7 * step)
    t = stamps(rate, 4.0, jitter, seed)
    for kind in ("smooth", "chirp-8"):
        x, _ = trajectory(kind, t, seed)
        q = measure(x, step, 0.0, seed)
        for j in range(3):
            got = detect_resolution(q[:, j])
            assert got is not None and got == pytest.approx(step, rel=1e-6), (kind, j, got)
        sm = smooth_encoder(t, q)
        assert sm.resolution == pytest.approx(step, rel=1e-6)
        assert sm.params["resolution"] == [pytest.approx(step, rel=1e-6)] * 3
        assert np.allclose(sm.sigma, step / math.sqrt(12), rtol=0.5)
    # noise before the quantiser leaves the values on the grid
    q = measure(x, step, 0.7 * step, seed)
    assert detect_resolution(q[:, 0]) == pytest.approx(step, rel=1e-6)


def test_step_of_a_ramp_that_skips_levels_and_of_printed_values():
    t = np.arange(5000) / 1000.0
    ramp = np.round((0.3 + 0.1 * t + 1e-3 * np.sin(3 * t)) / R) * R  # ~26 steps per sample: neighbours never seen
    assert detect_resolution(ramp) == pytest.approx(R, rel=1e-6)
    x, _ = trajectory("smooth", t, 3)
    q9 = np.array([float(f"{v:.9g}") for v in np.round(x[:, 1] / R) * R])  # a CSV with 9 digits
    assert detect_resolution(q9) == pytest.approx(R, rel=1e-5)


def test_no_step_in_real_valued_angles():
    rng = np.random.default_rng(5)
    for n in (5, 8, 20, 1000):
        for _ in range(50):
            assert detect_resolution(rng.uniform(-1, 1, n)) is None
    t = stamps(1000.0, 3.0, 0.2, 1)
    x, _ = trajectory("chirp-8", t, 1)
    assert all(detect_resolution(x[:, j]) is None for j in range(3))
    assert detect_resolution(np.full(10, 0.3)) is None
    assert detect_resolution(x[:, 0] + 1e-12 * np.arange(t.size) % 3) is None


@pytest.mark.parametrize("sigma", [1e-6, 1e-5])
@pytest.mark.parametrize("rate,jitter", [(200.0, 0.2), (1000.0, 0.0), (1000.0, 0.2)])
def test_white_noise_is_estimated_on_any_stamps(sigma, rate, jitter):
    t = stamps(rate, 6.0, jitter, 11)
    x, _ = trajectory("chirp-8", t, 11)
    sig, det, rough = estimate_noise(t, measure(x, None, sigma, 11))
    assert det.all()
    assert np.allclose(sig, sigma, rtol=0.1), sig
    assert np.allclose(rough, sigma, rtol=0.1), rough
    _, det0, _ = estimate_noise(t, x)  # the motion itself is not noise
    assert not det0.any()


# ------------------------------------------------------------ exact input
def test_exact_encoder_is_returned_bit_for_bit():
    t = stamps(1000.0, 5.0, 0.2, 2)
    x, _ = trajectory("chirp-8", t, 2)
    x[:, 2] = 0.1 * t + 0.25  # a ramp on uniform-looking values is exact too
    sm = smooth_encoder(t, x)
    assert sm.q.tobytes() == x.tobytes() and sm.q is not x
    assert np.all(sm.sigma == 0.0)
    assert sm.params["lam"] == [None, None, None]
    assert "as measured" in sm.method
    held = np.tile(POSE, (50, 1))
    assert smooth_encoder(np.arange(50) / 500.0, held).q.tobytes() == held.tobytes()


def test_short_input_unchanged_and_joints_without_error_untouched():
    t = np.arange(4) * 0.002
    q = np.round(np.random.default_rng(0).normal(0, 1e-3, (4, 3)) / R) * R
    sm = smooth_encoder(t, q)
    assert sm.q.tobytes() == q.tobytes() and "too few" in sm.method
    t = np.arange(9) * 0.002
    q = np.round(np.stack([np.sin(3 * t), t**2, 0 * t], axis=1) / R) * R
    assert smooth_encoder(t, q).q.tobytes() == q.tobytes()  # < 10 samples: no estimate of the error
    assert smooth_encoder(t, q, resolution=R).sigma[0] == pytest.approx(R / math.sqrt(12))
    # 13 samples of a fast smooth move have nearly equal increments: not a coarse grid
    t = np.arange(13) * 0.002
    q = np.round(np.stack([np.sin(3 * t), t**2, 0 * t], axis=1) / R) * R
    assert detect_resolution(q[:, 0]) is not None  # the values alone fit some step ...
    sm = smooth_encoder(t, q)
    assert sm.params["resolution"][0] is None and sm.sigma[0] < 1e-5  # ... but its error is not in them
    # one quantised joint, two exact: only the first is changed
    t = stamps(1000.0, 3.0)
    x, _ = trajectory("smooth", t, 4)
    q = x.copy()
    q[:, 0] = np.round(x[:, 0] / R) * R
    sm = smooth_encoder(t, q)
    assert sm.q[:, 1:].tobytes() == q[:, 1:].tobytes()
    assert not np.array_equal(sm.q[:, 0], q[:, 0])
    assert sm.sigma[0] > 0 and sm.sigma[1] == sm.sigma[2] == 0.0


def test_bad_input_names_the_argument():
    t = stamps(500.0, 1.0)
    q = np.zeros((t.size, 3))
    with pytest.raises(InputError, match="input q"):
        smooth_encoder(t, q[:, :2])
    with pytest.raises(InputError, match="input q"):
        smooth_encoder(t, q[:-1])
    with pytest.raises(InputError, match="input t"):
        smooth_encoder(t[:, None], q)
    with pytest.raises(InputError, match="input t"):
        smooth_encoder(t[::-1], q)
    bad = q.copy()
    bad[3, 1] = np.nan
    with pytest.raises(InputError, match="input q"):
        smooth_encoder(t, bad)
    with pytest.raises(InputError, match="input resolution"):
        smooth_encoder(t, q, resolution=-1.0)
    with pytest.raises(InputError, match="input noise"):
        smooth_encoder(t, q, noise=[1e-6, 1e-6])
    with pytest.raises(ValueError):  # InputError is a ValueError
        smooth_encoder(t, "angles")


# ----------------------------------------------------------- the smoother
def test_is_the_scipy_smoothing_spline_and_the_replay_keeps_it():
    """The values are scipy's make_smoothing_spline with the chosen λ, and the natural
    spline through them (the replay's) is the same curve."""
    t = stamps(500.0, 3.0, 0.2, 9)
    x, _ = trajectory("chirp-5", t, 9)
    q = measure(x, R, 0.0, 9)
    sm = smooth_encoder(t, q)
    mid = 0.5 * (t[1:] + t[:-1])
    for j in range(3):
        ref = make_smoothing_spline(t, q[:, j], lam=sm.params["lam"][j])
        assert np.max(np.abs(ref(t) - sm.q[:, j])) < 1e-12
        nat = CubicSpline(t, sm.q[:, j], bc_type="natural")
        assert np.max(np.abs(nat(mid, 2) - ref(mid, 2))) < 1e-6 * max(1.0, np.max(np.abs(ref(mid, 2))))
        r = q[:, j] - sm.q[:, j]
        assert np.sqrt(np.mean(r * r)) == pytest.approx(sm.sigma[j], rel=0.02)  # the discrepancy principle


def test_smooth_at_is_the_smoothing_spline_at_a_given_lambda():
    """smooth_at(t, y, λ) is scipy's make_smoothing_spline(lam=λ) at the stamps, on any
    stamps, and reproduces smooth_encoder with its own λ; bad shapes are named."""
    t = stamps(200.0, 2.0, 0.15, 4)
    x, _ = trajectory("chirp-5", t, 4)
    q = measure(x, R, 0.0, 4)
    sm = smooth_encoder(t, q)
    for j in range(3):
        lam = sm.params["lam"][j]
        assert np.array_equal(smooth_at(t, q[:, j], lam), sm.q[:, j])
        for f in (0.1, 10.0):
            ref = make_smoothing_spline(t, q[:, j], lam=f * lam)(t)
            assert np.max(np.abs(smooth_at(t, q[:, j], f * lam) - ref)) < 1e-12
    with pytest.raises(InputError, match="smooth_at"):
        smooth_at(t, q, 1.0)


def test_given_resolution_and_noise():
    t = stamps(1000.0, 3.0)
    x, _ = trajectory("smooth", t, 6)
    q = measure(x, 1e-5, 0.0, 6)
    a = smooth_encoder(t, q, resolution=1e-5, noise=0.0)
    assert a.resolution == 1e-5 and np.allclose(a.sigma, 1e-5 / math.sqrt(12))
    assert "given" in a.method
    b = smooth_encoder(t, q, resolution=1e-5, noise=[2e-6, 0.0, 0.0])
    assert b.sigma[0] == pytest.approx(math.hypot(1e-5 / math.sqrt(12), 2e-6))
    c = smooth_encoder(t, x, resolution=0, noise=0)  # "exact", as declared
    assert c.q.tobytes() == x.tobytes()


def test_deterministic_and_fast():
    t = stamps(1000.0, 19.999, 0.2, 8)
    assert t.size == 20000
    x, _ = trajectory("chirp-8", t, 8)
    q = measure(x, R, 1e-6, 8)
    best = math.inf
    for _ in range(2):
        t0 = time.perf_counter()
        a = smooth_encoder(t, q)
        best = min(best, time.perf_counter() - t0)
    b = smooth_encoder(t.copy(), q.copy())
    assert a.q.tobytes() == b.q.tobytes() and a.params == b.params and a.method == b.method
    assert best < 1.0, f"{best:.2f} s for 20000 x 3"
    assert isinstance(a, SmoothedEncoder) and a.q.shape == q.shape and a.sigma.shape == (3,)
    assert a.method.endswith(".") and "discrepancy" in a.method


CASES = [(1e-6, 0.0), (R, 0.0), (1e-5, 0.0), (1e-4, 0.0), (None, 3e-6), (R, 5e-6)]


@pytest.mark.parametrize("kind", ["smooth", "chirp-5", "chirp-8"])
@pytest.mark.parametrize("rate", [200.0, 500.0, 1000.0])
@pytest.mark.parametrize("jitter", [0.0, 0.2])
def test_qdd_error_much_smaller_than_the_raw_splines(kind, rate, jitter):
    """q̈ of the smoothed encoder vs the exact q̈, against the raw natural spline through
    the encoder samples (scipy's CubicSpline: what the replay does without smoothing)."""
    for step, noise in CASES:
        seed = (hash((kind, rate, jitter)) % 997) + int(1e7 * (step or 0))
        t = stamps(rate, 4.0, jitter, seed)
        x, a = trajectory(kind, t, seed)
        q = measure(x, step, noise, seed)
        exact, raw = qdd_rms(t, x, a), qdd_rms(t, q, a)
        smo = qdd_rms(t, smooth_encoder(t, q).q, a)
        where = f"{kind} {rate:g} Hz jitter {jitter} step {step} noise {noise}: exact {exact:.3g} raw {raw:.3g} smoothed {smo:.3g}"
        assert smo < raw, where
        if raw > 10 * exact:  # the encoder's error dominates the raw spline's
            assert smo < 0.3 * raw, where
        if raw > 100 * exact:
            assert smo < 0.1 * raw, where


@pytest.mark.parametrize("rate", [200.0, 1000.0])
def test_no_bias_on_fast_chirps(rate):
    """The 6-8 Hz end of a chirp keeps its q̈: gain 1 ± 0.5 %, error < 1 % of the signal."""
    t = stamps(rate, 6.0, 0.2, 21)
    x, a = trajectory("chirp-8", t, 21)
    q = measure(x, R, 1e-6, 21)
    qdd = CubicSpline(t, smooth_encoder(t, q).q, bc_type="natural")(t, 2)
    fast = (t > 0.75 * t[-1]) & (t < 0.95 * t[-1])
    for j in range(3):
        gain = float(np.dot(qdd[fast, j], a[fast, j]) / np.dot(a[fast, j], a[fast, j]))
        rel = float(np.sqrt(np.mean((qdd[fast, j] - a[fast, j]) ** 2) / np.mean(a[fast, j] ** 2)))
        assert abs(gain - 1.0) < 0.005 and rel < 0.01, (j, gain, rel)


# ------------------------------------------------------- replay at the floor
@pytest.fixture(scope="module")
def model() -> popup.Model:
    return popup.Model("popup-lab", payload_kg=1.0)


def chirp8(t: np.ndarray) -> np.ndarray:
    """0.2 → 8 Hz of every joint, 5/2.5/5 mrad, sin² envelope (moment ratios ≲ 3, as the
    lab trajectory)."""
    u = t - t[0]
    T = float(u[-1])
    ph = 2 * np.pi * (0.2 * u + 0.5 * (8.0 - 0.2) / T * u**2)
    return POSE + np.outer(np.sin(np.pi * u / T) ** 2 * np.sin(ph), [0.005, 0.0025, 0.005])


def floor_ratios(model, t, q_enc, measured, rate):
    """RMSE(measured − replay) / true noise std per channel, replay of ``q_enc`` at the
    stamps ``t`` (simulated at ``rate``, put on the stamps linearly when they differ)."""
    res = model.replay(t, q_enc, sample_rate=rate)
    ts = res.channel("t")
    out = {}
    for ch in CHANNELS:
        y = res.channel(ch)
        if ts.shape != t.shape or not np.allclose(ts, t, atol=1e-9, rtol=0):
            y = np.interp(t, ts, y)
        out[ch] = float(np.sqrt(np.mean((measured[ch] - y) ** 2)) / noise_std(ch))
    return out


@pytest.mark.parametrize(
    "excitation,rate,raw_tau_min",
    [("lab", 1000.0, 1.2), ("chirp8", 1000.0, 1.3), ("chirp8", 500.0, 1.04), ("lab", 200.0, None)],
)
def test_replay_of_a_measured_run_sits_at_the_noise_floor(model, tmp_path, excitation, rate, raw_tau_min):
    """The measured run's encoder (quantised), smoothed: every channel ≤ 1.1 × its noise
    and no worse than the exact encoder's replay (the noise draw itself) + 0.02; the raw
    encoder's worst torque is above ``raw_tau_min`` (at 200 Hz the raw spline is at the
    floor already: the smoothing must not spoil it)."""
    if excitation == "lab":
        t, q = popup.synth.lab_trajectory(duration=10.0, rate=rate, seed=3)
    else:
        t = stamps(rate, 8.0)
        q = chirp8(t)
    run = popup.synth.measured_run(model, t, q, tmp_path / "run", seed=3)  # quantised at ENCODER_RESOLUTION
    te, qe = run.encoder()
    sm = smooth_encoder(te, qe)
    assert sm.resolution == pytest.approx(R, rel=1e-6)
    measured = {ch: run.data[ch].to_numpy() for ch in CHANNELS}
    smoothed = floor_ratios(model, te, sm.q, measured, rate)
    raw = floor_ratios(model, te, qe, measured, rate)
    ideal = floor_ratios(model, te, q, measured, rate)  # the exact encoder: the noise draw itself
    assert max(smoothed.values()) <= 1.1, smoothed
    for ch in CHANNELS:
        assert smoothed[ch] <= ideal[ch] + 0.02, (ch, smoothed[ch], ideal[ch])
        assert smoothed[ch] <= raw[ch] + 0.01, (ch, smoothed[ch], raw[ch])
    if raw_tau_min is not None:
        worst = max(("tau1", "tau2", "tau3"), key=lambda c: raw[c])
        assert raw[worst] > raw_tau_min, raw
        assert raw[worst] > smoothed[worst] + 0.5 * (raw_tau_min - 1.0), (worst, raw[worst], smoothed[worst])


def test_replay_with_jittered_stamps_and_a_noisy_encoder(model):
    """±20 % stamp jitter at 1 kHz, the encoder with 2 µrad white noise before the
    quantiser; the truth replays the exact angles (as measured_run does), both
    simulations are put on the stamps linearly (as compare does)."""
    t = stamps(1000.0, 8.0, 0.2, 41)
    x = chirp8(t)
    q = measure(x, R, 2e-6, 41)
    truth = model.replay(t, x, sample_rate=1000.0)
    ts = truth.channel("t")
    rng = np.random.default_rng(42)
    measured = {ch: np.interp(t, ts, truth.channel(ch)) + rng.normal(0.0, noise_std(ch), t.size) for ch in CHANNELS}
    sm = smooth_encoder(t, q)
    smoothed = floor_ratios(model, t, sm.q, measured, 1000.0)
    raw = floor_ratios(model, t, q, measured, 1000.0)
    assert max(smoothed.values()) <= 1.1, smoothed
    assert min(raw[c] for c in ("tau1", "tau2", "tau3")) > 1.2, raw
    assert max(raw.values()) > 2.0

"""Frequency analysis: frequency response functions (FRFs) of the arm two ways, and the
numbers the thesis reports (cut-off, resonance peak and frequency, bandwidth vs amplitude).

**Linearised** (:func:`linearize`): the engine's state-space model about a static
equilibrium (``popup._core.linearize``: A, B, C, D by differencing the forward dynamics and
the sensor model), optionally closed with the cascade controller (continuous-time
equivalent of the discrete laws of ``docs/control.md``) → Bode magnitude/phase
(:meth:`LinearModel.frf`), poles and modes with natural frequency and damping ratio
(:meth:`LinearModel.modes`).

**Simulated** (:func:`simulate`): the non-linear engine excited by stepped sines (one run
per frequency, settling periods, then a least-squares fit of the first harmonic over whole
periods) or a chirp (Welch-averaged H1 estimator with its coherence); any input (open-loop
motor torque, prescribed motor angle, closed-loop velocity reference, closed-loop position
reference) to any output channel, at a given input amplitude (the motoreducer's torque limit
makes the loop non-linear: the stepped-sine gain is a describing function).

Both are **batched**: payloads, pressures and poses (and amplitudes) given as arrays are one
call (one batched Rust rollout per group of frequencies of similar run length). Results
(:class:`FRF`) carry the sweep and give ``.summary()`` (cut-off, resonance per run),
``.to_pandas()`` and ``.plot()`` (Bode, overlaid across the sweep).

Input kinds (``input=``):

============== ===================================== =========== ==========================
kind           what drives the motor joints          unit        engine run
============== ===================================== =========== ==========================
``torque``     motor torque on top of the holding    N·m         torque-driven, open loop
               torque (motors otherwise free)
``motor_angle`` prescribed motor angle (ideal         rad         encoder replay
               position servo; motors locked else)
``velocity``   velocity reference of the velocity     rad/s       closed loop, all three
               loops (position loops bypassed)                    velocity loops on
``reference``  position reference of the cascade     rad         closed loop, full cascade
``locked``     nothing (motors locked): modes only   –           –
============== ===================================== =========== ==========================

The link model is the one of the :class:`popup.Model` passed in; :func:`rigid_links` makes a
rigid copy (the links' universal joints locked). A model with other link types (beam links) is
passed the same way.

Units: ω in rad/s everywhere, magnitudes as ratios (output unit per input unit) and dB
(20 log10), phase in degrees.
"""

from __future__ import annotations

import math
import warnings as _warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _core
from .exceptions import InputError, PopupWarning
from .results import CHANNELS, UNITS

if TYPE_CHECKING:
    from .control import Controller, Task
    from .model import Model

__all__ = [
    "INPUT_KINDS",
    "DEFAULT_OUTPUTS",
    "LinearModel",
    "FRF",
    "linearize",
    "simulate",
    "rigid_links",
    "sine_fit",
    "h1_estimate",
    "cutoff",
    "resonance",
    "modes_from_poles",
]

INPUT_KINDS = ("torque", "motor_angle", "velocity", "reference", "locked")
"""Ways the motor joints are driven (see the module docs)."""
_INPUT_UNITS = {"torque": "N·m", "motor_angle": "rad", "velocity": "rad/s", "reference": "rad", "acceleration": "rad/s²"}
DEFAULT_OUTPUTS = ["q1", "q2", "q3", "dq1", "dq2", "dq3", "ee_x", "ee_y", "ee_z", "d11", "d12", "d21", "d22"]
"""Outputs of :func:`linearize` when none are named."""
_UNIT = dict(zip(CHANNELS, UNITS))
_SWEEP_KEYS = ("payload_kg", "p1", "p2", "q1", "q2", "q3", "amplitude")


# =============================================================================== estimators
def sine_fit(t: Any, y: Any, omega: float, trend: int = 1, window: Optional[str] = None) -> np.ndarray:
    """Least-squares fit ``y ≈ a sin ωt + b cos ωt + c₀ + c₁ t + …`` (polynomial of degree
    ``trend``, −1 for none) over the samples ``t`` [s]; returns the complex first-harmonic
    phasor ``a + i b`` (so that the fitted harmonic is ``Im((a + i b) e^{iωt})``), one per
    column of ``y`` (shape ``y.shape[1:]``).

    Fit over whole periods (the regressors are then orthogonal and leakage-free for the
    harmonics of ω). The trend terms absorb the drift of a marginally stable plant (free
    yaw, start transients). ``window="hann"`` weights the samples with a Hann window
    (weighted least squares): the leakage of a component at another frequency (a decaying
    transient of a lightly damped mode) falls from a sinc's 1/Δω to 1/Δω³."""
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    X, yy = _design(t, omega, trend), y.reshape(len(t), -1)
    if window is not None:
        wts = np.sqrt(_weights(t, window))
        X, yy = X * wts[:, None], yy * wts[:, None]
    c, *_ = np.linalg.lstsq(X, yy, rcond=None)
    return (c[0] + 1j * c[1]).reshape(y.shape[1:])


def _design(t: np.ndarray, omega: float, trend: int) -> np.ndarray:
    cols = [np.sin(omega * t), np.cos(omega * t)]
    if trend >= 0:
        tc = (t - t.mean()) / max(float(np.ptp(t)), 1e-300)
        cols += [tc**k for k in range(trend + 1)]
    return np.column_stack(cols)


def _weights(t: np.ndarray, window: str) -> np.ndarray:
    if window in ("boxcar", "rect", "none"):
        return np.ones_like(t)
    if window != "hann":
        raise InputError(f"input window: {window!r} must be 'hann' or 'boxcar'")
    x = (t - t[0]) / max(float(t[-1] - t[0]), 1e-300)
    return np.maximum(0.5 - 0.5 * np.cos(2 * np.pi * x), 1e-6)


def _harmonic_fraction(t: np.ndarray, y: np.ndarray, omega: float, trend: int = 1) -> np.ndarray:
    """Share of the detrended output variance carried by the first harmonic (1 for a pure
    sine; falls with harmonics, noise or a transient still decaying): the stepped sine's
    analogue of the coherence."""
    yy = y.reshape(len(t), -1)
    X = _design(t, omega, trend)
    c, *_ = np.linalg.lstsq(X, yy, rcond=None)
    r = yy - X[:, 2:] @ c[2:]
    h = (c[0] ** 2 + c[1] ** 2) / 2.0
    v = np.mean(r**2, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(v > 0, np.minimum(h / v, 1.0), 1.0).reshape(y.shape[1:])


def h1_estimate(
    u: Any, y: Any, fs: float, *, nperseg: Optional[int] = None, noverlap: Optional[int] = None, window: str = "hann", detrend: str = "constant"
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 estimate ``Ĥ = P_uy / P_uu`` and coherence ``γ² = |P_uy|² / (P_uu P_yy)`` from an
    input record ``u`` (N,) and outputs ``y`` (N,) or (N, P) sampled at ``fs`` [Hz], by
    Welch averaging (:func:`scipy.signal.csd`/:func:`scipy.signal.welch`: segments of
    ``nperseg`` samples, default N/8, ``window``, ``noverlap`` default half a segment).

    H1 is unbiased by output noise (noise on ``y`` averages out of P_uy); γ² < 1 flags
    noise, non-linearity, leakage or non-stationarity at that frequency. Returns
    (ω [rad/s] (F,), Ĥ (F,) or (F, P), γ² likewise)."""
    from scipy import signal

    u = np.asarray(u, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    one = y.ndim == 1
    yy = y[:, None] if one else y
    if u.ndim != 1 or yy.shape[0] != u.shape[0]:
        raise InputError(f"input h1_estimate: u must be (N,) and y (N,) or (N, P) with the same N; got {u.shape}, {y.shape}")
    n = u.shape[0]
    nps = int(nperseg) if nperseg is not None else max(16, n // 8)
    nps = min(nps, n)
    kw: Dict[str, Any] = dict(fs=fs, window=window, nperseg=nps, noverlap=noverlap, detrend=detrend)
    f, puu = signal.welch(u, **kw)
    H = np.empty((f.size, yy.shape[1]), dtype=complex)
    coh = np.empty((f.size, yy.shape[1]))
    for j in range(yy.shape[1]):
        _, puy = signal.csd(u, yy[:, j], **kw)
        _, pyy = signal.welch(yy[:, j], **kw)
        with np.errstate(invalid="ignore", divide="ignore"):
            H[:, j] = puy / puu
            coh[:, j] = np.abs(puy) ** 2 / (puu * pyy)
    w = 2 * np.pi * f
    return (w, H[:, 0], coh[:, 0]) if one else (w, H, coh)


def _reference_gain(mag: np.ndarray, reference: Union[str, float]) -> float:
    if isinstance(reference, str):
        if reference == "low":
            return float(mag[0])
        if reference == "max":
            return float(np.nanmax(mag))
        raise InputError(f"input reference: {reference!r} must be 'low', 'max' or a gain")
    return float(reference)


def cutoff(omega: Any, H: Any, *, level_db: float = -3.0, reference: Union[str, float] = "low", min_width: float = 1.0) -> float:
    """First frequency [rad/s] (going up) where the gain ``|H|`` falls ``level_db`` below the
    reference gain (``"low"``: the gain at the lowest frequency; ``"max"``; or a number,
    e.g. 1 for a tracking loop), interpolated in log ω and dB.

    ``min_width`` > 1: dips below the level narrower than that frequency ratio (an
    anti-resonance notch) are skipped. Returns 0 if already below at the lowest frequency,
    inf if never below."""
    w = np.asarray(omega, dtype=np.float64)
    o = np.argsort(w)
    w = w[o]
    db = 20 * np.log10(np.abs(np.asarray(H))[o])
    ref = 20 * np.log10(_reference_gain(np.abs(np.asarray(H))[o], reference))
    lvl = ref + level_db
    below = db < lvl
    if below[0]:
        return 0.0
    downs: List[float] = []
    ups: List[float] = []
    for i in range(len(w) - 1):
        if db[i] >= lvl > db[i + 1] or db[i] < lvl <= db[i + 1]:
            x = math.exp(math.log(w[i]) + (db[i] - lvl) / (db[i] - db[i + 1]) * math.log(w[i + 1] / w[i]))
            (downs if db[i] >= lvl else ups).append(x)
    for k, d in enumerate(downs):
        u = ups[k] if k < len(ups) else math.inf
        if u / d >= min_width:
            return d
    return math.inf


def resonance(omega: Any, H: Any, *, reference: Union[str, float] = "low") -> Tuple[float, float]:
    """Resonance: (frequency [rad/s], peak [dB above the reference gain]) of the largest
    interior maximum of ``|H|`` (parabola through the three points around it in log ω and
    dB). (nan, nan) when the gain has no interior maximum (monotone over the grid)."""
    w = np.asarray(omega, dtype=np.float64)
    o = np.argsort(w)
    w = w[o]
    mag = np.abs(np.asarray(H))[o]
    db = 20 * np.log10(mag)
    ref = 20 * np.log10(_reference_gain(mag, reference))
    inner = [i for i in range(1, len(w) - 1) if db[i] >= db[i - 1] and db[i] >= db[i + 1] and np.isfinite(db[i])]
    if not inner:
        return math.nan, math.nan
    i = max(inner, key=lambda k: db[k])
    x = np.log(w[i - 1 : i + 2])
    c = np.polyfit(x, db[i - 1 : i + 2], 2)
    if c[0] >= 0:
        return float(w[i]), float(db[i] - ref)
    xp = -c[1] / (2 * c[0])
    xp = min(max(xp, x[0]), x[2])
    return float(math.exp(xp)), float(np.polyval(c, xp) - ref)


def modes_from_poles(poles: Any) -> List[Dict[str, float]]:
    """Modes of a set of poles: one row per complex pair (``im > 0``) and per real pole, with
    natural frequency ``wn = |λ|`` [rad/s], ``f_hz``, damping ratio ``zeta = −Re λ / |λ|``
    (1 for a decaying real pole, −1 for a growing one, nan at λ = 0) and damped frequency
    ``wd = Im λ``, sorted by ``wn``."""
    rows = []
    for lam in np.asarray(poles, dtype=complex).ravel():
        if lam.imag < -1e-9 * max(abs(lam), 1.0):
            continue
        wn = abs(lam)
        rows.append(
            {
                "wn": float(wn),
                "f_hz": float(wn / (2 * np.pi)),
                "zeta": float(-lam.real / wn) if wn > 1e-9 else math.nan,
                "wd": float(max(lam.imag, 0.0)),
                "re": float(lam.real),
                "im": float(max(lam.imag, 0.0)),
            }
        )
    rows.sort(key=lambda r: (r["wn"], r["re"]))
    return rows


# =============================================================================== sweeps
def _joint_index(joint: Union[str, int]) -> int:
    if isinstance(joint, str):
        if joint not in ("q1", "q2", "q3"):
            raise InputError(f"input joint: {joint!r} must be 'q1', 'q2' or 'q3'")
        return int(joint[1]) - 1
    j = int(joint)
    if j not in (0, 1, 2):
        raise InputError(f"input joint: {joint!r} must be 0, 1 or 2 (q1..q3)")
    return j


def _sweep(model: "Model", payload_kg: Any, pressure_pa: Any, q_motor: Any, amplitude: Any = None) -> Dict[str, np.ndarray]:
    """Broadcast the swept parameters to one batch axis B (singletons tiled)."""
    pay = np.atleast_1d(np.asarray(model.payload_kg if payload_kg is None else payload_kg, dtype=np.float64))
    pres = np.asarray(model.pressure_pa if pressure_pa is None else pressure_pa, dtype=np.float64)
    if pres.ndim == 0:
        pres = np.array([float(pres), float(pres)])
    pres = np.atleast_2d(pres)
    qm = np.atleast_2d(np.asarray(q_motor, dtype=np.float64))
    amp = np.atleast_1d(np.asarray(0.0 if amplitude is None else amplitude, dtype=np.float64))
    if pay.ndim != 1 or pres.shape[-1] != 2 or pres.ndim != 2 or qm.shape[-1] != 3 or qm.ndim != 2 or amp.ndim != 1:
        raise InputError(f"input sweep: payload_kg ([B]), pressure_pa ([B] x 2), q_motor ([B] x 3), amplitude ([B]); got {pay.shape}, {pres.shape}, {qm.shape}, {amp.shape}")
    sizes = {len(pay), len(pres), len(qm), len(amp)} - {1}
    if len(sizes) > 1:
        raise InputError(f"input sweep: batch sizes differ: payload_kg {len(pay)}, pressure_pa {len(pres)}, q_motor {len(qm)}, amplitude {len(amp)}")
    nb = sizes.pop() if sizes else 1
    t = lambda a: np.broadcast_to(a, (nb,) + a.shape[1:]).copy()  # noqa: E731
    pay, pres, qm, amp = t(pay), t(pres), t(qm), t(amp)
    if not (np.all(np.isfinite(amp)) and np.all(amp >= 0)):
        raise InputError("input amplitude: must be finite and >= 0")
    return {"payload_kg": pay, "p1": pres[:, 0], "p2": pres[:, 1], "q1": qm[:, 0], "q2": qm[:, 1], "q3": qm[:, 2], "amplitude": amp}


def _label(sweep: Dict[str, np.ndarray], b: int) -> str:
    """Short label of run b: the swept parameters that vary."""
    parts = []
    for k in _SWEEP_KEYS:
        v = sweep.get(k)
        if v is None or len(v) < 2 or np.all(v == v[0]):
            continue
        parts.append(f"{k}={v[b]:g}")
    return ", ".join(parts) or "run"


# =============================================================================== results
@dataclass
class FRF:
    """Frequency responses from one input to several outputs, for a batch of runs.

    ``H`` (B, F, P) complex (output unit per input unit), at ``omega`` (F,) [rad/s], for
    ``outputs`` (P names); ``coherence`` (B, F, P) (H1: magnitude-squared coherence;
    stepped sine: share of the output variance in the first harmonic; linear: None);
    ``sweep``: per-run parameters (``payload_kg``, ``p1``, ``p2``, ``q1..q3``, ``amplitude``).
    """

    omega: np.ndarray
    H: np.ndarray
    outputs: List[str]
    input: str
    joint: str
    method: str
    sweep: Dict[str, np.ndarray]
    coherence: Optional[np.ndarray] = None
    info: Dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.H.shape[0])

    def _out(self, output: Optional[str]) -> int:
        if output is None:
            return 0
        if output not in self.outputs:
            raise KeyError(f"output {output!r} not in this FRF; outputs are {self.outputs}")
        return self.outputs.index(output)

    def response(self, output: Optional[str] = None) -> np.ndarray:
        """Complex response (B, F) of one output (default the first)."""
        return self.H[:, :, self._out(output)]

    def magnitude_db(self, output: Optional[str] = None) -> np.ndarray:
        """20 log10 |H| (B, F) [dB]."""
        with np.errstate(divide="ignore"):
            return 20 * np.log10(np.abs(self.response(output)))

    def phase_deg(self, output: Optional[str] = None) -> np.ndarray:
        """Unwrapped phase (B, F) [deg]."""
        return np.degrees(np.unwrap(np.angle(self.response(output)), axis=-1))

    def cutoff(self, output: Optional[str] = None, **kw: Any) -> np.ndarray:
        """−3 dB cut-off per run (B,) [rad/s] (see :func:`cutoff` for ``level_db``,
        ``reference``, ``min_width``)."""
        return np.array([cutoff(self.omega, h, **kw) for h in self.response(output)])

    def resonance(self, output: Optional[str] = None, **kw: Any) -> Tuple[np.ndarray, np.ndarray]:
        """(resonance frequency [rad/s], peak [dB]) per run, each (B,) (see :func:`resonance`)."""
        r = [resonance(self.omega, h, **kw) for h in self.response(output)]
        return np.array([x[0] for x in r]), np.array([x[1] for x in r])

    def label(self, b: int) -> str:
        """Label of run b (the swept values that vary across the batch)."""
        return _label(self.sweep, b)

    def summary(self, *, level_db: float = -3.0, reference: Union[str, float] = "low", min_width: float = 1.0) -> Any:
        """One row per (run, output): the sweep, low-frequency gain [dB], cut-off [rad/s],
        resonance frequency [rad/s] and peak [dB] (both relative to ``reference``)."""
        import pandas as pd

        rows = []
        for p, o in enumerate(self.outputs):
            for b in range(len(self)):
                h = self.H[b, :, p]
                wr, pk = resonance(self.omega, h, reference=reference)
                r: Dict[str, Any] = {k: float(v[b]) for k, v in self.sweep.items()}
                r.update(
                    {
                        "input": self.input,
                        "joint": self.joint,
                        "output": o,
                        "low_gain_db": float(20 * np.log10(abs(h[0]))),
                        "cutoff_rad_s": cutoff(self.omega, h, level_db=level_db, reference=reference, min_width=min_width),
                        "resonance_rad_s": wr,
                        "peak_db": pk,
                        "method": self.method,
                    }
                )
                rows.append(r)
        return pd.DataFrame(rows)

    def to_pandas(self) -> Any:
        """Long table: one row per (run, frequency, output) with the sweep, ``omega``,
        ``mag_db``, ``phase_deg``, ``re``, ``im`` and ``coherence``."""
        import pandas as pd

        B, F, P = self.H.shape
        grid = np.meshgrid(np.arange(B), np.arange(F), np.arange(P), indexing="ij")
        b, f, p = (g.ravel() for g in grid)
        h = self.H.ravel()
        ph = np.stack([self.phase_deg(o) for o in self.outputs], axis=-1).ravel()
        d: Dict[str, Any] = {"run": b}
        for k, v in self.sweep.items():
            d[k] = np.asarray(v)[b]
        d.update(
            {
                "omega": self.omega[f],
                "output": np.asarray(self.outputs, dtype=object)[p],
                "mag_db": 20 * np.log10(np.abs(h)),
                "phase_deg": ph,
                "re": h.real,
                "im": h.imag,
                "coherence": np.nan if self.coherence is None else self.coherence.ravel(),
            }
        )
        return pd.DataFrame(d)

    def plot(self, output: Optional[str] = None, *, axes: Any = None, label: Optional[str] = None, style: str = "-", coherence: bool = False) -> Any:
        """Bode plot of one output (magnitude [dB] and phase [deg] against ω, log axis), one
        line per run of the batch; ``coherence=True`` adds a third axis. Call again with the
        same ``axes`` to overlay another FRF (e.g. linearised vs simulated). Returns the
        figure."""
        import matplotlib.pyplot as plt

        n = 3 if coherence and self.coherence is not None else 2
        if axes is None:
            fig, axes = plt.subplots(n, 1, sharex=True, figsize=(7, 2.6 * n + 0.5))
        else:
            fig = axes[0].figure
        mag, ph = self.magnitude_db(output), self.phase_deg(output)
        o = self.outputs[self._out(output)]
        for b in range(len(self)):
            lb = (label + ": " if label else "") + self.label(b) if len(self) > 1 else (label or self.method)
            (ln,) = axes[0].semilogx(self.omega, mag[b], style, label=lb)
            axes[1].semilogx(self.omega, ph[b], style, color=ln.get_color())
            if n == 3 and self.coherence is not None:
                axes[2].semilogx(self.omega, self.coherence[b, :, self._out(output)], style, color=ln.get_color())
        u = _INPUT_UNITS.get(self.input, "")
        axes[0].set_ylabel(f"|{o}/{self.input}:{self.joint}| [dB]\n({_UNIT.get(o, '')} per {u})")
        axes[1].set_ylabel("phase [deg]")
        if n == 3:
            axes[2].set_ylabel("coherence")
            axes[2].set_ylim(0, 1.05)
        axes[-1].set_xlabel("ω [rad/s]")
        axes[0].legend(loc="best", fontsize="small")
        for a in axes:
            a.grid(True, which="both", alpha=0.3)
        return fig


def _eigvec(a: np.ndarray, lam: complex) -> np.ndarray:
    """Right eigenvector of ``a`` for the eigenvalue ``lam``: the right singular vector of
    ``a − λ I`` with the smallest singular value. (LAPACK's dgeev, as shipped with some
    OpenBLAS builds, returns wrong eigenvectors for the arm's matrices with an exact double
    zero eigenvalue, the free yaw; this is slower and always right.)"""
    _, _, vh = np.linalg.svd(a - lam * np.eye(a.shape[0]))
    return np.asarray(vh[-1].conj())


@dataclass
class LinearModel:
    """The linearised arm over a batch of operating points.

    ``a`` (B, n, n), ``b`` (B, n, m), ``c`` (B, p, n), ``d`` (B, p, m): ``ẋ = A x + B u``,
    ``y = C x + D u`` in deviations from the operating point (``q0`` (B, nv) joint
    coordinates, ``u0`` (B, m) inputs, ``y0`` (B, p) outputs). ``input`` is the kind (see
    :data:`INPUT_KINDS`; ``motor_angle`` is stored as the prescribed-acceleration model and
    multiplied by (iω)² in :meth:`frf`). ``states``/``inputs``/``outputs`` name the
    columns; for a closed loop the states after the plant's are the controller's
    (``Iv*``: velocity-PI integrators [drive units], ``tau*``: current-loop torques [N·m],
    ``zoh*``: the half-period hold delay (Padé), ``Iq*``: position-PI integrators [rad/s]).
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    input: str
    states: List[str]
    inputs: List[str]
    outputs: List[str]
    q0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    sweep: Dict[str, np.ndarray]
    joint_names: List[str]
    n_plant: int
    """Number of plant states (2 × joints in the state); the controller's follow."""
    s_power: int = 0
    """The FRF is (iω)^s_power × C (iω − A)⁻¹ B + D (2 for ``motor_angle``)."""
    passive_block: Optional[np.ndarray] = None
    """For ``motor_angle``: indices of the passive joints' states, whose block of A are the
    poles (the motors' double integrators cancel against (iω)²)."""
    info: Dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.a.shape[0])

    def poles(self) -> np.ndarray:
        """Poles (B, n') [1/s], sorted by |λ| (the motor double integrators of
        ``motor_angle`` excluded)."""
        out = []
        for k in range(len(self)):
            a = self.a[k]
            if self.passive_block is not None:
                a = a[np.ix_(self.passive_block, self.passive_block)]
            ev = np.linalg.eigvals(a)
            out.append(ev[np.lexsort((ev.imag, np.abs(ev)))])
        return np.array(out)

    def modes(self) -> Any:
        """Modes as a DataFrame: one row per (operating point, mode) with the sweep, natural
        frequency ``wn`` [rad/s], ``f_hz``, damping ratio ``zeta``, ``wd``, the pole's
        ``re``/``im`` and the joint that moves most in it (largest position entry of the
        eigenvector among the plant states)."""
        import pandas as pd

        rows = []
        for k in range(len(self)):
            a = self.a[k]
            idx = self.passive_block if self.passive_block is not None else np.arange(a.shape[0])
            sub = a[np.ix_(idx, idx)]
            ev = np.linalg.eigvals(sub)
            npos = self.n_plant // 2
            pos_rows = [i for i, s in enumerate(idx) if s < npos]
            for r in modes_from_poles(ev):
                v = np.abs(_eigvec(sub, complex(r["re"], r["im"]))[pos_rows]) if pos_rows else np.zeros(0)
                joint = self.states[idx[pos_rows[int(np.argmax(v))]]] if v.size and np.max(v) > 0 else ""
                row: Dict[str, Any] = {"point": k}
                row.update({kk: float(vv[k]) for kk, vv in self.sweep.items() if kk != "amplitude"})
                row.update(r)
                row["joint"] = joint
                rows.append(row)
        return pd.DataFrame(rows)

    def to_pandas(self) -> Any:
        """The modes (:meth:`modes`)."""
        return self.modes()

    def frf(self, omega: Any, *, joint: Union[str, int] = "q3", outputs: Optional[Sequence[str]] = None) -> FRF:
        """Frequency response from the input of motor ``joint`` to ``outputs`` (default all)
        at ``omega`` (F,) [rad/s]: ``(iω)^s C (iω − A)⁻¹ B + D`` per operating point."""
        if self.input == "locked":
            raise InputError("input: a locked-motor model has no input; linearise with input='motor_angle' for the response to a motor motion")
        w = np.asarray(omega, dtype=np.float64).ravel()
        j = _joint_index(joint)
        outs = list(self.outputs) if outputs is None else list(outputs)
        for o in outs:
            if o not in self.outputs:
                raise InputError(f"input outputs: {o!r} was not linearised; outputs are {self.outputs}")
        pi = [self.outputs.index(o) for o in outs]
        n = self.a.shape[1]
        H = np.empty((len(self), w.size, len(pi)), dtype=complex)
        for k in range(len(self)):
            A, Bj, C, Dj = self.a[k], self.b[k][:, j], self.c[k][pi], self.d[k][pi, j]
            for f, x in enumerate(w):
                s = 1j * x
                g = C @ np.linalg.solve(s * np.eye(n) - A, Bj) + Dj
                H[k, f] = g * s**self.s_power
        return FRF(omega=w, H=H, outputs=outs, input=self.input, joint=f"q{j + 1}", method="linear", sweep=dict(self.sweep))


# =============================================================================== linearise
def _controller_text(controller: Any) -> str:
    """TOML control text of a Controller or Task (one hold phase for a bare controller)."""
    from .control import Controller, Phase, Task

    if controller is None:
        controller = Controller()
    if isinstance(controller, Task):
        return controller.to_toml()
    if isinstance(controller, Controller):
        return Task([Phase("holding", hold=True)], controller).to_toml()
    raise InputError(f"input controller: expected a popup.control.Controller or Task, got {type(controller).__name__}")


def _close_loop(plant: Dict[str, Any], ctrl: Dict[str, Any], motor_pos: List[int], nv: int, mode: str, delay: bool) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, List[str]]:
    """Continuous-time closed loop around the torque-input plant (B, ...) arrays: velocity
    PI (Kp_v, Ki_v, c_u) → current loop (first-order lag ω_i) → [ZOH half-period delay,
    first-order Padé] → plant; with ``mode == "reference"`` the position PI in front.
    Inputs: the three velocity references (``velocity``) or position references
    (``reference``). ``motor_pos``: the motors' positions among the plant's ``nv`` joint
    states."""
    g = np.asarray(ctrl["gains"], dtype=np.float64)
    kpq, kiq, kpv, kiv = g[0:3], g[3:6], g[6:9], g[9:12]
    cu = np.array([m["torque_per_unit"] for m in ctrl["motors"]])
    wi = np.array([m["current_bandwidth"] for m in ctrl["motors"]])
    T = 1.0 / float(ctrl["rate_hz"])
    A0, B0, C0, D0 = plant["a"], plant["b"], plant["c"], plant["d"]
    nb, n, _ = A0.shape
    p = C0.shape[1]
    lag = np.isfinite(wi)
    if np.any(lag) and not np.all(lag):
        raise InputError("input controller: mixing finite and infinite current bandwidths is not supported by the linearised loop")
    lag_on = bool(np.all(lag))
    pos = mode == "reference"
    # state layout
    names: List[str] = []
    o_iv = n
    names += [f"Iv{k + 1}" for k in range(3)]
    o_tau = o_iv + 3
    if lag_on:
        names += [f"tau{k + 1}" for k in range(3)]
    o_z = o_tau + (3 if lag_on else 0)
    if delay:
        names += [f"zoh{k + 1}" for k in range(3)]
    o_iq = o_z + (3 if delay else 0)
    if pos:
        names += [f"Iq{k + 1}" for k in range(3)]
    N = o_iq + (3 if pos else 0)
    A = np.zeros((nb, N, N))
    B = np.zeros((nb, N, 3))
    C = np.zeros((nb, p, N))
    D = np.zeros((nb, p, 3))
    q_rows = np.zeros((3, N))
    v_rows = np.zeros((3, N))
    for k, i in enumerate(motor_pos):
        q_rows[k, i] = 1.0
        v_rows[k, nv + i] = 1.0
    # v* = Vx X + Vu r
    if pos:
        Vx = -np.diag(kpq) @ q_rows
        Vx[:, o_iq : o_iq + 3] += np.eye(3)
        Vu = np.diag(kpq)
    else:
        Vx = np.zeros((3, N))
        Vu = np.eye(3)
    Ex, Eu = Vx - v_rows, Vu  # velocity error
    # τ* = c_u (Kp_v e + I_v)
    Tsx = np.diag(cu * kpv) @ Ex
    Tsx[:, o_iv : o_iv + 3] += np.diag(cu)
    Tsu = np.diag(cu * kpv) @ Eu
    if lag_on:
        Tcx = np.zeros((3, N))
        Tcx[:, o_tau : o_tau + 3] = np.eye(3)
        Tcu = np.zeros((3, 3))
    else:
        Tcx, Tcu = Tsx, Tsu
    if delay:
        a_ = T / 4.0  # delay T/2: (1 − s a)/(1 + s a) = −1 + 2/(1 + s a)
        Tax = -Tcx.copy()
        Tax[:, o_z : o_z + 3] += np.eye(3)
        Tau = -Tcu
    else:
        Tax, Tau = Tcx, Tcu
    for k in range(nb):
        Ak, Bk = A[k], B[k]
        Ak[:n, :n] = A0[k]
        Ak[:n] += B0[k] @ Tax
        Bk[:n] += B0[k] @ Tau
        Ak[o_iv : o_iv + 3] += np.diag(kiv) @ Ex
        Bk[o_iv : o_iv + 3] += np.diag(kiv) @ Eu
        if lag_on:
            Ak[o_tau : o_tau + 3] += np.diag(wi) @ (Tsx - _sel(N, o_tau))
            Bk[o_tau : o_tau + 3] += np.diag(wi) @ Tsu
        if delay:
            Ak[o_z : o_z + 3] += (2.0 * Tcx - _sel(N, o_z)) / a_
            Bk[o_z : o_z + 3] += 2.0 * Tcu / a_
        if pos:
            Ak[o_iq : o_iq + 3] += -np.diag(kiq) @ q_rows
            Bk[o_iq : o_iq + 3] += np.diag(kiq)
        C[k, :, :n] = C0[k]
        C[k] += D0[k] @ Tax
        D[k] = D0[k] @ Tau
    return A, B, C, D, names


def _sel(N: int, off: int) -> np.ndarray:
    s = np.zeros((3, N))
    s[:, off : off + 3] = np.eye(3)
    return s


def linearize(
    model: "Model",
    q_motor: Any = (0.0, 0.0, 0.0),
    *,
    input: str = "torque",
    outputs: Optional[Sequence[str]] = None,
    payload_kg: Any = None,
    pressure_pa: Any = None,
    controller: Union["Controller", "Task", None] = None,
    delay: Optional[bool] = None,
    effects: Any = None,
) -> LinearModel:
    """Linearise the arm about its static equilibrium at motor angles ``q_motor`` ([B] x 3)
    [rad], for payloads ``payload_kg`` ([B]) and pressures ``pressure_pa`` ([B] x 2)
    (default: the model's); singletons are tiled, so a sweep is one call.

    ``input``: ``"torque"`` (open loop), ``"motor_angle"`` (motors follow a prescribed
    angle), ``"velocity"`` / ``"reference"`` (closed loop with ``controller``, a
    :class:`popup.control.Controller` or :class:`popup.control.Task`, default
    ``Controller()``) or ``"locked"`` (modes only). ``outputs``: channel names (default
    :data:`DEFAULT_OUTPUTS`).

    The closed loop is the continuous-time equivalent of the discrete cascade: velocity PI
    and current loop as a first-order lag ω_i. ``delay``: add the controller's zero-order
    hold as a half-period delay T/2 (first-order Padé). Default (None): only with an ideal
    current loop (ω_i = ∞). With a finite ω_i the core's exact discretisation of the lag
    applies, over [t_k, t_{k+1}), the lag's value at t_{k+1}: a half-period lead that
    cancels the hold's half-period lag (with it the linear −3 dB cut-off of the thesis's
    velocity loop is 702 rad/s against 705 simulated; with the delay added, 731).
    Valid well below the controller's Nyquist frequency π·rate. Not modelled: the torque limit (small-signal model),
    encoder quantisation, and the damping PIDs (a controller with damping on is refused:
    use :func:`simulate`)."""
    if input not in INPUT_KINDS:
        raise InputError(f"input input: {input!r} must be one of {list(INPUT_KINDS)}")
    sw = _sweep(model, payload_kg, pressure_pa, q_motor)
    outs = list(DEFAULT_OUTPUTS if outputs is None else outputs)
    for o in outs:
        if o not in CHANNELS:
            raise InputError(f"input outputs: unknown channel {o!r}; channels are {CHANNELS}")
    core_kind = {"torque": "torque", "motor_angle": "acceleration", "velocity": "torque", "reference": "torque", "locked": "locked"}[input]
    pres = np.column_stack([sw["p1"], sw["p2"]])
    qm = np.column_stack([sw["q1"], sw["q2"], sw["q3"]])
    fx = None if effects is None else np.ascontiguousarray(np.broadcast_to(np.asarray(effects, dtype=np.float64), (len(sw["q1"]), np.shape(effects)[-1])))
    r = _core.linearize(model.core, np.ascontiguousarray(sw["payload_kg"]), np.ascontiguousarray(pres), np.ascontiguousarray(qm), core_kind, outs, 0.0, fx)
    seen = set()
    for ws in r["warnings"]:
        for w in ws:
            if w not in seen:
                seen.add(w)
                _warnings.warn(w, PopupWarning, stacklevel=2)
    names = model.joint_names
    n2 = r["a"].shape[1]
    a, b, c, d = (np.asarray(r[k]) for k in ("a", "b", "c", "d"))
    states, inputs = list(r["states"]), list(r["inputs"])
    passive = None
    info: Dict[str, Any] = {}
    if input == "motor_angle":
        inputs = ["q1_ref", "q2_ref", "q3_ref"]
        free = list(r["free"])
        motors = set(model.core.motor_index)
        npos = len(free)
        pj = [k for k, j in enumerate(free) if j not in motors]
        passive = np.array(pj + [npos + k for k in pj])
    if input in ("velocity", "reference"):
        text = _controller_text(controller)
        ctrl = _core.controller_params(model.core, text, "<controller>")
        if any(ctrl["damping"]):
            raise InputError("input controller: the linearised loop does not model the damping PIDs (damping is on); use popup.frequency.simulate, or Controller(damping=False)")
        if delay is None:
            delay = not all(np.isfinite(m["current_bandwidth"]) for m in ctrl["motors"])
        # the motors' places in the state (rigid links' locked joints are not states)
        free = [int(j) for j in r["free"]]
        motor_pos = [free.index(int(i)) for i in model.core.motor_index]
        a, b, c, d, extra = _close_loop({"a": a, "b": b, "c": c, "d": d}, ctrl, motor_pos, n2 // 2, input, bool(delay))
        states = states + extra
        inputs = [f"{'v' if input == 'velocity' else 'r'}{k + 1}_ref" for k in range(3)]
        info["controller"] = ctrl
    return LinearModel(
        a=a,
        b=b,
        c=c,
        d=d,
        input=input,
        states=states,
        inputs=inputs,
        outputs=outs,
        q0=np.asarray(r["q0"]),
        u0=np.asarray(r["u0"]),
        y0=np.asarray(r["y0"]),
        sweep={k: v for k, v in sw.items() if k != "amplitude"},
        joint_names=names,
        n_plant=n2,
        s_power=2 if input == "motor_angle" else 0,
        passive_block=passive,
        info=info,
    )


# =============================================================================== link models
def rigid_links(model: "Model", factor: Optional[float] = None) -> "Model":
    """A copy of ``model`` with rigid links: by default truly rigid (both links
    ``"rigid"``, :meth:`popup.Model.with_links`: the universal joints locked, the root
    moments are the constraint moments). With ``factor`` instead the quasi-rigid PRBM of
    earlier versions: the bending stiffness table × ``factor`` (damping unchanged), the
    bending modes moved up by √factor. Payload and pressures are kept."""
    if factor is None:
        return model.with_links("rigid", "rigid")
    import tomllib

    d = tomllib.loads(model.arm.to_toml())
    k = [float(x) * factor for x in d["stiffness"]["k_nm_per_rad"]]
    arm = model.arm.with_overrides({"stiffness": {"k_nm_per_rad": k}})
    return model._recompiled(arm)


# =============================================================================== simulate
def _groups(durations: np.ndarray, ratio: float) -> List[List[int]]:
    """Indices grouped (by decreasing duration) so that within a group the longest run is at
    most ``ratio`` times the shortest."""
    order = list(np.argsort(-durations, kind="stable"))
    out: List[List[int]] = []
    for i in order:
        if out and durations[out[-1][0]] <= ratio * durations[i]:
            out[-1].append(int(i))
        else:
            out.append([int(i)])
    return out


def _sample_period(dt: float, omega_max: float, per_period: int) -> float:
    """Largest multiple of dt giving at least ``per_period`` samples per period of
    ``omega_max``."""
    T = 2 * np.pi / omega_max
    return dt * max(1, int(math.floor(T / (per_period * dt))))


def _channel_getter(outputs: Sequence[str], closed: bool) -> Tuple[List[int], List[int]]:
    from .control import CONTROL_CHANNELS

    si, ci = [], []
    for o in outputs:
        if o in CHANNELS:
            si.append(CHANNELS.index(o))
            ci.append(-1)
        elif closed and o in CONTROL_CHANNELS:
            si.append(-1)
            ci.append(CONTROL_CHANNELS.index(o))
        else:
            raise InputError(f"input outputs: unknown channel {o!r}; channels are {CHANNELS}" + (f" and {CONTROL_CHANNELS}" if closed else ""))
    return si, ci


def _pick(data: np.ndarray, ctrl: Optional[np.ndarray], si: List[int], ci: List[int]) -> np.ndarray:
    """(B, S, P) output array from the sensor and controller channels."""
    cols = [data[..., s] if s >= 0 else ctrl[..., c] for s, c in zip(si, ci)]  # type: ignore[index]
    return np.stack(cols, axis=-1)


def _task_for(kind: str, j: int, q_motor: Sequence[float], sig: Dict[str, Any], controller: Any) -> "Task":
    from .control import Controller, Phase, Task, chirp, const, sine

    ctrl = controller if controller is not None else Controller()
    if isinstance(ctrl, Task):
        raise InputError("input controller: give a popup.control.Controller for simulate (the task is built from the excitation)")
    faults = {"wrinkle": "continue", "saturation": "continue", "contact": "continue"}
    off = 0.0 if kind == "velocity" else float(q_motor[j])
    if sig["kind"] == "sine":
        ex = sine(float(sig["amplitude"]), float(sig["freq_hz"]), offset=off)
    else:
        ex = chirp(float(sig["amplitude"]), float(sig["f0_hz"]), float(sig["f1_hz"]), float(sig["duration"]), offset=off)
    if kind == "velocity":
        sigs = [const(0.0), const(0.0), const(0.0)]
        sigs[j] = ex
        ph = Phase("phase", name="excitation", velocity=sigs, until={"max_time": 1e9})
    else:
        sigs = [const(float(q)) for q in q_motor]
        sigs[j] = ex
        ph = Phase("phase", name="excitation", track=sigs, until={"max_time": 1e9})
    return Task([ph], ctrl, faults=faults)


def _run_batch(
    model: "Model",
    kind: str,
    j: int,
    sw: Dict[str, np.ndarray],
    jobs: List[Tuple[int, Dict[str, Any]]],
    duration: float,
    sample_period: float,
    controller: Any,
    outputs: Sequence[str],
    threads: int,
    u0: np.ndarray,
) -> Tuple[np.ndarray, np.ndarray, List[Optional[str]]]:
    """One batched engine call. ``jobs``: (run index b, excitation signal dict with kind
    ``sine`` or ``chirp`` and its amplitude/frequency). Returns (t (S,), outputs (J, S, P),
    errors)."""
    bidx = np.array([b for b, _ in jobs])
    pay = sw["payload_kg"][bidx]
    pres = np.column_stack([sw["p1"], sw["p2"]])[bidx]
    qm = np.column_stack([sw["q1"], sw["q2"], sw["q3"]])[bidx]
    closed = kind in ("velocity", "reference")
    si, ci = _channel_getter(outputs, closed)
    if closed:
        texts = [_task_for(kind, j, qm[k], s, controller).to_toml() for k, (_, s) in enumerate(jobs)]
        data, ctrl, errors, _ev, status, _al, warns = _core.closed_loop_rollout_multi(
            model.core,
            texts,
            np.ascontiguousarray(pay),
            np.ascontiguousarray(pres),
            np.ascontiguousarray(qm),
            float(duration),
            float(sample_period),
            None,
            None,
            int(threads),
            True,
            "<frequency>",
        )
        errs: List[Optional[str]] = [None if e is None else e[1] for e in errors]
        for k, st in enumerate(status):
            if st != "completed" and errs[k] is None:
                errs[k] = f"run {st}"
        data = np.asarray(data)
        y = _pick(data, np.asarray(ctrl), si, ci)
    else:
        # samples at dt/2: RK4's stages sit on them (torques: exact; replay: spline knots);
        # replay refines to >= 64 knots per period of the fastest sine (the spline's
        # acceleration error is (ω h)²/12)
        h = model.dt / 2
        if kind == "motor_angle":
            w_hi = max(2 * np.pi * float(s.get("freq_hz", s.get("f1_hz", 0.0))) for _, s in jobs)
            h /= max(1, math.ceil(h / (2 * np.pi / w_hi / 64)))
        tt = np.arange(int(math.ceil(duration / h)) + 2) * h
        vals = np.empty((len(jobs), tt.size, 3))
        for k, (b, s) in enumerate(jobs):
            base = u0[b] if kind == "torque" else qm[k]
            vals[k] = base
            vals[k, :, j] += _eval_signal(s, tt)
        if kind == "torque":
            res = model.rollout(payload_kg=pay, pressure_pa=pres, torque=vals, torque_times=tt, duration=duration, initial_q=_rest_q(model, sw, bidx), sample_rate=1.0 / sample_period, threads=threads, raise_on_error=False)
        else:
            res = model.rollout(payload_kg=pay, pressure_pa=pres, encoder_t=tt, encoder_q=vals, sample_rate=1.0 / sample_period, threads=threads, raise_on_error=False)
        errs = list(res.errors)
        data = np.asarray(res.data)
        y = _pick(data, None, si, ci)
    t = data[0, :, 0] if np.isfinite(data[0, 0, 0]) else np.arange(data.shape[1]) * sample_period
    return t, y, errs


def _rest_q(model: "Model", sw: Dict[str, np.ndarray], bidx: np.ndarray) -> np.ndarray:
    qs = []
    for b in bidx:
        m = model.with_params(payload_kg=float(sw["payload_kg"][b]), pressure_pa=(float(sw["p1"][b]), float(sw["p2"][b])))
        qs.append(m.rest_state((float(sw["q1"][b]), float(sw["q2"][b]), float(sw["q3"][b]))))
    return np.array(qs)


def _eval_signal(s: Dict[str, Any], t: np.ndarray) -> np.ndarray:
    """The excitation (without offset) at times t, as the controller's reference generator
    evaluates it (docs/control.md)."""
    A = float(s["amplitude"])
    if s["kind"] == "sine":
        tr = float(s.get("ramp", 0.0))
        env = np.where(t < tr, 0.5 - 0.5 * np.cos(np.pi * np.clip(t, 0.0, None) / max(tr, 1e-300)), 1.0) if tr > 0 else 1.0
        return A * env * np.sin(2 * np.pi * float(s["freq_hz"]) * t)
    f0, f1, D = float(s["f0_hz"]), float(s["f1_hz"]), float(s["duration"])
    tau = np.clip(t, 0.0, D)
    out = A * np.sin(2 * np.pi * (f0 * tau + (f1 - f0) * tau * tau / (2 * D)))
    return np.where(t <= D, out, 0.0)


def _auto_settle(model: "Model", w: np.ndarray, input: str, sw: Dict[str, np.ndarray], controller: Any, cap: float) -> np.ndarray:
    """Settling time per frequency [s]: 5/(ζ ω_n) of the linearised modes within a factor 3
    of ω (max over the sweep), at least 0.15 s, at most ``cap``."""
    kind = {"motor_angle": "locked"}.get(input, input)
    try:
        lin = linearize(
            model,
            np.column_stack([sw["q1"], sw["q2"], sw["q3"]]),
            input=kind,
            outputs=[],
            payload_kg=sw["payload_kg"],
            pressure_pa=np.column_stack([sw["p1"], sw["p2"]]),
            controller=controller,
        )
    except InputError as e:
        _warnings.warn(f"settle_s='auto' needs the linearised model ({e}); using 1 s", PopupWarning, stacklevel=3)
        return np.full(w.size, 1.0)
    out = np.full(w.size, 0.15)
    for poles in lin.poles():
        for r in modes_from_poles(poles):
            if not (0 < r["zeta"] < 1 and r["wn"] > 0):
                continue
            near = (w >= r["wn"] / 3) & (w <= 3 * r["wn"])
            out[near] = np.maximum(out[near], 5.0 / (r["zeta"] * r["wn"]))
    return np.minimum(out, cap)


def simulate(
    model: "Model",
    omega: Any = None,
    *,
    input: str = "torque",
    joint: Union[str, int] = "q3",
    outputs: Sequence[str] = ("dq3",),
    amplitude: Any = 0.1,
    method: str = "stepped",
    q_motor: Any = (0.0, 0.0, 0.0),
    payload_kg: Any = None,
    pressure_pa: Any = None,
    controller: Optional["Controller"] = None,
    settle_periods: int = 3,
    settle_s: Union[float, str] = 0.15,
    max_settle_s: float = 60.0,
    window_periods: int = 3,
    window_s: float = 0.1,
    ramp_periods: int = 3,
    fit_window: str = "hann",
    samples_per_period: int = 24,
    group_ratio: float = 2.0,
    chirp_band: Optional[Tuple[float, float]] = None,
    chirp_duration: Optional[float] = None,
    nperseg: Optional[int] = None,
    window: str = "hann",
    sample_rate: Optional[float] = None,
    threads: int = 0,
) -> FRF:
    """Simulated FRF of the non-linear engine from ``input`` on motor ``joint`` to
    ``outputs`` (channel names; closed loops also take the controller channels such as
    ``tau_cmd3``) at input ``amplitude`` (torque [N·m], angle [rad], velocity [rad/s],
    reference [rad]; scalar or one per run).

    ``method="stepped"``: one run per frequency of ``omega`` (F,) [rad/s], each from rest at
    the operating point; the excitation ``amplitude · sin ωt`` (open loop: faded in over
    ``ramp_periods`` periods by a raised cosine, so that lightly damped modes away from ω
    are hardly excited by the start) settles for ``max(settle_periods, settle_s/T)``
    periods, then the first harmonic of each output is fitted over
    ``max(window_periods, window_s/T)`` whole periods (:func:`sine_fit`, linear trend,
    ``fit_window`` weighting); H = output phasor / amplitude (a describing function when
    the loop saturates). ``settle_s="auto"``: five time constants 1/(ζ ω_n) of every mode
    of the linearised model within a factor 3 of ω (at least 0.15 s, at most
    ``max_settle_s``) — what a lightly damped bending mode needs to reach its steady
    state. Runs of similar length (within ``group_ratio``) are one batched engine call,
    padded to the longest (the extra time is more settling). Sampling: at least
    ``samples_per_period`` per period (a multiple of dt). ``coherence`` = share of the
    output's detrended variance in the first harmonic.

    ``method="chirp"``: one run per sweep point with a linear chirp over ``chirp_band`` =
    (ω0, ω1) [rad/s] (default the range of ``omega``) widened by √2 at both ends, lasting
    ``chirp_duration`` [s] (default 20 periods of ω0, at least 2 s), sampled at
    ``sample_rate`` [Hz] (default ≥ 6 samples per period of the top frequency, a multiple
    of dt); H1 and coherence by :func:`h1_estimate` (``nperseg`` default: 4 periods of the
    lowest swept frequency, ``window`` Hann, half overlap) on the Welch bins in [ω0, ω1].

    Sweep: ``payload_kg`` ([B]), ``pressure_pa`` ([B] x 2), ``q_motor`` ([B] x 3),
    ``amplitude`` ([B]) are broadcast to one batch; all of it is one call. Closed-loop
    inputs need the controller period to be a multiple of the model's dt (``dt=1e-4`` for
    the default 10 kHz controller). A run that fails or goes unstable gives NaN (and a
    warning naming it).
    """
    if input not in INPUT_KINDS or input == "locked":
        raise InputError(f"input input: {input!r} must be one of 'torque', 'motor_angle', 'velocity', 'reference'")
    if method not in ("stepped", "chirp"):
        raise InputError(f"input method: {method!r} must be 'stepped' or 'chirp'")
    j = _joint_index(joint)
    sw = _sweep(model, payload_kg, pressure_pa, q_motor, amplitude)
    nb = len(sw["q1"])
    outs = list(outputs)
    _channel_getter(outs, input in ("velocity", "reference"))
    u0 = np.zeros((nb, 3))
    if input == "torque":
        for b in range(nb):
            m = model.with_params(payload_kg=float(sw["payload_kg"][b]), pressure_pa=(float(sw["p1"][b]), float(sw["p2"][b])))
            u0[b] = m.holding_torque((float(sw["q1"][b]), float(sw["q2"][b]), float(sw["q3"][b])))
    dt = model.dt
    info: Dict[str, Any] = {"errors": {}}
    if method == "stepped":
        if omega is None:
            raise InputError("input omega: the stepped sine needs its frequencies [rad/s]")
        w = np.asarray(omega, dtype=np.float64).ravel()
        if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise InputError("input omega: frequencies must be finite and > 0 rad/s")
        T = 2 * np.pi / w
        if isinstance(settle_s, str):
            if settle_s != "auto":
                raise InputError(f"input settle_s: {settle_s!r} must be a time [s] or 'auto'")
            st = _auto_settle(model, w, input, sw, controller, max_settle_s)
        else:
            st = np.full(w.size, float(settle_s))
        n_set = np.maximum(settle_periods, np.ceil(st / T))
        ramp = 0 if input in ("velocity", "reference") else int(ramp_periods)
        n_set = np.maximum(n_set, ramp + 1)
        n_win = np.maximum(window_periods, np.ceil(window_s / T))
        dur = (n_set + n_win) * T
        H = np.full((nb, w.size, len(outs)), np.nan + 0j)
        coh = np.full((nb, w.size, len(outs)), np.nan)
        for grp in _groups(dur, group_ratio):
            D = float(dur[grp].max())
            sp = _sample_period(dt, float(w[grp].max()), samples_per_period)
            D_run = math.ceil(D / sp - 1e-9) * sp + 2 * sp
            jobs = [(b, {"kind": "sine", "amplitude": float(sw["amplitude"][b]), "freq_hz": float(w[f] / (2 * np.pi)), "ramp": ramp * float(T[f])}) for f in grp for b in range(nb)]
            t, y, errs = _run_batch(model, input, j, sw, jobs, D_run, sp, controller, outs, threads, u0)
            for k, (f, b) in enumerate([(f, b) for f in grp for b in range(nb)]):
                if errs[k] is not None:
                    info["errors"][(b, float(w[f]))] = errs[k]
                    continue
                t_end = D_run - 2 * sp
                t0 = t_end - n_win[f] * T[f]
                sel = (t >= t0 - 0.5 * sp) & (t < t_end - 0.5 * sp)
                ph = sine_fit(t[sel], y[k, sel], float(w[f]), window=fit_window)
                A = float(sw["amplitude"][b])
                H[b, f] = ph / A if A > 0 else np.nan
                coh[b, f] = _harmonic_fraction(t[sel], y[k, sel], float(w[f]))
        info.update({"settle_periods": n_set, "window_periods": n_win})
    else:
        if chirp_band is None:
            if omega is None:
                raise InputError("input: the chirp needs chirp_band=(ω0, ω1) [rad/s] or omega")
            wv = np.asarray(omega, dtype=np.float64)
            chirp_band = (float(wv.min()), float(wv.max()))
        w0, w1 = float(chirp_band[0]), float(chirp_band[1])
        if not (0 < w0 < w1 and math.isfinite(w1)):
            raise InputError(f"input chirp_band: need 0 < ω0 < ω1, got {chirp_band}")
        # the sweep runs over [ω0/√2, ω1·√2]; the estimate is kept on [ω0, ω1] (the ends of
        # a sweep, where it starts and stops, are biased)
        e0, e1 = w0 / math.sqrt(2.0), w1 * math.sqrt(2.0)
        Dc = float(chirp_duration) if chirp_duration is not None else max(20 * 2 * np.pi / w0, 2.0)
        if sample_rate is None:
            sp = _sample_period(dt, e1, 6)
        else:
            sp = dt * max(1, int(round(1.0 / (sample_rate * dt))))
        fs = 1.0 / sp
        D_run = math.ceil(Dc / sp) * sp + 2 * sp
        jobs = [(b, {"kind": "chirp", "amplitude": float(sw["amplitude"][b]), "f0_hz": e0 / (2 * np.pi), "f1_hz": e1 / (2 * np.pi), "duration": Dc}) for b in range(nb)]
        t, y, errs = _run_batch(model, input, j, sw, jobs, D_run, sp, controller, outs, threads, u0)
        nps = int(nperseg) if nperseg is not None else int(min(len(t), round(4 * 2 * np.pi / e0 * fs)))
        wl = None
        H_l, C_l = [], []
        for b in range(nb):
            sel = t <= Dc + 0.5 * sp
            if errs[b] is not None:
                info["errors"][(b, math.nan)] = errs[b]
            u = _eval_signal(jobs[b][1], t[sel])
            wl, Hb, Cb = h1_estimate(u, y[b, sel], fs, nperseg=nps, window=window)
            H_l.append(Hb)
            C_l.append(Cb)
        assert wl is not None
        keep = (wl >= w0) & (wl <= w1)
        w = wl[keep]
        H = np.array(H_l)[:, keep]
        coh = np.array(C_l)[:, keep]
        info.update({"chirp_band": (w0, w1), "chirp_duration": Dc, "fs": fs, "nperseg": nps})
    for (b, f), e in info["errors"].items():
        _warnings.warn(f"frequency run {b} at ω = {f:g} rad/s failed: {e}", PopupWarning, stacklevel=2)
    return FRF(omega=w, H=H, outputs=outs, input=input, joint=f"q{j + 1}", method=f"simulated-{method}", sweep=sw, coherence=coh, info=info)

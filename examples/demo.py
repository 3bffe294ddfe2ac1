"""The main job (until the diagnosis loop lands): a lab-style experiment on popup-lab.

1. Statics: equilibrium sag and locked-motor modes of the reference arm (compare with
   reference-arm.md).
2. Encoder-driven replay of a shoulder/elbow move with a 2 kg payload, then a hold: the
   bending ring-down after the stop, the motor torques needed, the wrinkling margin.
3. A batched payload sweep (0–2.5 kg) of the same move, in parallel in Rust.

Writes out/demo_replay.png and out/demo_sweep.png.
"""

from __future__ import annotations

import os
import time
import warnings

import numpy as np

import popup


def min_jerk(t: np.ndarray, t0: float, t1: float, a: float, b: float) -> np.ndarray:
    s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return a + (b - a) * (10 * s**3 - 15 * s**4 + 6 * s**5)


def main() -> None:
    os.makedirs("out", exist_ok=True)
    model = popup.Model(payload_kg=2.0, pressure_pa=(30e3, 30e3))
    print(f"popup {popup.__version__} ({popup.build_profile}), {model}")

    print("\n1. statics of popup-lab (30 kPa, gravity on)")
    print("   payload  pose              d12 [rad]   d22 [rad]   modes [rad/s]")
    for payload, pose in [(0.0, (0, 0, 0)), (2.0, (0, 0, 0)), (2.0, (0, 0.6, -0.3))]:
        m = model.with_params(payload_kg=payload)
        q = m.rest_state(pose)
        modes = m.locked_modes(pose)
        print(f"   {payload:4.1f} kg  {str(pose):16s}  {q[3]:+.5f}    {q[6]:+.5f}    " + ", ".join(f"{w:.1f}" for w in modes))

    print("\n2. encoder replay: move q2 0 -> 0.6 rad, q3 0 -> -0.3 rad in 1.2 s, hold 2.8 s (500 Hz)")
    t = np.arange(0.0, 4.0 + 1e-9, 0.002)
    q = np.stack([min_jerk(t, 0.5, 1.7, 0.0, 0.3), min_jerk(t, 0.5, 1.7, 0.0, 0.6), min_jerk(t, 0.5, 1.7, 0.0, -0.3)], axis=1)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)
        res = model.replay(t, q, sample_rate=500)
    wall = time.perf_counter() - t0
    hold = res.time > 1.7
    ring = res.bending[hold, 3] - res.bending[-1, 3]
    # ring-down frequency from zero crossings of d22 after the stop
    zc = np.flatnonzero(np.diff(np.sign(ring)) != 0)
    f_ring = (len(zc) - 1) / (2 * (res.time[hold][zc[-1]] - res.time[hold][zc[0]])) if len(zc) > 2 else float("nan")
    print(f"   {len(res)} samples, 4 s simulated in {wall * 1e3:.1f} ms")
    print(f"   peak bending |d22| = {np.max(np.abs(res.bending[:, 3])):.4f} rad, ring-down at {2 * np.pi * f_ring:.1f} rad/s "
          f"(locked-motor first modes {model.locked_modes((0.3, 0.6, -0.3))[0]:.1f} rad/s)")
    print(f"   peak motor torques [N·m]: {np.max(np.abs(res.tau), axis=0).round(2)}")
    print(f"   peak |M|/M_w per link: {np.max(res.moment_ratio, axis=0).round(2)} "
          f"(M_w = {model.wrinkling_moment.round(2)} N·m, classical coefficient π/2)")
    for a in res.alarms[:4]:
        print(f"   wrinkling alarm: link {a.link} from t = {a.t_start:.3f} s, peak |M|/M_w = {a.peak_ratio:.2f}")
    fig = res.plot()
    fig.savefig("out/demo_replay.png", dpi=90)

    print("\n3. batched payload sweep 0..2.5 kg of the same move (parallel, GIL released)")
    payloads = np.linspace(0.0, 2.5, 6)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", popup.PopupWarning)
        batch = model.rollout(payload_kg=payloads, encoder_t=t, encoder_q=q, sample_rate=500, threads=0)
    wall = time.perf_counter() - t0
    print(f"   {len(batch)} runs in {wall * 1e3:.1f} ms")
    print("   payload  ee z - rigid at t=4 s [mm]  peak |d22| [rad]  peak tau2 [N·m]  peak |M2|/M_w")
    for b, p in enumerate(payloads):
        sag = (batch.ee[b, -1, 2] - popup.Model(payload_kg=0.0).end_effector(np.r_[0.3, 0.6, 0, 0, -0.3, 0, 0])[2]) * 1e3
        print(f"   {p:4.1f} kg  {sag:9.2f}                   {np.max(np.abs(batch.bending[b, :, 3])):.4f}           "
              f"{np.max(np.abs(batch.tau[b, :, 1])):7.2f}          {np.max(batch.moment_ratio[b, :, 1]):.2f}")
    batch.plot("d22").savefig("out/demo_sweep.png", dpi=90)
    print("\nwrote out/demo_replay.png, out/demo_sweep.png")


if __name__ == "__main__":
    main()

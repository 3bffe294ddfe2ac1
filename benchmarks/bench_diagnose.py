"""Speed of the diagnosis: a 20 s run at 500 Hz against the whole effect library.

Target (issue 3): under a minute on 2 cores. Prints wall time, rollouts, the time per
simulated second, each candidate's rollouts and time, and the rollouts computed from a
shared motion (`Model.motion_hits`, docs/engine.md); with several ``--threads`` values it
checks that they give the same suspects, bit for bit. Run on demand:

    python benchmarks/bench_diagnose.py [--duration 20] [--threads 0] [--threads 1 --threads 0]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

import popup
from popup.diagnosis import rank


def _key(d: popup.Diagnosis) -> list:
    return [(s.effect, s.score, s.error_after, s.n_rollouts, {k: np.asarray(v).tobytes() for k, v in s.params.items()}) for s in d.suspects]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=500.0)
    ap.add_argument("--threads", type=int, action="append", help="cores to use (0 = all; repeat to compare)")
    a = ap.parse_args()
    t, q = popup.synth.lab_trajectory(a.duration, rate=a.rate, seed=11)
    truth = popup.Model("popup-lab", payload_kg=1.0).with_effect("joint_friction", tau_c=[1.5, 2.0, 0.8], b=[0.3, 0.2, 0.1])
    cores = os.cpu_count()
    print(f"load average at start: {os.getloadavg()}")
    keys = []
    with tempfile.TemporaryDirectory() as tmp:
        run = popup.synth.measured_run(truth, t, q, tmp, seed=11)
        for threads in a.threads or [0]:
            nominal = popup.Model("popup-lab", payload_kg=1.0)
            times = {}
            orig = rank.try_effect

            def timed(prob, name, *args, **kw):
                t0 = time.perf_counter()
                out = orig(prob, name, *args, **kw)
                times[name] = time.perf_counter() - t0
                return out

            rank.try_effect = timed
            try:
                t0 = time.perf_counter()
                d = popup.diagnose(nominal, run, threads=threads)
                wall = time.perf_counter() - t0
            finally:
                rank.try_effect = orig
            keys.append(_key(d))
            print(f"diagnose: {a.duration:g} s run at {a.rate:g} Hz, {len(d.suspects)} effects, threads={threads or cores} ({cores} cores)")
            print(f"  wall time        {wall:8.1f} s   (target < 60 s on 2 cores)")
            print(f"  rollouts         {d.n_rollouts:8d}   ({wall / max(d.n_rollouts, 1) * 1e3:.1f} ms each, {a.duration * d.n_rollouts / wall:.0f} simulated s per wall s)")
            print(f"  jobs computed from a kept motion (no physics run): {nominal.core.motion_hits} (jobs sharing a batch's motion not counted)")
            print(f"  top suspect      {d.suspects[0].effect} (significant: {d.suspects[0].significant}), error {d.nominal_error:.4f} -> {d.suspects[0].error_after:.4f}")
            for s in d.suspects:
                print(f"    {s.effect:22s} {s.n_rollouts:6d} rollouts  {times.get(s.effect, float('nan')):7.1f} s on its thread  dt {s.dt:.2e}")
    if len(keys) > 1:
        same = all(k == keys[0] for k in keys[1:])
        print(f"suspects for threads {a.threads}: {'the same bits' if same else 'DIFFERENT'}")
    print(f"load average at end: {os.getloadavg()}")


if __name__ == "__main__":
    main()

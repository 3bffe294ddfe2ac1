"""Speed of the diagnosis: a 20 s run at 500 Hz against the whole effect library.

Target (issue 3): under a minute on 2 cores. Prints wall time, rollouts and the time per
simulated second; run on demand:

    python benchmarks/bench_diagnose.py [--duration 20] [--threads 0]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import popup


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--rate", type=float, default=500.0)
    ap.add_argument("--threads", type=int, default=0)
    a = ap.parse_args()
    t, q = popup.synth.lab_trajectory(a.duration, rate=a.rate, seed=11)
    nominal = popup.Model("popup-lab", payload_kg=1.0)
    truth = nominal.with_effect("joint_friction", tau_c=[1.5, 2.0, 0.8], b=[0.3, 0.2, 0.1])
    with tempfile.TemporaryDirectory() as tmp:
        run = popup.synth.measured_run(truth, t, q, tmp, seed=11)
        t0 = time.perf_counter()
        d = popup.diagnose(nominal, run, threads=a.threads)
        wall = time.perf_counter() - t0
    cores = os.cpu_count()
    print(f"diagnose: {a.duration:g} s run at {a.rate:g} Hz, {len(d.suspects)} effects, threads={a.threads or cores} ({cores} cores)")
    print(f"  wall time        {wall:8.1f} s   (target < 60 s on 2 cores)")
    print(f"  rollouts         {d.n_rollouts:8d}   ({wall / max(d.n_rollouts, 1) * 1e3:.1f} ms each, {a.duration * d.n_rollouts / wall:.0f} simulated s per wall s)")
    print(f"  top suspect      {d.suspects[0].effect} (significant: {d.suspects[0].significant}), error {d.nominal_error:.4f} -> {d.suspects[0].error_after:.4f}")


if __name__ == "__main__":
    main()

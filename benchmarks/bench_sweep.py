#!/usr/bin/env python
"""Throughput of popup.sweep: runs per second and simulated seconds per wall second, against
the number of threads, the batch size and the executor.

    python benchmarks/bench_sweep.py            # about 2 min on 2 cores
    python benchmarks/bench_sweep.py --quick    # about 30 s
    python benchmarks/bench_sweep.py --runs 96 --duration 2 --no-dask

The workload: ``examples/scenarios/pick_and_place.toml`` without its sensor noise (so every
run goes through the batched closed-loop rollouts), ``duration`` simulated seconds per run
(controller 10 kHz, dt = 1e-4 s, RK4, 500 Hz output), ``runs`` runs over payload 0–2.5 kg.
Sections (everything is printed; nothing is asserted):

1. one by one: ``Scenario.run()`` in a Python loop (one core): the baseline;
2. local sweeps: ``threads`` x ``batch_size``;
3. executors: a ``ProcessPoolExecutor`` (spawn) and a ``dask.distributed`` LocalCluster
   with one worker process per core, one rayon thread per task (start-up time apart);
4. the planning overhead (every variant set, checked and converted in the parent).

"simulated s / wall s" counts every run's simulated time: runs/s x duration. "CPU ms/run" is
this process's CPU time (its rayon threads included) per run: it shows the per-run cost and
the batching overhead even on a machine shared with other work, where wall times are not
comparable (the load average is printed at the start and the end).
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Dict, List  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import popup  # noqa: E402
from machine import cpu_model, load_str, ncores  # noqa: E402
from popup.sweep import sweep  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def base(duration: float) -> popup.Scenario:
    """pick_and_place without sensor noise, ``duration`` s, 500 Hz output."""
    sc = popup.Scenario.read(ROOT / "examples" / "scenarios" / "pick_and_place.toml")
    d = sc.to_dict()
    d.pop("noise", None)
    d["duration_s"] = float(duration)
    return popup.Scenario.from_dict(d, str(sc.source), sc.base_dir)


def line(label: str, wall: float, nrun: int, duration: float, extra: str = "") -> Dict[str, Any]:
    rps = nrun / wall
    print(f"  {label:<44} {wall:8.2f} s  {rps:8.2f} runs/s  {rps * duration:8.1f} sim s/wall s  {extra}")
    return {"label": label, "wall_s": wall, "runs_per_s": rps, "sim_per_wall": rps * duration}


def best_of(k: int, f: Any) -> float:
    return min(_timed(f)[0] for _ in range(k))


def best_of_cpu(k: int, f: Any) -> Any:
    """(wall, CPU time of this process incl. its rayon threads) of the fastest of k calls."""
    return min((_timed(f) for _ in range(k)), key=lambda x: x[0])


def _timed(f: Any) -> Any:
    c0 = time.process_time()
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0, time.process_time() - c0


def main(argv: Any = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer and shorter runs")
    ap.add_argument("--runs", type=int, default=None, help="runs per sweep (default 64, quick 16)")
    ap.add_argument("--duration", type=float, default=None, help="simulated s per run (default 2, quick 1)")
    ap.add_argument("--repeat", type=int, default=None, help="best of N (default 2, quick 1)")
    ap.add_argument("--no-dask", action="store_true", help="skip the dask.distributed rows")
    a = ap.parse_args(argv)
    nrun = a.runs or (16 if a.quick else 64)
    dur = a.duration or (1.0 if a.quick else 2.0)
    rep = a.repeat or (1 if a.quick else 2)
    nc = ncores()
    sc = base(dur)
    grid = {"payload_kg": np.linspace(0.0, 2.5, nrun)}
    print("=" * 100)
    print("popup.sweep throughput")
    print("=" * 100)
    print(f"date     : {time.strftime('%Y-%m-%d %H:%M:%S')}")
    print(f"CPU      : {cpu_model()}; {nc} usable cores; {load_str()}")
    print(f"platform : {platform.platform()}; Python {platform.python_version()}")
    print(f"popup    : {popup.__version__} (build_profile={popup.build_profile}); numpy {np.__version__}")
    print(f"workload : {nrun} closed-loop runs x {dur:g} s simulated (pick_and_place.toml without noise: 10 kHz controller, dt 1e-4 s rk4, 500 Hz output), best of {rep}")
    print()

    print("1. one by one: Scenario.run() in a Python loop (one core)")
    k = max(2, nrun // 8)

    def one_by_one() -> None:
        for p in grid["payload_kg"][:k]:
            sc.set("payload_kg", float(p)).run()

    w, cpu = best_of_cpu(rep, one_by_one)
    line(f"{k} runs one by one", w, k, dur, f"CPU {1e3 * cpu / k:5.0f} ms/run")
    print()

    print("2. local sweeps (Rust batches, rayon threads)")
    threads = sorted({1, nc} | ({2} if nc > 2 else set()))
    sizes = sorted({1, 4, 16, nrun})
    ref = None
    for th in threads:
        for bs in sizes:
            res: List[Any] = []

            def go() -> None:
                res.append(sweep(sc, grid=grid, threads=th, batch_size=bs))

            w, cpu = best_of_cpu(rep, go)
            r = res[-1]
            if ref is None:
                ref = r
            same = np.array_equal(ref.table.select_dtypes("number").to_numpy(float), r.table.select_dtypes("number").to_numpy(float), equal_nan=True)
            line(f"threads={th} batch_size={bs}", w, nrun, dur, f"CPU {1e3 * cpu / nrun:5.0f} ms/run, chunks {r.info['chunks']:2d}, plan {r.info['plan_s']:.2f} s, identical {same}")
    res2: List[Any] = []
    w = best_of(rep, lambda: res2.append(sweep(sc, grid=grid)))
    line(f"default (threads=0, batch_size={res2[-1].info['batch_size']})", w, nrun, dur)
    print()

    print("3. executors (one worker process per core, threads_per_worker=1)")
    for bs in (4, 16):
        t0 = time.perf_counter()
        with ProcessPoolExecutor(max_workers=nc, mp_context=mp.get_context("spawn")) as ex:
            sweep(sc, grid={"payload_kg": [1.0] * nc}, executor=ex, batch_size=1, duration=0.01)  # start the workers
            up = time.perf_counter() - t0
            res3: List[Any] = []
            w = best_of(rep, lambda: res3.append(sweep(sc, grid=grid, executor=ex, batch_size=bs)))
        same = np.array_equal(ref.table.select_dtypes("number").to_numpy(float), res3[-1].table.select_dtypes("number").to_numpy(float), equal_nan=True)  # type: ignore[union-attr]
        line(f"ProcessPoolExecutor(spawn) batch_size={bs}", w, nrun, dur, f"start-up {up:.1f} s, identical {same}")
    if not a.no_dask:
        try:
            import distributed
        except ImportError:
            print("  (dask.distributed not installed: pip install 'dask[distributed]')")
        else:
            t0 = time.perf_counter()
            with distributed.LocalCluster(n_workers=nc, threads_per_worker=1, processes=True, dashboard_address=None, silence_logs=40) as cl, distributed.Client(cl) as client:
                client.wait_for_workers(nc, timeout=60)
                sweep(sc, grid={"payload_kg": [1.0] * nc}, executor=client, batch_size=1, duration=0.01)
                up = time.perf_counter() - t0
                for bs in (4, 16):
                    res4: List[Any] = []
                    w = best_of(rep, lambda: res4.append(sweep(sc, grid=grid, executor=client, batch_size=bs)))
                    same = np.array_equal(ref.table.select_dtypes("number").to_numpy(float), res4[-1].table.select_dtypes("number").to_numpy(float), equal_nan=True)  # type: ignore[union-attr]
                    line(f"dask LocalCluster({nc} workers) batch_size={bs}", w, nrun, dur, f"start-up {up:.1f} s, identical {same}")
    print()

    print("4. planning overhead in the parent (set + check + convert every variant)")
    big = 1000
    r = sweep(sc, grid={"payload_kg": np.linspace(0, 2.5, big)}, duration=0.001, batch_size=big)
    print(f"  {big} variants: plan {r.info['plan_s']:.2f} s = {1e3 * r.info['plan_s'] / big:.2f} ms per run")
    print(f"\n{load_str()} at the end")
    return 0


if __name__ == "__main__":
    sys.exit(main())

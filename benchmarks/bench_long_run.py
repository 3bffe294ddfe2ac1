#!/usr/bin/env python
"""Long headless run: memory, speed and log size of ``popup run`` writing an MCAP file.

    python benchmarks/bench_long_run.py                   # one hour simulated (about 1-3 min wall)
    python benchmarks/bench_long_run.py --duration 60     # shorter
    python benchmarks/bench_long_run.py --binary target/release/popup   # the Rust binary directly
    python benchmarks/bench_long_run.py --no-read         # skip reading the log back

Runs the headless CLI (by default ``python -m popup run``, i.e. the engine inside the
Python extension; ``--binary PATH`` runs a ``popup`` executable instead) on
``examples/scenarios/hold_1h.toml`` with ``--progress lines``, writing the MCAP log into a
temporary directory. While the child runs, its resident memory (VmRSS of
``/proc/<pid>/status``) is sampled every 0.5 s of wall time and paired with the simulated
time of the child's last progress line (``popup: t = ... s of ... s simulated ...`` on
stderr, read in a thread).

Printed (nothing is asserted):

0. machine (CPU, cores, platform, load) and the scenario's dt, sample rate, flush interval;
1. RSS against simulated-time progress (one row per tenth of the run);
2. peak RSS, RSS at 10 % vs at 100 % of the run (flatness), wall time, simulated seconds
   per wall second, file size and MB written per wall second;
3. with ``--read`` (default): the log read back with ``popup.read_log``: messages per
   topic, messages per simulated and per wall second of the run, and the read time and
   throughput (reading a one-hour log takes about a minute).
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import tomllib
from pathlib import Path
from typing import Dict, List, Optional, Tuple

sys.path.insert(0, str(Path(__file__).resolve().parent))
from machine import cpu_model, load_str, ncores  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENARIO = ROOT / "examples" / "scenarios" / "hold_1h.toml"
PROGRESS_RE = re.compile(r"popup: t = ([0-9.eE+-]+) s of ([0-9.eE+-]+) s simulated \(([0-9.eE+-]+)x real time")
MIB = 1024.0 * 1024.0


# ----------------------------------------------------------------------------- helpers
def proc_status_kib(pid: int, keys: Tuple[str, ...] = ("VmRSS", "VmHWM")) -> Dict[str, int]:
    """The given ``/proc/<pid>/status`` fields in KiB ({} once the process is gone or a zombie)."""
    out: Dict[str, int] = {}
    try:
        with open(f"/proc/{pid}/status") as f:
            for line in f:
                k, _, v = line.partition(":")
                if k in keys:
                    out[k] = int(v.split()[0])
    except (OSError, ValueError, IndexError):
        return {}
    return out


def file_size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


def scenario_settings(path: Path) -> Dict[str, object]:
    """dt, sample rate, flush interval etc. of a scenario, with the defaults of docs/logging.md."""
    with open(path, "rb") as f:
        doc = tomllib.load(f)
    ctl_rate = doc.get("controller", {}).get("rate_hz")
    dt = doc.get("dt", 1.0 / ctl_rate if ctl_rate else None)
    sr = float(doc.get("sample_rate_hz", 100.0))
    log = doc.get("log", {})
    return {
        "description": doc.get("description", ""),
        "arm": doc.get("arm", ""),
        "duration_s": doc.get("duration_s"),
        "dt": dt,
        "integrator": doc.get("integrator", "rk4"),
        "controller_rate_hz": ctl_rate,
        "sample_rate_hz": sr,
        "viz_rate_hz": float(log.get("viz_rate_hz", min(30.0, sr))),
        "flush_every_s": float(log.get("flush_every_s", 1.0)),
        "compression": log.get("compression", "zstd"),
        "chunk_size_bytes": int(log.get("chunk_size_bytes", 1 << 20)),
    }


class StderrReader(threading.Thread):
    """Reads the child's stderr line by line; keeps (wall, t, speed) of every progress line."""

    def __init__(self, stream, t0: float) -> None:
        super().__init__(daemon=True)
        self.stream = stream
        self.t0 = t0
        self.progress: List[Tuple[float, float, float]] = []
        self.other: List[str] = []
        self.sim_t = 0.0
        self.total: Optional[float] = None
        self.lock = threading.Lock()

    def run(self) -> None:
        for raw in self.stream:
            line = raw.decode("utf-8", "replace").rstrip("\n")
            m = PROGRESS_RE.search(line)
            if m:
                t, total, speed = float(m.group(1)), float(m.group(2)), float(m.group(3))
                with self.lock:
                    self.sim_t = t
                    self.total = total
                    self.progress.append((time.perf_counter() - self.t0, t, speed))
            elif line.strip():
                self.other.append(line)

    def current(self) -> float:
        with self.lock:
            return self.sim_t


# ----------------------------------------------------------------------------- the run
def run_child(cmd: List[str], out: Path, interval: float):
    """Run ``cmd``; sample its RSS every ``interval`` s. Returns (samples, reader, rc, wall, hwm_kib)."""
    samples: List[Tuple[float, float, int, int]] = []  # (wall s, simulated t, RSS KiB, file bytes)
    hwm = 0
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    reader = StderrReader(proc.stderr, t0)
    reader.start()
    next_t = t0
    while True:
        st = proc_status_kib(proc.pid)
        now = time.perf_counter()
        if "VmRSS" in st:
            samples.append((now - t0, reader.current(), st["VmRSS"], file_size(out)))
            hwm = max(hwm, st.get("VmHWM", 0))
        next_t += interval
        try:
            proc.wait(timeout=max(0.0, next_t - time.perf_counter()))
            break
        except subprocess.TimeoutExpired:
            pass
    wall = time.perf_counter() - t0
    reader.join(timeout=5.0)
    return samples, reader, proc.returncode, wall, hwm


def sample_at(samples, sim_t: float):
    """The first RSS sample whose simulated time is >= sim_t (the last one if none)."""
    for s in samples:
        if s[1] >= sim_t - 1e-9:
            return s
    return samples[-1]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=3600.0, help="simulated time [s] (default 3600)")
    ap.add_argument("--scenario", type=Path, default=DEFAULT_SCENARIO, help="scenario TOML (default examples/scenarios/hold_1h.toml)")
    ap.add_argument("--binary", type=Path, default=None, help="run this popup executable instead of `python -m popup`")
    ap.add_argument("--read", action=argparse.BooleanOptionalAction, default=True, help="read the log back with popup.read_log and count messages (default on)")
    ap.add_argument("--interval", type=float, default=0.5, help="RSS sampling interval [s wall] (default 0.5)")
    ap.add_argument("--keep", type=Path, default=None, help="write the MCAP file here and keep it (default: a temporary directory, removed)")
    args = ap.parse_args()

    sc = scenario_settings(args.scenario)
    if args.binary is not None:
        exe = [str(args.binary.resolve())]
        engine = f"{args.binary} (Rust binary)"
    else:
        exe = [sys.executable, "-m", "popup"]
        engine = f"{sys.executable} -m popup (engine in the Python extension)"

    print("=" * 100)
    print("popup long headless run (MCAP log): memory, speed, file size")
    print("=" * 100)
    print(f"date     : {time.strftime('%Y-%m-%d %H:%M:%S')}")
    print(f"CPU      : {cpu_model()}")
    print(f"cores    : {ncores()} usable (os.cpu_count() = {os.cpu_count()})")
    print(f"load     : {load_str()}  (at the start)")
    print(f"platform : {platform.platform()}; Python {platform.python_version()}")
    print(f"engine   : {engine}")
    try:
        import popup

        print(f"popup    : {popup.__version__} (build_profile={popup.build_profile})")
    except Exception as e:  # pragma: no cover
        print(f"popup    : not importable here ({e})")
    print(f"scenario : {args.scenario} ({sc['description']}); arm {sc['arm']}")
    print(
        f"           dt = {sc['dt']:g} s ({sc['integrator']}), controller {sc['controller_rate_hz']:g} Hz, "
        f"sample rate {sc['sample_rate_hz']:g} Hz, viz {sc['viz_rate_hz']:g} Hz, flush every {sc['flush_every_s']:g} s simulated, "
        f"{sc['compression']}, chunks {sc['chunk_size_bytes']} B"
    )
    n_steps = args.duration / sc["dt"] if sc["dt"] else float("nan")
    print(f"run      : --duration {args.duration:g} s simulated ({n_steps:.3g} physics steps), RSS sampled every {args.interval:g} s wall")
    print()

    tmp = None
    if args.keep is not None:
        out = args.keep.resolve()
        out.parent.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.mkdtemp(prefix="popup-long-run-")
        out = Path(tmp) / "run.mcap"
    try:
        cmd = exe + ["run", str(args.scenario), "--out", str(out), "--duration", repr(args.duration), "--progress", "lines"]
        print("$ " + " ".join(cmd))
        samples, reader, rc, wall, hwm = run_child(cmd, out, args.interval)
        size = file_size(out)
        if rc != 0 or not samples:
            print(f"child exited with code {rc} after {wall:.1f} s; stderr:")
            for line in reader.other[-30:]:
                print("  " + line)
            return rc or 1
        print(f"child exited with code 0 after {wall:.1f} s wall; {len(samples)} RSS samples, {len(reader.progress)} progress lines")
        for line in reader.other[-5:]:
            print("  child stderr: " + line)
        print()

        # ------------------------------------------------------------------ 1. table
        dur = args.duration
        print("-" * 100)
        print("1. resident memory (VmRSS) of the child against simulated-time progress")
        print("-" * 100)
        print(f"  {'progress':>8s} {'sim t [s]':>10s} {'wall [s]':>9s} {'RSS [MiB]':>10s} {'file [MB]':>10s}")
        rows = [samples[0]] + [sample_at(samples, f * dur) for f in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)] + [samples[-1]]
        rows = [s for i, s in enumerate(rows) if s not in rows[:i]]  # a short run has fewer samples than rows
        for s in rows:
            print(f"  {s[1] / dur:8.0%} {s[1]:10.1f} {s[0]:9.1f} {s[2] / 1024:10.1f} {s[3] / 1e6:10.1f}")
        print("  (first row: the first sample, at start-up; last row: the last sample before the child exited)")
        print()

        # ------------------------------------------------------------------ 2. figures
        rss = [s[2] for s in samples]
        peak_sampled = max(rss)
        peak = max(peak_sampled, hwm)
        r10 = sample_at(samples, 0.1 * dur)
        r100 = samples[-1]
        d_mib = (r100[2] - r10[2]) / 1024
        ratio = r100[2] / r10[2]
        last_speed = reader.progress[-1][2] if reader.progress else float("nan")
        t_first = reader.progress[0][0] if reader.progress else float("nan")
        print("-" * 100)
        print("2. figures")
        print("-" * 100)
        print(f"  peak RSS                  : {peak / 1024:.1f} MiB (max sampled {peak_sampled / 1024:.1f} MiB, kernel VmHWM {hwm / 1024:.1f} MiB)")
        print(
            f"  RSS at 10 % vs 100 %      : {r10[2] / 1024:.1f} MiB (t = {r10[1]:.0f} s) -> {r100[2] / 1024:.1f} MiB (t = {r100[1]:.0f} s): "
            f"{d_mib:+.2f} MiB ({r100[2] - r10[2]:+d} KiB), ratio {ratio:.3f}"
        )
        print(f"  wall time                 : {wall:.1f} s (process start to exit; first progress line after {t_first:.2f} s)")
        print(f"  simulated s per wall s    : {dur / wall:.1f} (the child's own last figure: {last_speed:.1f}x real time)")
        print(f"  physics steps per wall s  : {n_steps / wall / 1e6:.3f}e6")
        print(f"  file size                 : {size / 1e6:.1f} MB ({size / dur / 1e3:.1f} kB per simulated s)")
        print(f"  written per wall s        : {size / 1e6 / wall:.2f} MB/s")
        print(f"  {load_str()} at the end of the run")
        print()

        # ------------------------------------------------------------------ 3. read back
        if args.read:
            import popup

            print("-" * 100)
            print("3. the log read back with popup.read_log")
            print("-" * 100)
            t0 = time.perf_counter()
            log = popup.read_log(out)
            t_read = time.perf_counter() - t0
            n_msg = sum(log.topics.values())
            print(f"  {'topic':<22s} {'messages':>10s} {'per sim s':>10s}")
            for topic, n in log.topics.items():
                print(f"  {topic:<22s} {n:10d} {n / dur:10.1f}")
            print(f"  {'all':<22s} {n_msg:10d} {n_msg / dur:10.1f}")
            print(f"  complete = {log.complete}; run_end = {log.run_end}; table {log.table.shape[0]} rows x {log.table.shape[1]} columns")
            print(f"  messages per wall s (run) : {n_msg / wall:.0f}")
            print(f"  read time                 : {t_read:.1f} s: {size / 1e6 / t_read:.1f} MB/s, {n_msg / t_read:.0f} messages/s")
            print(f"  reader peak RSS           : {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB (this process, ru_maxrss)")
            print()
        else:
            print("(--no-read: messages not counted)")
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())

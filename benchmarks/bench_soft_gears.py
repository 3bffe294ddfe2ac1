"""Backlash alone on MuJoCo's soft gears with play on every joint (printed, not asserted).

The two archived runs whose compliant fit ended far above its truth before session 71
(MuJoCo 742 and 760: a two-mass gear on every joint, flanks of 4.7-5.2e4 N·m/rad damped
at ~69 N·m·s/rad, link sides of 0.1 kg·m², gaps of 12-28 mrad) are made again from their
seed and index (``rerun.remake``, the truth checked equal to the stored one) and diagnosed
with backlash as the only candidate (``popup.diagnose(..., effects=["backlash"])``, one
thread). Printed per run: the error left (noise units), the fitted gaps, flanks and link
sides beside the truth's, and the seconds::

    PYTHONPATH=python python3 benchmarks/bench_soft_gears.py [--out out/soft_gears] [742 760]

Session 70 measured 20.2 and 12.0 noise units on version ``483463088413``; session 71,
with the shared flank law as one more start, 0.18 and 0.37 (benchmarks/README.md).
"""
from __future__ import annotations

import argparse
import gzip
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import families as F  # noqa: E402
import rerun  # noqa: E402

RUNS = {
    "742": HERE / "results/fam_rr69b_9d09c4e/results/mujoco-backlash-000.json.gz",
    "760": HERE / "results/fam_ms760_9d09c4e/results/mujoco-backlash-000.json.gz",
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("seeds", nargs="*", default=sorted(RUNS), help=f"runs to diagnose (of {', '.join(sorted(RUNS))})")
    ap.add_argument("--out", default="out/soft_gears", help="folder for the runs made again")
    a = ap.parse_args()
    import popup
    from popup.io import read_run

    for seed in a.seeds:
        row = json.loads(gzip.decompress(RUNS[seed].read_bytes()))
        out = Path(a.out) / seed
        path = out / Path(row["run"]).name
        if not path.exists():
            path = rerun.remake(row["truth"], out)
        run = read_run(str(path))
        t0 = time.perf_counter()
        d = popup.diagnose(run.model(), run, effects=["backlash"], threads=1)
        s = next(x for x in d.suspects if x.effect == "backlash")
        truth = row["truth"]["effects"]["backlash"]
        print(f"{seed}: error {d.nominal_error:.4g} -> {s.error_after:.4g} noise units (truth at the run's step: "
              f"{row['truth_error']:.3g}); {time.perf_counter() - t0:.0f} s; {s.message.split('; ')[-1]}")
        print(f"  gap       {[round(g, 5) for g in s.params.get('gap', [])]}  truth {truth['gap']}")
        print(f"  contact_k {[round(k) for k in s.params.get('contact_k', [])]}  truth {truth.get('gear_k')}")
        print(f"  contact_c {[round(c, 2) for c in s.params.get('contact_c', [])]}  truth {truth.get('gear_d')}")
        print(f"  inertia   {[round(j, 4) for j in s.params.get('inertia', [])]}  truth {F.BACKLASH_OUT} (the gear's output inertia)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

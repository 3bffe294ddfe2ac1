"""Diagnose chosen runs of cached or archived results again, on this checkout.

For the checks of a new diagnosis version (``OUTCOME_EQUIVALENT`` and ``CARRIED_FORWARD``
in ``bench_diagnosis_families.py``) and for the results a change's ``PathTest`` says took
the changed path: each run is made again from its family's seed and index (the run folders
of ``out/`` are not kept), its truth checked equal to the stored one, diagnosed with the
bench's settings and written as ``OUT/results/<run>.json`` (and the run as ``OUT/<run>``),
for ``--pool`` and ``equivalence.py`` like any family folder::

    python3 benchmarks/rerun.py --out out/fam_rr59_COMMIT \\
        benchmarks/results/fam_pe651_d0a1136/results/popup-pressure_leak-002.json.gz ...
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_diagnosis_families as bench  # noqa: E402
import families as F  # noqa: E402


#: Truth keys the generator added after results were archived: a stored truth without one is
#: the same run (the pool fills ``member_sigma`` in from ``results/member_sigma.json``).
LATER_KEYS = ("member_sigma",)


def _load(f: Path) -> Dict[str, Any]:
    raw = f.read_bytes()
    return json.loads(gzip.decompress(raw) if f.suffix == ".gz" else raw)


def remake(truth: Dict[str, Any], out: Path) -> Path:
    """The run of ``truth`` made again under ``out`` from its family's seed and index (drawn
    as the bench draws it, or with the bench's ``--duration`` and ``--rates`` set to the
    truth's duration and rate where the plain draw differs: the independent runs' format);
    raises ``ValueError`` where the truth made now differs from the stored one (a family
    drawn with other overrides, or a generator that changed since)."""
    i = int(truth["index"])
    b = json.dumps(truth, sort_keys=True, default=str)
    a = ""
    for ov in ({}, {"duration": float(truth.get("duration", 0.0)), "rates": [float(truth.get("rate", 0.0))]}):
        spec = F.family_specs(str(truth["family"]), str(truth["engine"]), i + 1, int(truth["seed"]), biases=bool(truth.get("biases")), **ov)[i]
        path, now = F.make_run(spec, out)
        # keys the generator added since the stored truth was made (``member_sigma``, session 65)
        # describe the same run: compared only where the stored truth has them
        now = {k: v for k, v in now.items() if k in truth or k not in LATER_KEYS}
        a = json.dumps(now, sort_keys=True, default=str)
        if a == b:
            break
    if a != b:
        keys = sorted(k for k in set(now) | set(truth) if json.dumps(now.get(k), sort_keys=True, default=str) != json.dumps(truth.get(k), sort_keys=True, default=str))
        raise ValueError(f"{path.name}: the truth made now differs from the stored one (seed {truth['seed']}, index {i}; "
                         f"differing keys: {', '.join(keys)}): drawn with overrides, or the generator changed (a MuJoCo "
                         "backlash run made before session 67 has no 'gear': its gear cannot be made again)")
    return path


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", help="result files (results/<run>.json or .json.gz)")
    ap.add_argument("--out", required=True, help="folder for the runs and their new results")
    ap.add_argument("--timeout", type=float, default=2900.0, help="seconds per diagnosis (default 2900)")
    ap.add_argument("--diagnose-args", default="--threads 1", help="extra arguments for popup diagnose")
    a = ap.parse_args(argv)
    out = Path(a.out)
    (out / "results").mkdir(parents=True, exist_ok=True)
    extra = [x for x in a.diagnose_args.split() if x]
    files = list(map(Path, a.results))
    first: Dict[str, Path] = {}
    for f in files:
        name = f.name.split(".json")[0]
        if name in first and first[name].resolve() != f.resolve():
            ap.error(f"{first[name]} and {f} are both run {name!r}: one --out folder holds one result per run name; "
                     "rerun them into separate folders")
        first.setdefault(name, f)
    for f in files:
        truth = _load(f)["truth"]
        path = remake(truth, out)
        cache = out / "results" / f"{path.name}.json"
        if cache.is_file():
            kept = _load(cache).get("truth")
            if kept is not None and kept != truth:
                raise ValueError(f"{cache} holds another run than {f} (another seed or draw under the same name): "
                                 "rerun it into a separate --out folder")
            print(f"{cache} exists (kept)")
            continue
        bench.diagnose_row(path, truth, cache, timeout=a.timeout, extra=extra)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

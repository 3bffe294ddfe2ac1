"""Whether two diagnosis versions give the same outcomes on the same runs.

A change that only touches what the benchmark does not classify on (the wording after "not
explained by the library", a column of ``Comparison.spectrum``) cannot move a count, and
its results may be pooled with the version it came from
(``bench_diagnosis_families.OUTCOME_EQUIVALENT``). This script is the check behind such a
declaration: it pairs the kept results of the old version (folders ``--old``) with reruns of
the same runs on the new one (``--new``), by run name and truth, and compares every number
the classification reads - each round's effects, error and parameters, the suspects'
effect, significance, score and error after, the nominal error - bit for bit, and the
outcome. It prints the pairs that differ and exits 1 if any does.

Bit for bit holds on one kind of machine only: NumPy's SIMD code paths and OpenBLAS's
kernels differ between an AVX-512 and an AVX2 CPU in the last bits, and a diagnosis carries
that to ~1e-9 relative (session 46 found this behind 7 "different" nominal runs). Each kept
result records its ``machine`` (``bench_diagnosis_families.machine``) and, since session 52,
its ``libraries`` (NumPy, SciPy, pandas and Python versions); a pair made on different
machines or libraries is flagged, and the new version should then be rerun with the old
machine's code paths, e.g. ``NPY_DISABLE_CPU_FEATURES=X86_V4,AVX512_ICL,AVX512_SPR
OPENBLAS_CORETYPE=Haswell`` for results made on an AVX2 machine.

    python benchmarks/equivalence.py --old benchmarks/results/fam_pd623_06debd8 --new out/fam_pd623_fee02b5
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Tuple

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_diagnosis_families as B  # noqa: E402

#: What the classification reads of one result, bit for bit.
HISTORY_KEYS = ("effects", "round", "error", "params")
SUSPECT_KEYS = ("effect", "significant", "tested", "score", "error_after", "params")


def fingerprint(row: Dict[str, Any]) -> Dict[str, Any]:
    """The numbers of one kept result that decide its outcome, as JSON text of each (so that
    NaN and -inf compare equal to themselves and floats compare bit for bit)."""
    js = row.get("json") or {}
    hist = [{k: h.get(k) for k in HISTORY_KEYS} for h in js.get("history", []) or [] if isinstance(h, dict)]
    rounds = [[{k: s.get(k) for k in SUSPECT_KEYS} for s in (rd or {}).get("suspects", []) or [] if isinstance(s, dict)]
              for rd in js.get("rounds", []) or []]
    sus = [{k: s.get(k) for k in SUSPECT_KEYS} for s in js.get("suspects", []) or [] if isinstance(s, dict)]
    oc = {k: v for k, v in (row.get("outcome") or {}).items() if k != "conclusion"}
    return {"nominal_error": json.dumps(js.get("nominal_error")), "history": json.dumps(hist, sort_keys=True),
            "rounds": json.dumps(rounds, sort_keys=True), "suspects": json.dumps(sus, sort_keys=True),
            "outcome": json.dumps(oc, sort_keys=True, default=str)}


def _key(row: Dict[str, Any]) -> Tuple[str, str]:
    return Path(str(row["run"])).name, json.dumps(row.get("truth"), sort_keys=True)


def machine_note(old: Dict[str, Any], new: Dict[str, Any]) -> str:
    """Why two results may differ in the last bits without a change of method: "" if both
    were made with the same recorded CPU code paths (and, where both record them, the same
    library versions)."""
    a, b = old.get("machine"), new.get("machine")
    if a is None or b is None:
        return "machine not recorded"
    notes = [] if a == b else [f"different machines ({a} vs {b})"]
    la, lb = old.get("libraries"), new.get("libraries")
    if la is not None and lb is not None and la != lb:
        notes.append("different libraries (" + ", ".join(f"{k} {la.get(k)} vs {lb.get(k)}" for k in sorted(set(la) | set(lb))
                                                         if la.get(k) != lb.get(k)) + ")")
    return "; ".join(notes)


def compare_versions(old: Sequence[str], new: Sequence[str]) -> Tuple[int, List[Tuple[str, List[str]]], List[str]]:
    """``(pairs compared, [(run, [fields that differ, then a machine note if any])], [new
    runs with no old result of the same name and truth])``."""
    olds = {_key(r): r for r in B.cached_rows(old)}
    n, diffs, unpaired = 0, [], []
    for r in B.cached_rows(new):
        o = olds.get(_key(r))
        if o is None:
            unpaired.append(Path(str(r["run"])).name)
            continue
        n += 1
        a, b = fingerprint(o), fingerprint(r)
        bad = [k for k in a if a[k] != b[k]]
        if bad:
            note = machine_note(o, r)
            bad += [f"({note})"] if note else []
            diffs.append((Path(str(r["run"])).name, bad))
    return n, diffs, unpaired


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", nargs="+", required=True, help="result folders of the old version")
    ap.add_argument("--new", nargs="+", required=True, help="result folders of the same runs on the new version")
    a = ap.parse_args(argv)
    n, diffs, unpaired = compare_versions(a.old, a.new)
    for name, bad in diffs:
        print(f"differs: {name}: {', '.join(bad)}")
    if unpaired:
        print(f"not compared (no old result of the same run and truth): {', '.join(unpaired)}")
    print(f"{n - len(diffs)} of {n} run(s) give the same outcome, bit for bit in every number the classification reads")
    return 1 if diffs or n == 0 else 0


if __name__ == "__main__":
    sys.exit(main())

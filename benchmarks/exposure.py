"""Which kept diagnosis results a change to one effect's rule could reach.

Before the diagnosis code changes, the results already kept (``benchmarks/results/*``,
or ``--out`` folders of ``bench_diagnosis_families.py``) say which runs the change can
touch: a rule that only acts on a significant ``actuator_saturation`` suspect cannot move
a run in which no round ever had one. This script scans every round's suspects of every
result and lists the runs where an effect was significant (or, with ``--tested``, fitted
at all; with ``--message``, where a suspect's message contains a text), with the round,
the run's truth and whether the run was counted right. Those are the runs to rerun on the
new code; the others keep their outcome by construction.

    python benchmarks/exposure.py benchmarks/results/fam_* --effect actuator_saturation
    python benchmarks/exposure.py benchmarks/results/fam_*_06debd8 --message "not tested"
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Dict, Iterator, List, Optional, Sequence, Tuple

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_diagnosis_families as B  # noqa: E402


def suspects_by_round(js: Optional[Dict[str, Any]]) -> Iterator[Tuple[int, Dict[str, Any]]]:
    """``(round, suspect)`` for every suspect of every round of one ``popup diagnose --json``
    output (round 1 is the first; an output without ``rounds`` gives its ``suspects`` as
    round 1)."""
    if not isinstance(js, dict):
        return
    rounds = js.get("rounds")
    if not isinstance(rounds, list) or not rounds:
        rounds = [{"suspects": js.get("suspects") or []}]
    for k, rd in enumerate(rounds, start=1):
        for s in (rd or {}).get("suspects") or []:
            if isinstance(s, dict):
                yield k, s


def exposed(row: Dict[str, Any], effect: Optional[str], *, tested: bool = False,
            message: Optional[str] = None) -> List[int]:
    """The rounds of one kept result in which ``effect`` (any effect if ``None``) was
    significant (``tested``: tested at all) and, with ``message``, whose suspect's message
    contains that text (case-insensitive)."""
    hits = []
    for k, s in suspects_by_round(row.get("json")):
        if effect is not None and s.get("effect") != effect:
            continue
        if tested:
            if s.get("tested") is False:
                continue
        elif not s.get("significant"):
            continue
        if message is not None and message.lower() not in str(s.get("message") or "").lower():
            continue
        hits.append(k)
    return sorted(set(hits))


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="+", help="folders holding results/*.json or results/*.json.gz")
    ap.add_argument("--effect", help="the effect whose rule changes (default: any effect)")
    ap.add_argument("--tested", action="store_true", help="count rounds where the effect was fitted at all, not only significant")
    ap.add_argument("--message", help="only suspects whose message contains this text")
    ap.add_argument("--version", help="only results of this diagnosis version (12 hex)")
    a = ap.parse_args(argv)
    if a.effect is not None and a.effect not in B.F.LIBRARY:
        ap.error(f"--effect: unknown effect {a.effect!r} (library: {', '.join(B.F.LIBRARY)})")
    if a.effect is None and a.message is None and not a.tested:
        ap.error("give --effect, --message or --tested: every result would be listed")
    rows = B.cached_rows(a.dirs)
    memo: Dict[str, Optional[str]] = {}

    def version(r: Dict[str, Any]) -> Optional[str]:
        c = str(r.get("commit") or "unrecorded")
        if c not in memo:
            memo[c] = B.diagnosis_version(c)
        return memo[c]

    scanned, hits = 0, []
    for r in rows:
        if a.version is not None and version(r) != a.version:
            continue
        scanned += 1
        ks = exposed(r, a.effect, tested=a.tested, message=a.message)
        if ks:
            hits.append((r, ks))
    what = f"{a.effect or 'any effect'} {'tested' if a.tested else 'significant'}" + (f", message ~ {a.message!r}" if a.message else "")
    print(f"{len(hits)} of {scanned} kept result(s) have {what} in some round\n")
    if hits:
        print(f"{'run':<44} {'folder':<24} {'version':<13} {'hidden':<34} {'rounds':<8} outcome")
        for r, ks in sorted(hits, key=lambda x: (Path(x[0]["run"]).parent.name, Path(x[0]["run"]).name)):
            o = r["outcome"]
            verdict = "failed" if o.get("ok") is None else ("ok" if o["ok"] else "wrong")
            print(f"{Path(r['run']).name:<44} {Path(r['run']).parent.name:<24} {str(version(r)):<13} "
                  f"{'+'.join(r['truth'].get('hidden') or []) or '-':<34} {','.join(map(str, ks)):<8} {verdict}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

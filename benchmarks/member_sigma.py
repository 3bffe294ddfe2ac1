"""Each effect's own size beside the others (``families.member_size``) for archived pair
results made before the generator recorded it (session 65), kept in
``benchmarks/results/member_sigma.json`` for ``--pool``::

    python3 benchmarks/member_sigma.py benchmarks/results/fam_*

Each pair result's run spec is drawn again from its family's seed and index; a spec that
differs from the stored truth (a generator changed since) is skipped and listed, and its
pair stays counted under (c). Entries already in the file are kept.
"""

from __future__ import annotations

import argparse
import gzip
import json
import sys
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))
import families as F  # noqa: E402

#: Where the sizes of archived pairs are kept (read by ``bench_diagnosis_families.cached_rows``).
TABLE = Path(__file__).resolve().parent / "results" / "member_sigma.json"

#: Truth keys the generator fills in while it makes a run (not part of the drawn spec).
MADE = ("effect_sigma", "member_sigma", "near_target_sigma")


def key(truth: Dict[str, Any]) -> str:
    """The run a truth describes: ``engine/family/seed/index``."""
    return f"{truth['engine']}/{truth['family']}/{int(truth['seed'])}/{int(truth['index'])}"


def load(path: Optional[Path] = None) -> Dict[str, Dict[str, float]]:
    """The table at ``path`` (default :data:`TABLE`; empty when there is none)."""
    path = Path(path) if path is not None else TABLE
    return json.loads(path.read_text()) if path.is_file() else {}


def spec_of(truth: Dict[str, Any]) -> Optional[F.RunSpec]:
    """The run spec drawn again from ``truth``'s family, seed and index, or ``None`` where it
    differs from ``truth`` (apart from what :func:`families.make_run` fills in)."""
    i = int(truth["index"])
    sp = F.family_specs(str(truth["family"]), str(truth["engine"]), i + 1, int(truth["seed"]), biases=bool(truth.get("biases")))[i]
    now = F.inf_to_str(sp.truth())
    strip = lambda d: json.dumps({k: v for k, v in d.items() if k not in MADE}, sort_keys=True, default=str)  # noqa: E731
    return sp if strip(now) == strip(truth) else None


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="+", help="result folders (DIR/results/*.json.gz)")
    ap.add_argument("--table", default=str(TABLE), help=f"the table to update (default {TABLE})")
    a = ap.parse_args(argv)
    table = load(Path(a.table))
    added, skipped = 0, []
    for d in a.dirs:
        for f in sorted([*Path(d).glob("results/*.json"), *Path(d).glob("results/*.json.gz")]):
            truth = json.loads(gzip.decompress(f.read_bytes()) if f.suffix == ".gz" else f.read_text())["truth"]
            if truth.get("kind") != "pair" or truth.get("member_sigma") or key(truth) in table:
                continue
            sp = spec_of(truth)
            if sp is None:
                skipped.append(str(f))
                continue
            table[key(truth)] = F.member_size(sp)
            added += 1
            print(f"{key(truth)}: {table[key(truth)]}", flush=True)
            Path(a.table).write_text(json.dumps(dict(sorted(table.items())), indent=1) + "\n")
    print(f"{added} added, {len(table)} in {a.table}")
    for s in skipped:
        print(f"skipped (the spec drawn now differs from the stored truth): {s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Which kept family results the session-43 change of the share rule can reach.

For an effect that acts on some channels only in encoder replay
(``popup.effects.OUTPUT_ONLY_IN_REPLAY``: friction and the torque clamp on ``tau*``, a sensor
group's delay on its channels) the share rule (``popup.diagnosis.rules.MIN_EXPLAINED``) now
sets aside the isolated spikes it leaves on those channels, and judges it on them also when
it is refitted jointly with the effects already added (net of what that refit adds
elsewhere; before, a joint refit was judged on the whole error): session 43,
``docs/effects.md`` step 5. Either can only turn a candidate that was held back into a
significant one, and only one that passed the likelihood and held-out tests and either had
isolated spikes on its channels or was a joint refit. This lists every kept result
(``benchmarks/results/*/results/*.json.gz``, or the folders given) whose rounds hold such a
candidate, with the spikes its final residual has on each channel (the rounds' own residuals
are not kept): the runs a rerun on the new code has to check. Prints only; asserts nothing.

    python benchmarks/share_exposure.py                       # every kept result
    python benchmarks/share_exposure.py benchmarks/results/fam_mp612
"""

from __future__ import annotations

import argparse
import glob
import gzip
import json
import os
import sys
from typing import Any, Dict, List, Tuple

import popup.effects as fx

HERE = os.path.dirname(os.path.abspath(__file__))


def acts_prefixes() -> Dict[str, Tuple[str, ...]]:
    """Per effect, the channel prefixes its parameters act on only in replay (the core's table)."""
    out: Dict[str, Tuple[str, ...]] = {}
    for effect, _, prefix in fx.OUTPUT_ONLY_IN_REPLAY:
        out[effect] = tuple(sorted(set(out.get(effect, ())) | {prefix}))
    return out


def held_back(result: Dict[str, Any], acts: Dict[str, Tuple[str, ...]]) -> List[Tuple[int, str, float, float, str]]:
    """(round, effect, score, share of the whole error, why) of each acts-only candidate the
    rounds of ``result`` held back although it passed the likelihood and held-out tests, with
    isolated spikes on a channel it acts on or refitted jointly with added effects."""
    js = result.get("json") or {}
    spiky = {c for c, v in (js.get("channels") or {}).items() if v.get("spikes", 0)}
    out = []
    for k, rnd in enumerate(js.get("rounds") or [], start=1):
        for s in rnd.get("suspects", []):
            pre = acts.get(s.get("effect"))
            v = s.get("validation") or {}
            if not (pre and s.get("tested") and not s.get("significant") and (s.get("score") or -1.0) > 10.0
                    and (v.get("lr") or -1.0) > 0 and v.get("error_after", float("inf")) < v.get("error_before", 0.0)):
                continue
            why = [w for w, hit in (("spikes", any(c.startswith(pre) for c in spiky)),
                                    ("joint refit with " + "+".join(sorted(s.get("refitted") or {})), bool(s.get("refitted")))) if hit]
            if why:
                out.append((k, s["effect"], float(s["score"]), float(s.get("explained_share", 0.0)), ", ".join(why)))
    return out


def main(argv: List[str]) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="*", help="result folders (default: every one under benchmarks/results)")
    a = ap.parse_args(argv)
    folders = a.folders or sorted(glob.glob(os.path.join(HERE, "results", "fam_*")))
    acts = acts_prefixes()
    n = 0
    hits = []
    for folder in folders:
        for f in sorted(glob.glob(os.path.join(folder, "results", "*.json*"))):
            with (gzip.open(f, "rt") if f.endswith(".gz") else open(f)) as fh:
                r = json.load(fh)
            n += 1
            h = held_back(r, acts)
            if h:
                spikes = {c: v["spikes"] for c, v in ((r.get("json") or {}).get("channels") or {}).items() if v.get("spikes", 0)}
                hits.append((r.get("commit"), os.path.basename(folder), os.path.basename(f).split(".")[0], (r.get("outcome") or {}).get("ok"), h, spikes))
    print(f"{n} kept results read; {len(hits)} with an acts-only candidate held back by the share beside spikes on its channels "
          "or in a joint refit")
    for commit, folder, name, ok, h, spikes in hits:
        cands = ", ".join(f"round {k} {e} (score {s:.0f}, {100 * sh:.0f} % of the whole; {why})" for k, e, s, sh, why in h)
        print(f"  {commit}  {folder}/{name}  ok={ok}: {cands}; spikes {spikes}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

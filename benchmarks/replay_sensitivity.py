"""How sensitive is the replay of the truth's own laws on a family run: the error of popup's
laws at the true parameters, and how far its prediction moves when a true parameter moves by
a little, the step shrinks, or one hidden effect is taken out.

A sample-by-sample replay is only as good as its prediction is stable: where a gear with
play rattles (a link side and its payload bouncing between soft flanks, MuJoCo pair 620 of
session 44), a 0.1 % wider gap moves popup's own prediction by tens of noise units, and an
effect whose signal is smaller than that cannot be told from the replay's drift, whatever
the criterion. Printed, per run, in noise units of the run (the same measure as the
diagnosis's systematic error, ``sqrt(mean_c r_c²)`` of the change between two predictions,
and the torque channels' own): the truth's error, the nominal model's, then each change.
The truth's laws are those :func:`bench_diagnosis_families.popup_law` maps (on MuJoCo runs:
friction, backlash, a payload, delays). Prints only; asserts nothing.

    python benchmarks/replay_sensitivity.py out/fam_mp620/mujoco-pairs-000
    python benchmarks/replay_sensitivity.py RUN [RUN ...] --rel 1e-3
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import bench_diagnosis_families as B  # noqa: E402
import families as F  # noqa: E402


def _prediction(prob: Any, model: Any, engine: str) -> Tuple[Any, np.ndarray]:
    """``model`` replayed on ``prob``'s run (its unseen motion fitted on a run of the engine
    ``"mujoco"``, as the diagnosis does), at half the step while the step check asks for it."""
    from popup.exceptions import StepTooLargeError
    from popup.unseen import fit_unseen_motion

    for _ in range(6):
        try:
            p = prob.with_model(model)
            p = fit_unseen_motion(p) if engine == "mujoco" else p
            return p, p.nominal_simulation()
        except StepTooLargeError:
            model = model.with_dt(0.5 * model.dt)
    raise RuntimeError("no stable step within 6 halvings")


def _moved(p: Any, a: np.ndarray, b: np.ndarray) -> Tuple[float, Dict[str, float]]:
    """How far prediction ``b`` is from ``a`` in noise units: overall, and per torque channel."""
    z = (np.asarray(b) - np.asarray(a)) / p.sigma
    ms = np.nanmean(z[p.used] ** 2, axis=0)
    return float(math.sqrt(np.nanmean(ms))), {c: float(math.sqrt(v)) for c, v in zip(p.channels, ms) if c.startswith("tau")}


def sensitivity(path: str, rel: float = 1e-3) -> Optional[List[Tuple[str, float, Dict[str, float]]]]:
    """(what, noise units, per torque channel) for the run at ``path``; ``None`` where its
    truth has an effect popup's laws do not map."""
    import popup
    from popup.problem import ReplayProblem

    truth = F.read_truth(path)
    eng = truth.get("engine")
    laws = {n: B.popup_law(n, p, eng) for n, p in (truth.get("effects") or {}).items()}
    if any(v is None for v in laws.values()):
        return None
    run = popup.read_run(path)
    nominal = run.model()
    base = ReplayProblem(nominal, run)

    def model_of(lw: Dict[str, Dict[str, Any]], dt: Optional[float] = None) -> Any:
        m = nominal
        for n, p in lw.items():
            m = m.with_effect(n, **p)
        return m if dt is None else m.with_dt(dt)

    p0, s0 = _prediction(base, model_of(laws), eng)
    out = [("truth's error", p0.error(p0.residuals(s0))[0], {}), ("nominal's error", base.error()[0], {})]
    pn, sn = _prediction(base, model_of(laws, 0.25 * p0.model.dt), eng)
    out.append((f"step / 4 ({p0.model.dt:.3g} s → {pn.model.dt:.3g} s)", *_moved(p0, s0, sn)))
    for n in laws:
        _, s = _prediction(base, model_of({k: v for k, v in laws.items() if k != n}, p0.model.dt), eng)
        out.append((f"without {n}", *_moved(p0, s0, s)))
    for n, params in laws.items():
        for k, v in params.items():
            arr = np.atleast_1d(np.asarray(v, dtype=float))
            if not np.all(np.isfinite(arr)) or not np.any(arr != 0) or k in ("held", "restitution"):
                continue
            moved = {**laws, n: {**params, k: (arr * (1.0 + rel)).tolist() if np.ndim(v) else float(v) * (1.0 + rel)}}
            _, s = _prediction(base, model_of(moved, p0.model.dt), eng)
            out.append((f"{n}.{k} × (1 {rel:+g})", *_moved(p0, s0, s)))
    return out


def main(argv: Optional[List[str]] = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="family run folders (experiment.toml with the truth in its description)")
    ap.add_argument("--rel", type=float, default=1e-3, help="relative change of each true parameter (default 1e-3)")
    a = ap.parse_args(argv)
    for path in a.runs:
        rows = sensitivity(path, a.rel)
        print(f"\n{path}")
        if rows is None:
            print("  its truth has an effect written in the engine's own terms: not mapped to popup's laws")
            continue
        for what, v, tau in rows:
            print(f"  {what:<44} {v:10.3g}   " + "  ".join(f"{c} {x:.3g}" for c, x in tau.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

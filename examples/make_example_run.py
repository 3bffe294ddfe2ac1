"""Regenerate the bundled example run ``examples/data/lab_run`` (committed; CSV, so that it
reads after a plain ``pip install`` without the optional pyarrow).

A synthetic lab experiment of ``popup-lab`` (8 s at 250 Hz: moves with ring-down holds,
velocity reversals, a chirp) in which the "real arm" has motoreducer friction and a
payload 0.3 kg heavier than declared, with sensor noise and encoder quantisation
(:mod:`popup.synth`). The experiment file declares only what the lab knew; the truth
is in its description.

    python examples/make_example_run.py
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import popup

OUT = Path(__file__).resolve().parent / "data" / "lab_run"
TRUTH = {
    "joint_friction": {"tau_c": [1.2, 1.8, 0.7], "b": [0.25, 0.2, 0.1]},
    "payload_mass": {"delta_kg": 0.3},
}


def main() -> Path:
    t, q = popup.synth.lab_trajectory(8.0, rate=250.0, seed=7)
    truth = popup.Model("popup-lab", payload_kg=1.0).with_effects(TRUTH)
    with tempfile.TemporaryDirectory() as tmp:
        popup.synth.measured_run(truth, t, q, tmp, seed=7, description="bundled example:")
        OUT.mkdir(parents=True, exist_ok=True)
        shutil.copy(Path(tmp) / "experiment.toml", OUT / "experiment.toml")
        for old in ("measurements.csv", "measurements.parquet"):
            (OUT / old).unlink(missing_ok=True)
        shutil.copy(Path(tmp) / "measurements.csv", OUT / "measurements.csv")
    run = popup.read_run(OUT)
    print(f"wrote {OUT} ({len(run)} rows, columns {', '.join(run.columns)})")
    return OUT


if __name__ == "__main__":
    main()

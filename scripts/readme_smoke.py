"""The README's Python steps, run against an installed popup (a plain `pip install` of the
wheel, no optional dependencies) by scripts/check_pythons.sh on the oldest and newest
Python on the machine. Exits non-zero, naming the step, at the first failure."""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    import popup

    print(f"popup {popup.__version__} on Python {sys.version.split()[0]} from {Path(popup.__file__).parent}")
    steps = []

    def step(name):
        def deco(fn):
            steps.append((name, fn))
            return fn

        return deco

    state = {}

    @step("read the bundled run")
    def _():
        state["run"] = popup.read_run(ROOT / "examples" / "data" / "lab_run")
        state["model"] = state["run"].model()

    @step("compare")
    def _():
        cmp = popup.compare.compare(state["model"], state["run"])
        assert cmp.overall["error"] > 1.0 and len(cmp.to_pandas()) == 12

    @step("diagnose (payload, friction) and add the best")
    def _():
        d = popup.diagnose(state["model"], state["run"], effects=["payload_mass", "joint_friction"])
        assert d.best is not None
        m2 = d.best.apply(state["model"])
        err, _ = popup.diagnosis.model_error(m2, state["run"], problem=d.problem)
        assert err < d.nominal_error

    @step("fit_params")
    def _():
        f = popup.fit_params(state["model"], state["run"], ["payload_mass.delta_kg"], seeds=False, starts=1, max_iter=10)
        assert abs(f.params["payload_mass.delta_kg[0]"] - 0.3) < 0.1, f

    @step("Model, statics, replay, rollout")
    def _():
        model = popup.Model("popup-lab", payload_kg=2.0, pressure_pa=(30e3, 30e3))
        model.rest_state((0.0, 0.6, -0.3))
        model.locked_modes((0.0, 0.6, -0.3))
        t = np.arange(0, 1, 0.002)
        q = np.stack([0 * t, 0.6 * np.minimum(t / 2, 1), -0.3 * np.minimum(t / 2, 1)], axis=1)
        res = model.replay(t, q, sample_rate=500)
        res.to_pandas()
        batch = model.rollout(payload_kg=np.linspace(0, 2.5, 4), encoder_t=t, encoder_q=q, threads=0)
        assert batch.ee.shape == (4, res.ee.shape[0], 3)

    @step("arm files and rigid kinematics")
    def _():
        with tempfile.TemporaryDirectory() as tmp:
            popup.Arm.builtin("popup-lab").save(str(Path(tmp) / "my-arm.toml"))
            popup.Model(str(Path(tmp) / "my-arm.toml"))
        popup.Model("popup-lab").rigid("as_built").ik([-0.8, -0.8, 0.9])

    @step("scenario check")
    def _():
        popup.Scenario.read(ROOT / "examples" / "scenarios" / "pick_and_place.toml")

    for name, fn in steps:
        try:
            fn()
        except Exception as e:  # noqa: BLE001 - report the step and fail
            print(f"FAILED: {name}: {type(e).__name__}: {e}", file=sys.stderr)
            return 1
        print(f"ok: {name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

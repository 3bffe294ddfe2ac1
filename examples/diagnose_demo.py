"""The main job: compare → diagnose → add the effect → watch the error fall, on the
bundled example run (``examples/data/lab_run``, a lab experiment with effects the
nominal model lacks). Writes ``out/report.html`` (self-contained) and ``out/report.json``.

    python examples/diagnose_demo.py
"""

from __future__ import annotations

import time
from pathlib import Path

import popup

HERE = Path(__file__).resolve().parent
OUT = HERE.parent / "out"


def main() -> None:
    t0 = time.perf_counter()
    run = popup.read_run(HERE / "data" / "lab_run")
    model = run.model()  # the nominal model of the declared experiment
    print(f"run: {run.source.name}: {len(run)} samples, {run.time[-1]:.1f} s, payload {run.payload_kg} kg declared")

    cmp = popup.compare.compare(model, run)
    print(f"\n1. compare the nominal model (free-run encoder replay): mean fit {cmp.overall['fit_pct']:.1f} %")
    print(f"   systematic error {cmp.overall['error']:.3g} noise units (0 = at the noise floor)")
    worst = cmp.metrics.sort_values("noise_multiple", ascending=False).head(3)
    for ch, row in worst.iterrows():
        print(f"   worst channel {ch:<8} {row['noise_multiple']:7.1f}× its noise (σ = {row['noise_std']:.3g} {row['unit']})  NRMSE {row['nrmse']:.3f}  fit {row['nrmse_fit_pct']:6.1f} %")

    # the loop runs the diagnosis of round 1 too: step 2 shows it, step 4 the whole loop
    h = popup.improve(model, run)
    d = h.diagnoses[0]
    print(f"\n2. diagnose: every effect of the library fitted, confirmed on held-out samples and ranked ({d.seconds:.1f} s, {d.n_rollouts} rollouts)")
    print(d.to_pandas()[["effect", "significant", "score", "error_after", "explained", "validation_after"]].to_string())

    best = d.best
    if best is not None:
        better = best.apply(model)
        err, _ = popup.diagnosis.model_error(better, run, problem=d.problem)
        print(f"\n3. add the top suspect: model.with_effect({best.effect!r}, ...)")
        print(f"   fitted: {best.params_text()}")
        print(f"   systematic error {d.nominal_error:.4g} -> {err:.4g} noise units (predicted {best.error_after:.4g})")

    print("\n4. the loop until nothing significant is left:")
    for s in h.steps:
        print(f"   {' + '.join(s.effects) or 'nominal':<36} systematic error {s.error:.4g} noise units")
    print(f"   {h.conclusion}")
    print(f"   (the run's truth: {run.description.split('hidden effects: ')[-1]})")

    OUT.mkdir(exist_ok=True)
    html = popup.report.write_html(h, OUT / "report.html", title="popup: diagnosis of the bundled lab run")
    js = popup.report.write_json(h, OUT / "report.json")
    print(f"\nreport: {html}  numbers: {js}  ({time.perf_counter() - t0:.0f} s in all)")


if __name__ == "__main__":
    main()

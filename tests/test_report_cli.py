"""`popup diagnose` (CLI, JSON contract) and the self-contained HTML report, on the
bundled example run."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import popup

RUN = Path(__file__).resolve().parents[1] / "examples" / "data" / "lab_run"
# the bundled run's two effects and a third candidate (backlash, with its compliant-flank
# variant at a small step, doubled the fixture's time for the same answer: in benchmarks/)
FAST = "payload_mass,joint_friction,sensor_delay"


@pytest.fixture(scope="module")
def cli_json(tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "report.html"
    r = subprocess.run(
        [sys.executable, "-m", "popup", "diagnose", str(RUN), "--json", "--effects", FAST, "--report", str(out)],
        capture_output=True, text=True, timeout=900,
    )
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout), out


def test_json_contract(cli_json):
    d, _ = cli_json
    assert d["run"] == str(RUN)
    assert isinstance(d["nominal_error"], float) and d["nominal_error"] > 0
    assert "noise" in d["error_definition"]
    assert d["complete"] is True and "error" not in d
    names = [s["effect"] for s in d["suspects"]]
    assert sorted(names) == sorted(FAST.split(","))
    for s in d["suspects"]:
        assert set(s) >= {"effect", "significant", "score", "params", "ci95", "error_after", "tested", "message"}
        assert s["tested"] is True
    # the noise floor of every compared channel, close to the generator's (make_example_run.py)
    assert d["noise"]["tau1"] == pytest.approx(0.05, rel=0.2) and d["noise"]["imu2_az"] == pytest.approx(0.02, rel=0.2)
    assert set(d["channels"]) == set(d["noise"])
    # the conclusion tells the history in order: the payload first, with its value
    # (0.29x, 0.30x, or 0.3 itself at four significant digits)
    assert re.match(r"Added payload_mass \(delta_kg=0\.(29\d*|3|30\d*)±", d["conclusion"]), d["conclusion"]
    assert d["conclusion"].index("payload_mass") < d["conclusion"].index("joint_friction")
    # the bundled run hides a heavier payload and friction: both are found, in two rounds
    hist = d["history"]
    assert hist[0] == {**hist[0], "effects": [], "error": d["nominal_error"]}
    assert [h["effects"] for h in hist] == [[], ["payload_mass"], ["payload_mass", "joint_friction"]]
    assert hist[1]["error"] < 0.5 * hist[0]["error"] and hist[2]["error"] < hist[1]["error"]
    assert d["suspects"][0]["effect"] == "payload_mass" and d["suspects"][0]["significant"]
    assert abs(d["suspects"][0]["params"]["delta_kg"][0] - 0.3) < 0.02


def test_html_report_is_self_contained(cli_json):
    _, path = cli_json
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    assert len(re.findall(r'src="data:image/png;base64,', text)) >= 5
    assert not re.search(r'(src|href)="(http|/|\.)', text), "external reference in the report"
    data = json.loads(re.search(r"<script type='application/json' id='popup-data'>(.*?)</script>", text, re.S).group(1))
    assert [h["effects"] for h in data["history"]][-1] == ["payload_mass", "joint_friction"]


def test_text_output_and_bad_run(tmp_path):
    r = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(tmp_path / "nope")], capture_output=True, text=True)
    assert r.returncode == 2
    assert "popup diagnose: error" in r.stderr and "nope" in r.stderr
    r = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(RUN), "--effects", "payload_mass", "--max-rounds", "1"],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    assert "payload_mass" in r.stdout and "error history" in r.stdout
    r = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(RUN), "--effects", "friction"], capture_output=True, text=True)
    assert r.returncode == 2 and "must be one of" in r.stderr


def test_history_and_diagnosis_objects_plot_and_tabulate():
    run = popup.read_run(RUN)
    h = popup.improve(run.model(), run, effects=["payload_mass"], max_rounds=1)
    assert h.effects == ["payload_mass"]
    df = h.to_pandas()
    assert list(df["effects"]) == ["nominal", "payload_mass"]
    assert list(df["round"]) == [0, 1] and list(df["change"]) == ["", "+ payload_mass"]
    assert df["error"].iloc[1] < df["error"].iloc[0]
    ax = h.plot()
    assert len(ax.lines) >= 2
    ax = h.diagnoses[0].plot()
    assert ax.patches
    assert h.model.effects["payload_mass"]["delta_kg"][0] == pytest.approx(0.3, abs=0.02)


def test_history_names_swaps_removals_and_a_law_set_back():
    """The history's table and conclusion say what each step of the loop changed."""
    from popup.diagnosis import History, HistoryStep
    from popup.diagnosis.conclusion import conclude as _conclude

    ch = {"tau1": 1.0}
    steps = [
        HistoryStep([], {}, 90.0, {"tau1": 90.0}),
        HistoryStep(["backlash"], {"backlash": {"gap": [0.01, 0.0, 0.0]}}, 30.0, ch, round=1),
        HistoryStep(["backlash", "payload_mass"], {"payload_mass": {"delta_kg": [0.1]}}, 9.0, ch, round=2),
        HistoryStep(["air_drag", "payload_mass"], {"air_drag": {"cd": [7.0]}, "payload_mass": {"delta_kg": [0.12]}}, 2.0, ch, round=2,
                    removed="backlash", swapped_in="air_drag"),
        HistoryStep(["air_drag", "payload_mass", "torsion"], {"torsion": {"k_t": [225.0, 240.0]}}, 1.0, ch, round=3, law_reset="payload_mass"),
        HistoryStep(["payload_mass", "torsion"], {}, 1.0, ch, round=3, removed="air_drag"),
    ]
    notes = ["swap of payload_mass (candidates torsion): torsion not kept (BIC gain -3.1 (threshold 10), held-out error 2 → 2.1)"]
    h = History(steps, [], "", notes=notes)
    df = h.to_pandas()
    assert list(df["round"]) == [0, 1, 2, 2, 3, 3]
    assert list(df["change"]) == ["", "+ backlash", "+ payload_mass", "backlash → air_drag", "+ torsion (payload_mass at its base law)", "− air_drag"]
    text = _conclude(h, 4)
    assert "replaced backlash by air_drag (cd=7): backlash stood in for it; the error fell from 9 to 2 noise units" in text
    assert "added torsion (k_t=225/240), with payload_mass back at its base law (its richer variant had stood in for torsion)" in text
    assert "removed air_drag again" in text
    js = h.to_dict()["history"]
    assert [x["round"] for x in js] == [0, 1, 2, 2, 3, 3]
    assert js[3]["swapped_in"] == "air_drag" and js[3]["removed"] == "backlash" and js[4]["law_reset"] == "payload_mass"
    assert h.to_dict()["notes"] == notes  # what the swap tried and why it was not kept
    from popup.report import to_html

    assert "<li>swap of payload_mass (candidates torsion): torsion not kept (BIC gain -3.1" in to_html(h)


def test_history_names_a_pair_swapped_in_for_one_effect():
    """The pair step's history step (one effect replaced by two, ``swapped_in`` = "a + b")
    in the table, the conclusion (each member's values) and the JSON."""
    from popup.diagnosis import History, HistoryStep
    from popup.diagnosis.conclusion import conclude as _conclude

    ch = {"tau1": 1.0}
    steps = [
        HistoryStep([], {}, 2730.0, {"tau1": 2730.0}),
        HistoryStep(["backlash"], {"backlash": {"gap": [0.001, 0.0, 0.004]}}, 170.0, ch, round=1),
        HistoryStep(["air_drag", "payload_mass"], {"air_drag": {"cd": [7.49]}, "payload_mass": {"delta_kg": [0.2503]}}, 0.142, ch, round=2,
                    removed="backlash", swapped_in="air_drag + payload_mass"),
    ]
    h = History(steps, [], "")
    assert list(h.to_pandas()["change"]) == ["", "+ backlash", "backlash → air_drag + payload_mass"]
    text = _conclude(h, 4)
    assert ("replaced backlash by air_drag + payload_mass (air_drag: cd=7.49; payload_mass: delta_kg=0.2503): backlash stood in for them; "
            "the error fell from 170 to 0.142 noise units") in text, text
    js = h.to_dict()["history"][-1]
    assert (js["removed"], js["swapped_in"], js["effects"], js["round"]) == ("backlash", "air_drag + payload_mass", ["air_drag", "payload_mass"], 2)


def test_rollout_count_is_the_number_of_simulations_run(monkeypatch):
    run = popup.read_run(RUN)
    model = run.model()
    counted = []
    orig = popup.Model.rollout

    def counting(self, **kw):
        res = orig(self, **kw)
        counted.append(len(res))
        return res

    monkeypatch.setattr(popup.Model, "rollout", counting)  # Model.replay is a rollout of one
    # every rollout of the nominal replay, the fits and the candidates' checks is counted
    d = popup.diagnose(model, run, effects=["payload_mass", "sensor_delay"])
    assert d.n_rollouts == sum(counted)
    assert [s.n_rollouts for s in d.suspects] and all(s.n_rollouts > 2 for s in d.suspects)


def test_a_run_at_its_floor_is_answered_without_fitting_and_says_why(tmp_path):
    """A nominal run (popup's engine, 12-bit encoders) is at its floor: `popup diagnose`
    tries nothing, says so per effect and in the conclusion, and exits 0 complete; the
    report's table shows the encoder floor; `--rank-at-floor` fits the candidates anyway."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    import families as F

    sp = F.family_specs("nominal", "popup", 1, 3, duration=4.0, channels="full", encoder_bits=12, noise_scale=1.0, style="lab")[0]
    path, _ = F.make_run(sp, tmp_path)
    html_out = tmp_path / "r.html"
    r = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(path), "--json", "--report", str(html_out)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["complete"] is True and d["history"][-1]["effects"] == []
    assert d["rounds"][0]["model_at_floor"] is True
    assert len(d["suspects"]) == len(popup.effects.EFFECT_NAMES)
    assert all(s["tested"] is False and s["message"].startswith("not tried: the model is at its floor") for s in d["suspects"])
    assert "floor" in d["conclusion"] and "incomplete" not in d["conclusion"]
    assert all(v["encoder_floor"] >= 1.0 for v in d["channels"].values())
    assert "encoder floor" in html_out.read_text()
    r2 = subprocess.run([sys.executable, "-m", "popup", "diagnose", str(path), "--json", "--rank-at-floor", "--effects", "payload_mass"],
                        capture_output=True, text=True, timeout=600)
    assert r2.returncode == 0, r2.stderr
    d2 = json.loads(r2.stdout)
    assert [s["tested"] for s in d2["suspects"]] == [True] and d2["history"][-1]["effects"] == []


def test_history_names_a_pair_added_from_none():
    """The pair-from-none step (nothing significant in round 1, two effects added together
    in round 1) in the table, the conclusion (each member's values, that neither was
    significant alone) and the JSON."""
    from popup.diagnosis import History, HistoryStep
    from popup.diagnosis.conclusion import conclude as _conclude

    ch = {"tau1": 1.0}
    steps = [
        HistoryStep([], {}, 8.39, {"tau1": 12.0}),
        HistoryStep(["sensor_delay", "higher_bending_modes"], {"sensor_delay": {"torque": [0.0128]}, "higher_bending_modes": {"k_scale": [1.3, 1.3]}},
                    0.9, ch, round=1),
    ]
    h = History(steps, [], "")
    assert list(h.to_pandas()["change"]) == ["", "+ sensor_delay + higher_bending_modes"]
    text = _conclude(h, 4)
    assert ("Added the pair sensor_delay and higher_bending_modes (sensor_delay: torque=0.0128; higher_bending_modes: k_scale=1.3/1.3), "
            "neither of which was significant alone: the systematic error fell from 8.39 to 0.9 noise units") in text, text
    js = h.to_dict()["history"][-1]
    assert (js["effects"], js["round"], js["removed"], js["swapped_in"]) == (["sensor_delay", "higher_bending_modes"], 1, "", "")


def test_a_runner_up_within_the_threshold_is_said_to_be_indistinguishable():
    """Two significant candidates whose scores (BIC gains over the same nominal) differ by
    less than the threshold: the round's and the history's conclusions say the run cannot
    tell them apart; one further apart, or not significant, is not named."""
    from popup.diagnosis import Diagnosis, History, HistoryStep, Suspect
    from popup.diagnosis.conclusion import conclude as _conclude
    from popup.diagnosis.conclusion import round_conclusion, tied_with_best
    from popup.diagnosis.rules import SCORE_THRESHOLD

    def sus(name, sig, score, after):
        return Suspect(name, sig, score, {}, {}, 1.0, after, {}, {})

    best = sus("payload_mass", True, 11450.0, 0.153)
    near = sus("wrinkling", True, 11450.0 - 0.9 * SCORE_THRESHOLD, 0.162)
    far = sus("torsion", True, 11450.0 - 1.1 * SCORE_THRESHOLD, 0.2)
    weak = sus("air_drag", False, 11449.0, 0.9)
    d = Diagnosis([best, near, far, weak], 1.0, {"tau1": 1.0}, None, True, "")
    assert [s.effect for s in tied_with_best(d)] == ["wrinkling"]
    text = round_conclusion(d)
    assert "this run cannot tell it from wrinkling (score" in text and "torsion" not in text and "air_drag" not in text, text
    ch = {"tau1": 1.0}
    steps = [HistoryStep([], {}, 1.0, ch), HistoryStep(["payload_mass"], {"payload_mass": {"delta_kg": [0.0015]}}, 0.153, ch, round=1)]
    assert "payload_mass, added first: this run cannot tell it from wrinkling" in _conclude(History(steps, [d], ""), 4)
    d2 = Diagnosis([best, far, weak], 1.0, {"tau1": 1.0}, None, True, "")
    assert tied_with_best(d2) == [] and "cannot tell" not in round_conclusion(d2) and "cannot tell" not in _conclude(History(steps, [d2], ""), 4)

"""Issue 19: the plausibility limits of measured torques and accelerations come from the
run's arm. Torque limits are factors of each drive's limit (the arm file's
``motors.tau_max_nm``); IMU limits factors of the specific force the arm can reach (drive
torques and link collapse moments through its mass matrix, plus gravity). The factors are
the engine's one registry (``_core.CHANNEL_LIMITS``); Python reads them."""

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

import popup
from popup import _core
from popup import io as pio

LAB_TAU = 66.83
THESIS_TAU = 31.376


def exp(arm: str) -> str:
    return f'format = "popup-run/1"\narm = "{arm}"\npayload_kg = 2.0\npressure_pa = [30000.0, 30000.0]\nreplay = "encoder"\n'


def write(folder: Path, cols: dict, arm: str = "popup-lab") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "experiment.toml").write_text(exp(arm))
    names = list(cols)
    n = len(cols["t"])
    rows = [",".join(names)] + [",".join(repr(float(cols[c][i])) for c in names) for i in range(n)]
    (folder / "measurements.csv").write_text("\n".join(rows) + "\n")
    return folder


def base(n: int = 100) -> dict:
    t = np.arange(n) * 0.002
    s = 0.5 - 0.5 * np.cos(np.pi * t / t[-1])
    return {"t": t, "q1": 0.2 * s, "q2": 0.6 * s, "q3": -0.3 * s, "tau2": 10.0 + 5 * s, "imu2_az": 9.81 + s}


def scaled(name: str) -> tuple:
    return next(g for g in _core.CHANNEL_LIMITS if name in g[0])


def test_registry_holds_factors_and_the_arm_gives_numbers():
    cols, unit, lo, warn, err, scale, advice = scaled("tau2")
    assert scale == "drive torque" and unit == "N·m" and 1.0 < warn < err and err >= 10 * warn
    assert scaled("imu1_ax")[5] == "arm acceleration" and scaled("q1")[5] == ""
    lab = pio.arm_limits("popup-lab")
    assert lab == pio.LIMITS
    unit, lo, w, e, advice = lab["tau2"]
    assert (w, e) == pytest.approx((warn * LAB_TAU, err * LAB_TAU))
    assert "motors.tau_max_nm[1]" in advice and "66.83 N·m" in advice, advice
    reach = _core.Arm.builtin("popup-lab").reach()
    acc_warn, acc_err = scaled("imu2_az")[3:5]
    assert lab["imu2_az"][2:4] == pytest.approx((acc_warn * reach["imu_accel"][1], acc_err * reach["imu_accel"][1]))
    assert lab["imu1_ax"][2:4] == pytest.approx((acc_warn * reach["imu_accel"][0], acc_err * reach["imu_accel"][0]))
    assert lab["q1"][3] == pytest.approx(8 * math.pi)


def test_reach_is_derived_from_the_arm():
    lab = _core.Arm.builtin("popup-lab")
    r = lab.reach()
    assert r["tau_max_nm"] == [LAB_TAU] * 3
    # q̈ of a drive against its armature (0.8 kg·m²) and what it turns: below tau/armature x 10
    assert all(0 < a < 10 * LAB_TAU / 0.8 for a in r["motor_accel"])
    assert 9.81 < r["imu_accel"][0] < r["imu_accel"][1]
    assert len(r["joint_accel"]) == 7
    thesis = popup.load_arm("popup-lab-thesis").reach()
    assert thesis["tau_max_nm"] == [THESIS_TAU] * 3
    # a lighter link 2 (0.104 kg outer piece against 0.38 kg): its tip can be shaken harder
    assert thesis["imu_accel"][1] > 1.5 * r["imu_accel"][1]
    assert pio.arm_limits("popup-lab-thesis")["imu2_ax"][3] > pio.LIMITS["imu2_ax"][3]


def test_same_torque_two_arms_two_verdicts(tmp_path):
    d = base()
    d["tau2"] = np.array(d["tau2"])
    d["tau2"][40] = 5000.0  # beyond 100 x 31.376 N·m (thesis drive), within 100 x 66.83 (lab)
    with pytest.warns(popup.PopupWarning, match=r"column tau2: 1 value beyond 334\.1 N·m"):
        pio.read_run(write(tmp_path / "lab", d, "popup-lab"))
    thesis = tmp_path / "thesis"
    thesis.mkdir()
    (thesis / "thesis.toml").write_text(popup.Arm.packaged_source("popup-lab-thesis"))
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(write(thesis, d, "thesis.toml"))
    msg = str(e.value)
    assert "row 41 (line 42), column tau2: 5000.0 N·m is not plausible" in msg, msg
    assert "the limit is 3138 N·m" in msg and "motors.tau_max_nm[1]" in msg and "check the unit" in msg, msg


def test_an_arm_files_drive_limit_is_used(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "weak.toml").write_text('base = "popup-lab"\nname = "weak"\n[motors]\ntau_max_nm = [66.83, 1.0, 66.83]\n')
    d = base()
    d["tau2"] = np.full(len(d["t"]), 0.5)
    d["tau2"][10] = 150.0  # 150 x the weak drive of q2
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(write(run, d, "weak.toml"))
    msg = str(e.value)
    assert "row 11 (line 12), column tau2: 150.0 N·m" in msg and "drive of q2 of arm weak delivers at most 1.0 N·m" in msg, msg
    # the same value on q1, whose drive is the lab's: fine
    d = base()
    d["tau2"] = np.full(len(d["t"]), 0.5)
    d["tau1"] = np.full(len(d["t"]), 150.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        r = pio.read_run(write(tmp_path / "ok", d, str(run / "weak.toml")))
    assert r.warnings == []


def test_accelerations_beyond_the_arms_reach(tmp_path):
    bound = _core.Arm.builtin("popup-lab").reach()["imu_accel"][1]
    d = base()
    d["imu2_az"] = np.array(d["imu2_az"])
    d["imu2_az"][5] = 2.0 * bound  # beyond the worst case: an impact or a unit slip
    with pytest.warns(popup.PopupWarning, match=r"column imu2_az: 1 value beyond .* m/s² .*IMU 2 of arm popup-lab"):
        pio.read_run(write(tmp_path / "w", d))
    d["imu2_az"][5] = 50.0 * bound
    with pytest.raises(popup.MeasuredRunError) as e:
        pio.read_run(write(tmp_path / "e", d))
    msg = str(e.value)
    assert "row 6 (line 7), column imu2_az:" in msg and "not plausible" in msg and "IMU 2 of arm popup-lab" in msg, msg
    assert "fix the unit or drop the samples" in msg, msg


def test_a_run_whose_arm_cannot_be_loaded_is_checked_against_the_lab(tmp_path):
    run = tmp_path / "run"
    run.mkdir()
    (run / "bad.toml").write_text("this is not toml = = =\n")
    with pytest.warns(popup.PopupWarning, match=r"(?s)arm .bad.toml. could not be loaded .*limits of popup-lab"):
        r = pio.read_run(write(run, base(), "bad.toml"))
    assert any("could not be loaded" in w for w in r.warnings)


@pytest.mark.parametrize("bad", ["0.0", "-1.0", "nan"])
def test_a_bad_drive_limit_is_named(bad):
    arm = popup.Arm.from_toml(f'base = "popup-lab"\n[motors]\ntau_max_nm = [66.83, {bad}, 66.83]\n')
    with pytest.raises(popup.ParameterError, match=r"motors\.tau_max_nm\[1\]") as e:
        arm.channel_limits()
    assert isinstance(e.value, ValueError)
    with pytest.raises(popup.ParameterError, match=r"motors\.tau_max_nm\[1\]"):
        popup.Model(arm)

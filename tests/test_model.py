"""Model, arm files, statics and kinematics through the Python API."""

import math

import numpy as np
import pytest

import popup


def test_reference_table_through_python(model):
    # reference-arm.md, 2 kg, motors (0, 0.6, -0.3): delta12, delta22, sag, modes
    q = model.rest_state((0.0, 0.6, -0.3))
    assert q[3] == pytest.approx(-0.02423, abs=1e-4)
    assert q[6] == pytest.approx(-0.03302, abs=1e-4)
    rigid = np.zeros(7)
    rigid[[0, 1, 4]] = (0.0, 0.6, -0.3)
    sag = model.end_effector(q)[2] - model.end_effector(rigid)[2]
    assert sag == pytest.approx(-0.0436, abs=5e-4)
    modes = model.locked_modes((0.0, 0.6, -0.3))
    np.testing.assert_allclose(modes, [15.1, 15.1, 66.0, 69.9], rtol=5e-3)


def test_payload_changes_modes_and_sag():
    light = popup.Model(payload_kg=0.0)
    heavy = popup.Model(payload_kg=2.0)
    assert light.locked_modes()[0] > heavy.locked_modes()[0] * 2
    assert heavy.rest_state()[6] < light.rest_state()[6]


def test_stiffness_table_and_scaling(model):
    k = model.stiffness
    assert k[5] == pytest.approx(360.0)  # link 2 at 30 kPa, Table 3
    assert k[2] == pytest.approx(360.0 * (0.085 / 0.055) ** 3)
    m = model.with_params(pressure_pa=(45e3, 45e3))
    assert m.stiffness[5] == pytest.approx(376.0)  # midway 370..382
    assert m.damping[5] == pytest.approx(0.4415)


def test_pressure_outside_table_warns_and_clamps():
    with pytest.warns(popup.PopupWarning, match="outside the stiffness table"):
        m = popup.Model(pressure_pa=(5e3, 120e3))
    assert m.stiffness[5] == pytest.approx(405.0)


def test_wrinkling_moment_classical_and_thesis(model):
    mw = model.wrinkling_moment
    assert mw[1] == pytest.approx(math.pi / 2 * 30e3 * 0.055**3)  # 7.84 N·m
    assert mw[1] == pytest.approx(7.84, abs=0.01)
    thesis = popup.Model(popup.Arm.builtin("popup-lab").with_overrides({"wrinkling": {"coefficient": "thesis"}}))
    assert thesis.wrinkling_moment[1] == pytest.approx(12.32, abs=0.01)
    assert thesis.describe()["wrinkle_coefficient"] == pytest.approx(math.pi**2 / 4)


def test_arm_file_roundtrip(tmp_path):
    arm = popup.Arm.builtin("popup-lab")
    path = tmp_path / "arm.toml"
    arm.save(path)
    again = popup.Arm.load(path)
    assert again == arm
    assert popup.Model(path).rest_state()[3] == pytest.approx(popup.Model().rest_state()[3], abs=0)


def test_arm_file_partial_override(tmp_path):
    path = tmp_path / "bigger.toml"
    path.write_text('base = "popup-lab"\n[payload]\ndefault_kg = 0.5\n[[links]]\nradius_m = 0.1\n')
    m = popup.Model(path)
    assert m.payload_kg == 0.5
    assert m.stiffness[2] == pytest.approx(360.0 * (0.1 / 0.055) ** 3)


def test_space_arm_is_a_file_not_code(tmp_path):
    # a Canadarm3-sized arm written as a file: two 4 m booms, heavy joints, lunar gravity
    tube = lambda name, m, l: {"name": name, "shape": "tube", "mass_kg": m, "com_m": [-l / 2, 0.0, 0.0], "length_m": l}
    point = lambda name, m, i: {"name": name, "shape": "point", "mass_kg": m, "com_m": [0.0, 0.0, 0.0], "inertia_kgm2": [i, i, i, 0.0, 0.0, 0.0]}
    arm = popup.Arm.builtin("popup-lab").with_overrides(
        {
            "name": "space-arm",
            "joints": [{}, {"a": 0.3}, {}, {"a": 3.7}, {"a": 0.3}, {}, {"a": 3.7}],
            "bodies": [
                {"parts": [point("shoulder", 60.0, 2.0)]},
                {"parts": [tube("boom 1 root", 8.0, 0.3)]},
                {},
                {"parts": [tube("boom 1", 90.0, 3.7), point("elbow", 50.0, 1.5)]},
                {"parts": [tube("boom 2 root", 6.0, 0.3)]},
                {},
                {"parts": [tube("boom 2", 70.0, 3.7)]},
            ],
            "links": [{"radius_m": 0.2, "length_m": 4.0}, {"radius_m": 0.18, "length_m": 4.0}],
            "stiffness": {"k_nm_per_rad": [2e5] * 9, "c_nms_per_rad": [200.0] * 9, "reference_radius_m": 0.18},
            "motors": {"armature_kgm2": [20.0, 20.0, 20.0]},
            "gravity_mps2": [0.0, 0.0, -1.62],
            "payload": {"default_kg": 100.0},
        }
    )
    path = tmp_path / "space.toml"
    arm.save(path)
    m = popup.Model(path, dt=1e-3)
    assert m.arm.name == "space-arm"
    r = m.simulate(m.holding_torque(), duration=0.2, sample_rate=100)
    assert np.all(np.isfinite(r.data))
    assert r.ee[0, 0] == pytest.approx(8.0, abs=0.05)
    assert np.max(np.abs(r.bending - r.bending[0])) < 1e-9  # held at rest


def test_rigid_ik_roundtrip(model):
    rng = np.random.default_rng(0)
    for table in ("as_built", "ik"):
        rigid = model.rigid(table)
        for _ in range(50):
            q = rng.uniform(-2.5, 2.5, 3)
            p = rigid.fk(q)
            sols = rigid.ik(p)
            assert len(sols) == 4
            for qs, _, _ in sols:
                np.testing.assert_allclose(rigid.fk(qs), p, atol=1e-9)


def test_rigid_singularities_and_jacobian(model):
    rigid = model.rigid("ik")
    assert rigid.singularity([0.3, 0.2, 0.0])["elbow"]
    assert not rigid.singularity([0.3, 0.2, 0.5])["elbow"]
    # shoulder: 0.745 c2 + 0.685 c23 = 0 with q2 = pi/2, q3 = 0
    assert rigid.singularity([0.0, math.pi / 2, 0.0])["shoulder"]
    q = np.array([0.3, 0.4, -0.8])
    j = rigid.jacobian(q)
    h = 1e-7
    for i in range(3):
        dq = np.zeros(3)
        dq[i] = h
        np.testing.assert_allclose(j[:3, i], (rigid.fk(q + dq) - rigid.fk(q - dq)) / (2 * h), atol=1e-7)


def test_unreachable_target_is_an_error(model):
    with pytest.raises(popup.UnreachableError, match="unreachable"):
        model.rigid("as_built").ik([3.0, 0.0, 0.0])
    # the chapter-8 target is inside Table 1's workspace
    assert len(model.rigid("as_built").ik([-0.8, -0.8, 0.9])) == 4


def test_prbm_rigid_table_matches_the_chain_and_its_workspace(model):
    rigid = model.rigid("prbm")
    np.testing.assert_allclose(rigid.fk([0.0, 0.0, 0.0]), [1.2, 0.0, 0.0], atol=1e-15)
    rng = np.random.default_rng(1)
    for _ in range(20):
        qm = rng.uniform(-2, 2, 3)
        q = np.zeros(7)
        q[[0, 1, 4]] = qm
        np.testing.assert_allclose(rigid.fk(qm), model.end_effector(q), atol=1e-12)
    # reference-arm.md: the chapter-8 target is inside Table 1's workspace, outside Table 4's
    with pytest.raises(popup.UnreachableError, match="1.2"):
        rigid.ik([-0.8, -0.8, 0.9])


def test_prbm_frames_consistent_with_end_effector(model):
    q = model.rest_state((0.1, 0.5, -0.4))
    f = model.frames(q)
    assert f.shape == (8, 4, 4)
    np.testing.assert_allclose(f[7, :3, 3], model.end_effector(q), atol=1e-15)
    for i in range(8):
        r = f[i, :3, :3]
        np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)

"""Beam links in the arm at the Python surface (issue 6): ``higher_bending_modes.elements``.

The closed-form checks (P L³/3EI, the tip-mass frequency equation, energy) are in Rust
(``crates/popup-core/tests/beam_arm.rs``); these check what a Python user relies on:
the chain the effect builds, the matched-stiffness beam against the PRBM, the second
bending mode the PRBM lacks, per-run materials in batched rollouts and their
determinism, and bad materials refused by name.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import popup
from popup import effects as fx

HBM = fx.EFFECTS["higher_bending_modes"]
K30 = 360.0  # PRBM link-2 stiffness at 30 kPa [N·m/rad] (popup-lab's table)
L2, R2, WALL = 0.57, 0.055, 1.2e-3
#: E of a beam link with EI = k L / 3: the same tip deflection under a tip force as the PRBM link
E_MATCH = K30 * L2 / (3.0 * math.pi * R2**3 * WALL)


def beam(elements, dt=1e-4, integrator="rk4", payload_kg=2.0, **material):
    m = popup.Model("popup-lab", dt=dt, integrator=integrator, payload_kg=payload_kg)
    return m.with_effect("higher_bending_modes", elements=list(elements), **material)


def test_matched_modulus_uses_the_prbm_stiffness():
    m = popup.Model("popup-lab")
    k = m.stiffness[m.joint_names.index("d21")]
    assert k == pytest.approx(K30)
    assert E_MATCH == pytest.approx(109.05e6, rel=1e-3)


@pytest.mark.parametrize("n", [1, 2, 4, 6])
def test_link2_beam_chain_names_and_size(n):
    m = beam([0, n], dt=1e-3)
    names = m.joint_names
    # 3 motors + link 1's universal joint + 2n universal joints (4n joints) on link 2
    assert len(names) == 5 + 4 * n
    assert names[:7] == ["q1", "q2", "d11", "d12", "q3", "d21", "d22"]
    extra = [f"d2{a}_{k}" for k in range(2, 2 * n + 1) for a in (1, 2)]
    assert names[7:] == extra
    assert len(m.rest_state()) == len(names)
    assert m.mass_matrix(m.rest_state()).shape == (len(names), len(names))
    assert m.effects["higher_bending_modes"]["elements"] == [0.0, float(n)]
    # every passive joint has a locked mode
    assert len(m.locked_modes()) == len(names) - 3


def test_both_links_beams_and_the_joint_limit():
    m = beam([2, 3], dt=1e-3)
    names = m.joint_names
    assert len(names) == 3 + 4 * (2 + 3)
    assert [n for n in names if n.startswith("d1")][:2] == ["d11", "d12"]
    assert sum(n.startswith("d1") for n in names) == 8 and sum(n.startswith("d2") for n in names) == 12
    with pytest.raises(popup.ParameterError, match="elements"):
        popup.Model("popup-lab").with_effect("higher_bending_modes", elements=[4, 4])  # 35 joints > 31
    with pytest.raises(popup.ParameterError, match="elements"):
        popup.Model("popup-lab").with_effect("higher_bending_modes", elements=[0, 7])


def test_prbm_model_is_unchanged_by_beam_material_alone():
    """Material parameters do nothing while no link is a beam (neutral = nominal)."""
    m0 = popup.Model("popup-lab")
    m1 = m0.with_effect("higher_bending_modes", e_pa=[2e8, 2e8], lambda_s=[1e-3, 1e-3])
    assert m1.joint_names == m0.joint_names
    np.testing.assert_array_equal(m1.locked_modes(), m0.locked_modes())
    r0 = m0.simulate(m0.holding_torque(), duration=0.2)
    r1 = m1.simulate(m1.holding_torque(), duration=0.2)
    np.testing.assert_array_equal(r0.data, r1.data)


@pytest.mark.parametrize("payload", [0.0, 2.0])
@pytest.mark.parametrize("n", [1, 2, 4])
def test_matched_beam_first_mode_within_10_percent_of_prbm(n, payload):
    prbm = popup.Model("popup-lab", payload_kg=payload)
    b = beam([0, n], payload_kg=payload, e_pa=[E_MATCH, E_MATCH], wall_m=[WALL, WALL])
    wp, wb = prbm.locked_modes(), b.locked_modes()
    assert wb[0] == pytest.approx(wp[0], rel=0.10)
    assert wb[1] == pytest.approx(wp[1], rel=0.10)
    # and the static sag of the end effector (link 2 loaded at its tip)
    qp, qb = prbm.rest_state(), b.rest_state()
    sag_p = prbm.end_effector(qp)[2] - prbm.end_effector(np.zeros(len(qp)))[2]
    sag_b = b.end_effector(qb)[2] - b.end_effector(np.zeros(len(qb)))[2]
    assert sag_p < 0 and sag_b == pytest.approx(sag_p, rel=0.10)


def test_a_stiffer_wall_raises_the_first_mode():
    w_soft = beam([0, 2], e_pa=[E_MATCH, E_MATCH]).locked_modes()
    w_stiff = beam([0, 2], e_pa=[5 * E_MATCH, 5 * E_MATCH]).locked_modes()
    assert w_stiff[0] > 1.1 * w_soft[0]


def test_beam_has_a_second_bending_mode_per_plane_that_the_prbm_lacks():
    prbm = popup.Model("popup-lab")
    wp = prbm.locked_modes()
    # the PRBM arm: two mode pairs (link 1 and link 2), all far below 3000 rad/s, nothing else
    assert len(wp) == 4 and wp.max() < 300.0
    for n in (2, 4):
        wb = beam([0, n], e_pa=[E_MATCH, E_MATCH]).locked_modes()
        below = wb[wb < 3000.0]
        assert len(below) >= len(wp) + 2
        second = below[len(wp) : len(wp) + 2]  # link 2's second bending mode, one per plane
        assert second[1] == pytest.approx(second[0], rel=0.05)
        assert second[0] > 3.0 * wp.max()
        # with link 1 stiffened, link 2 alone: the PRBM link has one mode per plane below
        # 2000 rad/s, the beam link two
        arm = popup.Arm.builtin("popup-lab").with_overrides({"links": [{"stiffness_scale": 1e4}]})
        p_alone = popup.Model(arm).locked_modes()
        b_alone = popup.Model(arm).with_effect("higher_bending_modes", elements=[0, n], e_pa=[E_MATCH, E_MATCH]).locked_modes()
        assert np.sum(p_alone < 2000.0) == 2
        assert np.sum(b_alone < 2000.0) >= 4
        assert b_alone[0] == pytest.approx(p_alone[0], rel=0.10)


def _flat(model, e_pa):
    f = model.effects_flat.copy()
    f[HBM.params["e_pa"].offset + 1] = e_pa
    return f


def test_rollouts_with_per_run_modulus_differ_and_repeat_bit_for_bit(encoder_run):
    t, q = encoder_run
    t, q = t[:251], q[:251]  # 0.5 s
    m = beam([0, 2], e_pa=[E_MATCH, E_MATCH])
    flats = np.array([_flat(m, E_MATCH), _flat(m, 3 * E_MATCH), _flat(m, E_MATCH)])
    b1 = m.rollout(encoder_t=t, encoder_q=q, effects=flats, threads=0)
    b2 = m.rollout(encoder_t=t, encoder_q=q, effects=flats, threads=1)
    assert np.all(np.isfinite(b1.data))
    np.testing.assert_array_equal(b1.data, b2.data)  # any thread count, run to run
    np.testing.assert_array_equal(b1.data[0], b1.data[2])  # same parameters, same run
    d0, d1 = b1.channel("d22")[0], b1.channel("d22")[1]
    assert np.max(np.abs(d0 - d1)) > 1e-4  # a 3x stiffer wall bends less
    assert np.max(np.abs(d1)) < np.max(np.abs(d0))
    # the model's own effects give the same run as its flat vector
    single = m.replay(t, q)
    np.testing.assert_array_equal(single.data, b1.data[0])
    assert b1.params["effects"][1]["higher_bending_modes"]["e_pa"][1] == pytest.approx(3 * E_MATCH)


def test_semi_implicit_beam_runs_at_a_larger_step_than_rk4():
    m_rk4 = beam([0, 4], dt=1e-4)  # thesis material: stiff damped FE modes
    with pytest.raises(popup.StepTooLargeError, match=r"dt <= [0-9.e+-]+ s"):
        m_rk4.simulate(m_rk4.holding_torque(), duration=0.01)
    m_si = beam([0, 4], dt=1e-4, integrator="semi_implicit")
    r = m_si.simulate(m_si.holding_torque(), duration=0.05)
    assert np.all(np.isfinite(r.data))


@pytest.mark.parametrize("bad", [float("nan"), -1.0, 0.0])
def test_bad_modulus_is_refused_by_name(bad):
    m = beam([0, 2], dt=1e-3)
    with pytest.raises(popup.ParameterError, match=r"e_pa"):
        m.with_effect("higher_bending_modes", e_pa=[0.557e9, bad])
    # through a batched rollout's flat effect vector
    t = np.arange(0.0, 0.02, 0.002)
    with pytest.raises(popup.ParameterError, match=r"e_pa\[1\]"):
        m.rollout(encoder_t=t, encoder_q=np.zeros((len(t), 3)), effects=_flat(m, bad)[None])
    # through an arm file's [effects] table (the engine's own check)
    arm = popup.Arm.builtin("popup-lab").with_overrides({"effects": {"higher_bending_modes": {"elements": [0, 2], "e_pa": [0.557e9, bad]}}})
    with pytest.raises(popup.ParameterError, match=r"e_pa"):
        popup.Model(arm)

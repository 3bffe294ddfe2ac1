"""`Model.with_links` / `link_models` / `BEAM_PRESETS`: choosing rigid, PRBM or beam links per
link."""

import numpy as np
import pytest

import popup


def test_link_models_and_presets():
    m = popup.Model("popup-lab")
    assert m.link_models == ["prbm", "prbm"]
    b = m.with_links(link2="beam(3)", preset="thesis-0.8mm")
    assert b.link_models == ["prbm", "beam(3)"]
    # 3 motors + link 1's universal joint + 2 universal joints per element
    assert len(b.joint_names) == 3 + 2 + 4 * 3
    hbm = b.effects["higher_bending_modes"]
    assert hbm["elements"] == [0.0, 3.0]
    assert hbm["e_pa"] == [popup.BEAM_PRESETS["thesis-0.8mm"]["e_pa"]] * 2
    assert hbm["lambda_s"] == [3.4919e-4] * 2
    both = b.with_links("beam(2)", None, e_pa=[0.6e9, 0.7e9])
    assert both.link_models == ["beam(2)", "beam(3)"]
    assert both.effects["higher_bending_modes"]["e_pa"] == [0.6e9, 0.7e9]
    back = both.with_links("prbm", "prbm(2)")
    assert back.link_models == ["prbm", "prbm(2)"]
    assert set(popup.BEAM_PRESETS) == {"thesis-1.2mm", "thesis-0.8mm"}


def test_beam_link_changes_the_physics():
    m = popup.Model("popup-lab")
    b = m.with_links(link2="beam(2)")
    # a beam link has a second bending mode per plane; the PRBM link 2 has one
    assert len(b.locked_modes()) == len(m.locked_modes()) + 6
    # a stiffer wall raises link 2's modes (E × 3: up to √3 on a link-2 mode), not link 1's
    soft, stiff = (b.with_links(link2="beam(2)", e_pa=e).locked_modes() for e in (0.3e9, 0.9e9))
    ratio = stiff[:6] / soft[:6]
    assert ratio.max() > 1.4 and ratio.min() >= 1.0


@pytest.mark.parametrize(
    "args, needle",
    [(("beam",), "element count"), (("rigid(2)",), "takes no count"), (("stiff",), "not a link model"), (("beam(7)",), "elements[0]"), (("prbm(4)",), "segments")],
)
def test_bad_link_models_are_refused_by_name(args, needle):
    with pytest.raises(popup.PopupError, match=needle.replace("[", r"\[").replace("]", r"\]")):
        popup.Model("popup-lab").with_links(*args)


def test_unknown_preset_lists_the_known_ones():
    with pytest.raises(popup.InputError, match="thesis-1.2mm"):
        popup.Model("popup-lab").with_links(link2="beam(2)", preset="nope")
    with pytest.raises(popup.ParameterError, match="wall_m"):
        popup.Model("popup-lab").with_links(link2="beam(2)", wall_m=0.2)


def test_stable_dt_is_the_step_checks_limit():
    m = popup.Model("popup-lab").with_links(link2="beam(3)")
    lim = m.stable_dt()
    assert 0 < lim < m.dt  # beam links need a smaller step than 1 ms with RK4
    with pytest.raises(popup.StepTooLargeError) as ei:
        m.simulate(torque=m.holding_torque(), duration=0.01)
    assert ei.value.dt == m.dt and ei.value.dt_max == lim
    # at (just below) that step the model runs; the PRBM model keeps its own 1 ms
    dt = max(d for d in (5e-5, 4e-5, 2.5e-5, 2e-5, 1e-5) if d < lim)  # divides the 2 ms sample period
    ok = popup.Model("popup-lab", dt=dt).with_links(link2="beam(3)")
    assert ok.stable_dt() == ok.dt
    r = ok.simulate(torque=ok.holding_torque(), duration=0.002)
    assert np.all(np.isfinite(r.data))
    assert popup.Model("popup-lab").stable_dt() == 1e-3


def test_rigid_links_lock_the_universal_joint_and_report_its_moment():
    from popup import frequency as fr

    m = popup.Model("popup-lab", payload_kg=2.0, dt=2e-4)  # the stiff PRBM below needs it
    r = m.with_links("rigid", None)
    assert r.link_models == ["rigid", "prbm"]
    assert r.effects["higher_bending_modes"]["segments"] == [0.0, 1.0]
    assert r.joint_names == m.joint_names and r.core.locked_index == [2, 3]
    # link 1's bending modes are gone, link 2's remain
    assert len(r.locked_modes()) == len(m.locked_modes()) - 2
    q = (0.0, 0.6, -0.4)
    res = r.simulate(torque=r.holding_torque(q), duration=0.2, initial_q=r.rest_state(q))
    assert np.all(res.channel("d11") == 0.0) and np.all(res.channel("dd12") == 0.0)
    # rigid links' root moments = the stiff PRBM links' spring moments at rest (k × 1e4: the
    # links bend by ~1e-5 rad, their moments differ by that much relatively)
    both = fr.rigid_links(m)
    res = both.simulate(torque=both.holding_torque(q), duration=0.2, initial_q=both.rest_state(q))
    stiff = fr.rigid_links(m, factor=1e4)
    s = stiff.simulate(torque=stiff.holding_torque(q), duration=0.2, initial_q=stiff.rest_state(q))
    for ch in ("m11", "m12", "m21", "m22", "m1_ratio", "m2_ratio"):
        a, b = res.channel(ch)[-1], s.channel(ch)[-1]
        assert a == pytest.approx(b, rel=1e-4, abs=1e-6), ch
    assert abs(res.channel("m12")[-1]) > 10.0  # link 1 carries link 2 and 2 kg


def test_rigid_links_in_the_linearised_closed_loop():
    """The velocity loop around a rigid-link arm (the motors' places in the state skip the
    locked joints) equals the quasi-rigid PRBM's well below its bending modes (k × 1e6: the
    lowest above 10⁴ rad/s)."""
    from popup import frequency as fr

    m = popup.Model("popup-lab", payload_kg=2.0, gravity=False)
    q = (0.0, np.pi / 2, 0.0)
    w = np.array([5.0, 50.0, 300.0, 700.0])
    rig = fr.linearize(fr.rigid_links(m), q, input="velocity", outputs=["dq2", "dq3"])
    quasi = fr.linearize(fr.rigid_links(m, factor=1e6), q, input="velocity", outputs=["dq2", "dq3"])
    assert rig.a.shape[-1] == quasi.a.shape[-1] - 8  # 4 locked joints: no (q, q̇) states
    for j in ("q2", "q3"):
        hr, hq = rig.frf(w, joint=j).H, quasi.frf(w, joint=j).H
        assert np.abs(hr / hq - 1).max() < 0.01, j


def test_rigid_links_in_a_closed_loop_task_report_their_moments():
    from popup.control import Controller, Phase, Task, const, sine

    m = popup.Model("popup-lab", payload_kg=1.0, dt=5e-4).with_links(None, "rigid")
    task = Task([Phase("moving", velocity=[const(0), const(0), sine(0.3, 1.0)], until={"max_time": 9.0})], Controller(rate_hz=2000.0))
    a = m.run_task(task, duration=1.0, q0=(0.0, 1.0, 0.0))
    assert a.status == "completed"
    assert np.all(a.channel("d21") == 0.0)
    ratio = a.channel("m2_ratio")
    assert ratio.min() > 0.0 and np.ptp(a.channel("m22")) > 0.01  # the moving elbow changes the load

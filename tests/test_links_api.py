"""`Model.with_links` / `link_models` / `BEAM_PRESETS`: choosing PRBM or beam links per link."""

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
    [(("beam",), "element count"), (("rigid",), "not a link model"), (("beam(7)",), "elements[0]"), (("prbm(4)",), "segments")],
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

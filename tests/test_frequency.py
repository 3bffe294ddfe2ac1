"""Frequency analysis (popup.frequency): the estimators on systems with known answers, the
linearised arm against the locked-motor modes, and the simulated FRF of the arm against the
linearised one where both apply."""

import math

import numpy as np
import pytest
from scipy import signal

import popup
from popup import frequency as fr
from popup.control import Controller

# ----------------------------------------------------------------------------- SDOF
WN, ZETA = 10.0, 0.05
SDOF = signal.lti([WN**2], [1.0, 2 * ZETA * WN, WN**2])  # unit static gain
PEAK_W = WN * math.sqrt(1 - 2 * ZETA**2)
PEAK_DB = 20 * math.log10(1 / (2 * ZETA * math.sqrt(1 - ZETA**2)))


def _sdof_stepped(omegas, system=SDOF, settle_tau=8.0, window_periods=6, fs_per_period=160):
    """Stepped sine on an LTI system simulated by scipy.signal.lsim: settle, then the
    first-harmonic fit over whole periods. (lsim holds the input linearly between samples,
    which attenuates a sampled sine by (ω h)²/12: 160 samples per period keep that below
    1e-4.)"""
    H = []
    for w in omegas:
        T = 2 * np.pi / w
        n_set = math.ceil(settle_tau / (ZETA * WN) / T)
        n = (n_set + window_periods) * fs_per_period
        t = np.arange(n + 1) * (T / fs_per_period)
        u = np.sin(w * t)
        _, y, _ = signal.lsim(system, u, t)
        sel = t >= n_set * T - 1e-12
        sel[-1] = False  # whole periods
        H.append(fr.sine_fit(t[sel], y[sel], w))
    return np.array(H)


def test_sdof_stepped_sine_peak_and_height():
    w = np.geomspace(6.0, 16.0, 41)
    H = _sdof_stepped(w)
    exact = signal.freqresp(SDOF, w)[1]
    assert np.max(np.abs(H / exact - 1)) < 2e-3
    wr, pk = fr.resonance(w, H, reference=1.0)
    assert wr == pytest.approx(PEAK_W, rel=2e-3)
    assert pk == pytest.approx(PEAK_DB, abs=0.05)
    # the same extraction on the exact response, and through an FRF object
    frf = fr.FRF(omega=w, H=exact[None, :, None], outputs=["y"], input="torque", joint="q1", method="exact", sweep={"amplitude": np.ones(1)})
    wr2, pk2 = frf.resonance(reference=1.0)
    assert wr2[0] == pytest.approx(PEAK_W, rel=2e-3) and pk2[0] == pytest.approx(PEAK_DB, abs=0.05)


def test_sdof_chirp_h1_with_output_noise():
    """H1 from a linear chirp with white noise on the output (seeded): unbiased by the noise
    (it averages out of P_uy) away from the resonance; at the resonance, whose half-power
    width (2ζω_n = 1 rad/s) is about three Welch bins, the Hann window's smearing shows as
    a lower coherence and a peak within 1 dB."""
    rng = np.random.default_rng(20240607)
    fs = 200.0
    t = np.arange(0, 120.0, 1 / fs)
    u = signal.chirp(t, f0=0.3, f1=6.0, t1=t[-1], method="linear")
    _, y, _ = signal.lsim(SDOF, u, t)
    w, H0, _ = fr.h1_estimate(u, y, fs, nperseg=4096)
    w, H, coh = fr.h1_estimate(u, y + 0.02 * rng.standard_normal(t.size), fs, nperseg=4096)
    band = (w > 4.0) & (w < 30.0)
    exact = signal.freqresp(SDOF, w[band])[1]
    away = np.abs(w[band] - WN) > 2.5
    err = np.abs(H[band] / exact - 1)
    assert np.median(err[away]) < 0.02 and err[away].max() < 0.05
    assert np.median(np.abs(H[band] / H0[band] - 1)) < 0.02  # the noise adds no bias
    assert np.all(coh[band][away] > 0.95)
    assert coh[band][~away].min() < coh[band][away].min()
    wr, pk = fr.resonance(w[band], H[band], reference=1.0)
    assert wr == pytest.approx(PEAK_W, rel=0.02)
    assert pk == pytest.approx(PEAK_DB, abs=1.0)
    assert np.all((coh >= 0) & (coh <= 1 + 1e-9))


def test_first_order_lowpass_cutoff_at_its_corner():
    wc = 50.0
    lp = signal.lti([wc], [1.0, wc])
    w = np.geomspace(5.0, 500.0, 25)
    H = []
    for x in w:
        T = 2 * np.pi / x
        n_set = max(3, math.ceil(8 / wc / T))
        t = np.arange((n_set + 4) * 160 + 1) * (T / 160)
        _, y, _ = signal.lsim(lp, np.sin(x * t), t)
        sel = (t >= n_set * T - 1e-12) & (t < t[-1])
        H.append(fr.sine_fit(t[sel], y[sel], x))
    assert fr.cutoff(w, np.array(H), reference=1.0) == pytest.approx(wc, rel=5e-3)
    # relative to the lowest frequency (the default) it is slightly higher than the corner
    assert fr.cutoff(w, np.array(H)) > wc


def test_cutoff_skips_narrow_notches_and_edge_cases():
    w = np.geomspace(1, 1000, 400)
    lp = 1 / (1 + 1j * w / 300.0)
    notch = (1 - (w / 70) ** 2 + 0.02j * w / 70) / (1 - (w / 70) ** 2 + 0.1j * w / 70)  # −3 dB over ≈ 10 %
    H = lp * notch
    assert fr.cutoff(w, H) < 80  # the notch is the first −3 dB crossing
    assert fr.cutoff(w, H, min_width=1.2) == pytest.approx(300.0, rel=0.02)
    assert fr.cutoff(w, np.full(w.size, 0.5), reference=1.0) == 0.0
    assert fr.cutoff(w, np.ones(w.size)) == math.inf
    assert all(math.isnan(x) for x in fr.resonance(w, lp))


def test_modes_from_poles():
    lam = -ZETA * WN + 1j * WN * math.sqrt(1 - ZETA**2)
    rows = fr.modes_from_poles([lam, np.conj(lam), -3.0, 0.0])
    assert [r["wn"] for r in rows] == pytest.approx([0.0, 3.0, WN])
    assert rows[2]["zeta"] == pytest.approx(ZETA) and rows[1]["zeta"] == 1.0 and math.isnan(rows[0]["zeta"])


# ----------------------------------------------------------------------------- the arm, linearised
def test_locked_modes_from_the_linearisation(model):
    lin = fr.linearize(model, (0.0, 0.6, -0.3), input="locked", payload_kg=[0.0, 1.0, 2.0])
    df = lin.modes()
    for k, p in enumerate((0.0, 1.0, 2.0)):
        want = model.with_params(payload_kg=p).locked_modes((0.0, 0.6, -0.3))
        got = np.sort(df[df.point == k].wn.to_numpy())
        assert got == pytest.approx(want, rel=1e-6)
        z = df[df.point == k].zeta.to_numpy()
        assert np.all((z > 0.005) & (z < 0.2))  # light structural damping
    # reference-arm.md: 2 kg at (0, 0.6, -0.3): 15.1, 15.1, 66.0, 69.9 rad/s
    assert np.sort(df[df.point == 2].wn) == pytest.approx([15.1, 15.1, 66.0, 69.9], rel=5e-3)
    # payload lowers the first mode
    first = [df[df.point == k].wn.min() for k in range(3)]
    assert first[0] > first[1] > first[2]


def test_linear_model_shapes_and_errors(model):
    lin = fr.linearize(model, [(0, 0, 0), (0, 0.5, 0)], input="torque", outputs=["ee_z", "d22"])
    assert lin.a.shape == (2, 14, 14) and lin.b.shape == (2, 14, 3) and lin.c.shape == (2, 2, 14)
    assert lin.u0[0] == pytest.approx(model.holding_torque((0, 0, 0)))
    frf = lin.frf([1.0, 10.0], joint="q2")
    assert frf.H.shape == (2, 2, 2) and frf.summary().shape[0] == 4
    with pytest.raises(popup.PopupError):
        fr.linearize(model, input="bogus")
    with pytest.raises(popup.InputError):
        fr.linearize(model, outputs=["nope"])
    with pytest.raises(popup.InputError):
        fr.linearize(model, input="locked").frf([1.0])
    with pytest.raises(popup.InputError):
        fr.linearize(popup.Model(dt=1e-4), input="velocity", controller=Controller(damping=True))
    with pytest.raises(popup.InputError):
        fr.linearize(model, q_motor=[(0, 0, 0)] * 2, payload_kg=[0, 1, 2])


# ----------------------------------------------------------------------------- simulated vs linearised
def test_simulated_frf_matches_linearised_near_the_first_bending_mode():
    """Prescribed elbow motion of 1 mrad, gravity on, 2 kg, around the first vertical
    bending mode (15 rad/s, ζ ≈ 0.01): the stepped sine with automatic settling agrees with
    the linearised model in gain and phase; the resonance is where the model's mode is."""
    m = popup.Model("popup-lab", payload_kg=2.0)
    q = (0.0, 0.6, -0.3)
    w = np.array([12.0, 14.0, 14.8, 15.2, 16.0, 18.0])
    outs = ["d22", "imu2_ay", "ee_z"]  # imu y: in the arm plane, normal to link 2
    sim = fr.simulate(m, w, input="motor_angle", joint="q3", outputs=outs, amplitude=1e-3, q_motor=q, settle_s="auto", threads=2)
    lin = fr.linearize(m, q, input="motor_angle", outputs=outs).frf(w, joint="q3")
    ratio = sim.H[0] / lin.H[0]
    assert np.max(np.abs(np.abs(ratio) - 1)) < 0.02
    assert np.max(np.abs(np.degrees(np.angle(ratio)))) < 2.0
    assert np.all(sim.coherence > 0.99)
    modes = fr.linearize(m, q, input="locked").modes()
    wf = np.geomspace(13.0, 17.5, 60)
    wr, _ = fr.linearize(m, q, input="motor_angle", outputs=["d22"]).frf(wf).resonance()
    assert np.min(np.abs(modes.wn - wr[0])) < 0.1


def test_closed_loop_velocity_frf_matches_linearised_and_falls_with_amplitude():
    """The thesis's velocity-loop experiment (elbow, 2 kg, gravity off): at 0.1 rad/s the
    simulated first-harmonic gain follows the linearised closed loop; at 3 rad/s the torque
    limit lowers the cut-off (a describing function)."""
    m = popup.Model("popup-lab", dt=1e-4, gravity=False)
    q = (0.0, math.pi / 2, 0.0)
    w = np.array([100.0, 400.0, 700.0, 1200.0])
    sim = fr.simulate(m, w, input="velocity", joint="q3", outputs=["dq3"], amplitude=[0.1, 3.0], q_motor=q, threads=2)
    lin = fr.linearize(m, q, input="velocity", outputs=["dq3"]).frf(w)
    assert np.abs(sim.H[0, :, 0] / lin.H[0, :, 0] - 1).max() < 0.01
    g = np.abs(sim.H[:, :, 0])
    assert g[1, 2] < 0.5 * g[0, 2]  # saturated at 3 rad/s, 700 rad/s
    assert lin.cutoff(reference=1.0)[0] == pytest.approx(707.0, rel=0.02)  # thesis Table 5


def test_batched_sweep_one_call_and_results(model):
    w = np.array([20.0, 60.0, 70.0, 80.0])
    sim = fr.simulate(model, w, input="torque", joint="q3", outputs=["d22", "dq3"], amplitude=0.2, q_motor=(0, 0, 0), payload_kg=[0.0, 2.0], threads=2)
    assert sim.H.shape == (2, 4, 2) and np.all(np.isfinite(sim.H))
    df = sim.to_pandas()
    assert len(df) == 2 * 4 * 2 and {"payload_kg", "omega", "mag_db", "phase_deg", "coherence"} <= set(df.columns)
    s = sim.summary()
    assert list(s.payload_kg) == [0.0, 2.0, 0.0, 2.0]
    fig = sim.plot("d22", coherence=True)
    fr.linearize(model, input="torque", outputs=["d22"], payload_kg=[0.0, 2.0]).frf(w).plot(axes=fig.axes, style="--", label="linear")
    assert len(fig.axes) == 3
    # deterministic: the same call gives the same bits
    again = fr.simulate(model, w, input="torque", joint="q3", outputs=["d22", "dq3"], amplitude=0.2, q_motor=(0, 0, 0), payload_kg=[0.0, 2.0], threads=1)
    assert np.array_equal(sim.H, again.H)


def test_closed_loop_rollout_multi_equals_one_task_per_call():
    from popup import _core
    from popup.control import Phase, Task, const, sine

    m = popup.Model("popup-lab", dt=5e-4)
    ctrl = Controller(rate_hz=2000.0)
    tasks = [Task([Phase("phase", velocity=[const(0), const(0), sine(0.1, f)], until={"max_time": 9.0})], ctrl) for f in (1.0, 3.0)]
    args = (np.array([2.0, 1.0]), np.full((2, 2), 30e3), np.array([[0, 1.5, 0], [0, 1.0, 0.2]]), 0.3, 5e-3)
    multi = _core.closed_loop_rollout_multi(m.core, [t.to_toml() for t in tasks], *args)
    for b, t in enumerate(tasks):
        one = _core.closed_loop_rollout(m.core, t.to_toml(), args[0][b : b + 1], args[1][b : b + 1], args[2][b : b + 1], *args[3:])
        assert np.array_equal(np.asarray(multi[0])[b], np.asarray(one[0])[0])
    with pytest.raises(popup.InputError):
        _core.closed_loop_rollout_multi(m.core, [tasks[0].to_toml()], *args)


def test_rigid_links_push_the_bending_modes_up(model):
    assert fr.rigid_links(model).link_models == ["rigid", "rigid"]
    r = fr.rigid_links(model, factor=1e4)
    w = np.sort(fr.linearize(r, input="locked").modes().wn)
    assert w[0] > 100 * 14.0
    assert r.payload_kg == model.payload_kg


def test_thesis_table3_fit_of_the_link_inertia():
    """examples/thesis_tables.py, Table 3: the thesis's f_s is √(k/J)/2π with one J at every
    pressure (the ratio to ours is constant), and that J is 0.86 of the spec's link."""
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "examples" / "thesis_tables.py"
    spec = importlib.util.spec_from_file_location("thesis_tables", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rows = [r for r in mod.table3() if r.startswith("| ") and r[2].isdigit()]
    ratios = [float(r.split("|")[5]) for r in rows]
    fitted = [float(r.split("|")[6]) for r in rows]
    assert len(rows) == 9 and max(ratios) - min(ratios) < 0.005
    assert np.mean(fitted) == pytest.approx(0.0359, abs=2e-4)

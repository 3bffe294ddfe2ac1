"""Runs, batched rollouts and the determinism contract (bit-identical arrays)."""

import tomllib

import numpy as np
import pytest

import popup


def test_simulate_holds_at_rest(model):
    r = model.simulate(model.holding_torque(), duration=0.5, sample_rate=100)
    assert r.data.shape == (51, len(popup.CHANNELS))
    # held at the static equilibrium: nothing moves
    assert np.max(np.abs(r.bending - r.bending[0])) < 1e-9
    np.testing.assert_allclose(r.imu2, np.broadcast_to(r.imu2[0], r.imu2.shape), atol=1e-9)
    # IMU at rest reads |a - g| = 9.81 m/s²
    np.testing.assert_allclose(np.linalg.norm(r.imu2, axis=1), 9.81, atol=1e-9)


def test_imu_reads_specific_force_at_rest(model):
    r = model.simulate(model.holding_torque((0.0, np.pi / 2, 0.0)), duration=0.1, initial_q=model.rest_state((0.0, np.pi / 2, 0.0)))
    # link 1 vertical: frame-4 x axis points up, IMU reads +9.81 along it
    assert r.imu1[0, 0] == pytest.approx(9.81, abs=1e-9)
    assert np.linalg.norm(r.imu2[0]) == pytest.approx(9.81, abs=1e-9)


def test_same_run_twice_bit_identical(model, encoder_run):
    t, q = encoder_run
    a = model.replay(t, q)
    b = model.replay(t, q)
    np.testing.assert_array_equal(a.data, b.data)


def test_batched_equals_one_by_one_and_any_thread_count(model, encoder_run):
    t, q = encoder_run
    payloads = np.array([0.0, 0.5, 1.0, 1.5, 2.0, 2.5])
    pressures = np.stack([np.linspace(20e3, 80e3, 6), np.linspace(80e3, 20e3, 6)], axis=1)
    b1 = model.rollout(payload_kg=payloads, pressure_pa=pressures, encoder_t=t, encoder_q=q, threads=1)
    b2 = model.rollout(payload_kg=payloads, pressure_pa=pressures, encoder_t=t, encoder_q=q, threads=2)
    b0 = model.rollout(payload_kg=payloads, pressure_pa=pressures, encoder_t=t, encoder_q=q, threads=0)
    np.testing.assert_array_equal(b1.data, b2.data)
    np.testing.assert_array_equal(b1.data, b0.data)
    for i in range(len(payloads)):
        single = model.with_params(payload_kg=payloads[i], pressure_pa=pressures[i]).replay(t, q)
        np.testing.assert_array_equal(b1.data[i], single.data)
    # the runs differ from each other (the batch is not one run copied)
    assert np.all(np.abs(np.diff(b1.ee[:, -1, 2])) > 1e-4)


def test_torque_batch_matches_single_runs(model):
    tau = model.holding_torque() + np.array([0.0, 2.0, -1.0])
    b = model.rollout(payload_kg=[1.0, 2.0], torque=tau, duration=0.3, threads=2)
    for i, p in enumerate([1.0, 2.0]):
        s = model.with_params(payload_kg=p).simulate(tau, duration=0.3)
        np.testing.assert_array_equal(b[i].data, s.data)


def test_to_pandas_and_plot(model, encoder_run):
    t, q = encoder_run
    r = model.replay(t, q, sample_rate=100)
    df = r.to_pandas()
    assert list(df.columns[:3]) == ["q1", "q2", "q3"]
    assert df.index.name == "t"
    np.testing.assert_array_equal(df["ee_z"].to_numpy(), r.ee[:, 2])
    fig = r.plot()
    assert len(fig.axes) == 4
    b = model.rollout(payload_kg=[0.0, 2.0], encoder_t=t, encoder_q=q, sample_rate=100)
    long = b.to_pandas()
    assert len(long) == 2 * len(r)
    assert b.plot("ee_z").axes[0].get_ylabel().startswith("ee_z")
    import matplotlib.pyplot as plt

    plt.close("all")


def test_replay_follows_encoders_exactly(model, encoder_run):
    t, q = encoder_run
    r = model.replay(t, q)  # 500 Hz output = the encoder samples
    np.testing.assert_allclose(r.q, q, atol=1e-12)


def test_replay_torque_matches_torque_driven_run():
    """Torque-driven run → its motor angles replayed → the replay's link-side torque equals
    the applied torque minus armature·q̈, and the bending motion is reproduced."""
    m = popup.Model(dt=5e-4)
    t = np.arange(0, 1.0 + 1e-12, 5e-4)
    tau = m.holding_torque()[None, :] + np.stack([0.5 * np.sin(2 * np.pi * t), 3.0 * np.sin(3 * t), np.sin(5 * t)], axis=1)
    fwd = m.simulate(tau, torque_times=t, duration=1.0, sample_rate=2000)
    rep = m.replay(fwd.time, fwd.q, sample_rate=2000)
    qdd = np.gradient(fwd.dq, fwd.time, axis=0)
    armature = np.asarray(tomllib.loads(m.arm.to_toml())["motors"]["armature_kgm2"])
    expected = tau - armature * qdd
    inner = slice(20, -20)  # spline end conditions
    assert np.max(np.abs(rep.tau[inner] - expected[inner])) < 0.05
    assert np.max(np.abs(rep.bending[inner] - fwd.bending[inner])) < 1e-4


def test_energy_conserved_with_damping_off():
    """Free swing under gravity with springs on, dampers off, zero torque: RK4's energy
    error is small and falls at least ~2^4 per halving of dt."""
    errs = []
    for dt in (2e-3, 1e-3, 5e-4):
        m = popup.Model(dt=dt, disable=["damper"])
        q0 = m.rest_state()
        v0 = np.zeros(7)
        v0[[1, 3, 6]] = (0.3, 0.5, -0.8)
        r = m.simulate(np.zeros(3), duration=1.0, initial_q=q0, initial_v=v0, sample_rate=100)
        assert np.ptp(r.q[:, 1]) > 1.0  # a large swing, not a trivial test
        errs.append(np.max(np.abs(r.energy - r.energy[0])))
    assert errs[-1] < 1e-5  # J
    for a, b in zip(errs, errs[1:]):
        assert a / b > 12


def test_jobs_that_differ_in_friction_and_delays_only_share_one_motion_with_the_same_bits(encoder_run):
    """Friction, saturation and the sensor groups' delays do not move the arm in replay: a
    batch of them runs the physics once, and later batches of that motion none (a fit's
    next steps); every array the same bits as a fresh model running each job alone."""
    from popup import effects as fx

    t, q = encoder_run
    rng = np.random.default_rng(4)
    model = popup.Model("popup-lab", payload_kg=1.0)

    def flat(k):
        f = model.effects_flat.copy()
        f[fx.EFFECTS["joint_friction"].params["tau_c"].slice] = rng.uniform(0.0, 3.0, 3)
        f[fx.EFFECTS["joint_friction"].params["b"].slice] = rng.uniform(0.0, 0.5, 3)
        if k % 2:
            f[fx.EFFECTS["joint_friction"].params["tau_s"].slice] = rng.uniform(0.0, 1.0, 3)
            f[fx.EFFECTS["sensor_delay"].params["imu"].slice] = rng.uniform(0.0, 0.02)
        if k % 3 == 2:
            f[fx.EFFECTS["actuator_saturation"].params["tau_max"].slice] = [8.0, 15.0, np.inf]
        return f

    flats = np.stack([flat(k) for k in range(6)])
    batch = model.rollout(encoder_t=t, encoder_q=q, effects=flats[:4], threads=2)
    later = [model.rollout(encoder_t=t, encoder_q=q, effects=flats[k : k + 1], threads=1) for k in (4, 5)]
    assert model.core.motion_hits == 2
    for k in range(6):
        alone = popup.Model("popup-lab", payload_kg=1.0).rollout(encoder_t=t, encoder_q=q, effects=flats[k : k + 1])
        got = batch.data[k] if k < 4 else later[k - 4].data[0]
        np.testing.assert_array_equal(got, alone.data[0])
    assert not np.array_equal(batch.data[0], batch.data[1])
    # another payload moves the arm: its own run, no motion shared
    model.rollout(encoder_t=t, encoder_q=q, effects=flats[:1], payload_kg=1.5)
    assert model.core.motion_hits == 2

"""One simulation: state arrays, stepping, the history against the CLI's, callbacks,
failures as results, Ctrl-C and the GIL."""

import csv
import os
import signal
import threading
import time

import numpy as np
import pytest

import cosserat


def frame_sim(**kw):
    return cosserat.Simulation(cosserat.Scene.builtin("frame"), **kw)


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(x) for x in r] for r in rows[1:]])


def test_state_arrays_have_numpy_shapes_and_dtypes():
    sim = frame_sim()
    n = cosserat.Scene.builtin("frame").nodes
    for a, shape in (
        (sim.positions, (n, 3)),
        (sim.velocities, (n, 3)),
        (sim.directors, (n, 3, 3)),
    ):
        assert a.dtype == np.float64 and a.shape == shape
    # Each node's directors are an orthonormal triad.
    d = sim.directors
    eye = np.einsum("aki,ali->akl", d, d)
    assert np.abs(eye - np.eye(3)).max() < 1e-14
    assert sim.t == 0.0 and sim.steps == 0 and sim.status == "ready"


def test_frame_history_equals_the_cli_history_csv(cli, tmp_path):
    cli("run", "frame", "--scheme", "edmc2", "--alpha", "0.5", "--out", tmp_path)
    header, rows = read_csv(tmp_path / "history.csv")
    sim = frame_sim(scheme="edmc2", alpha=0.5)
    summary = sim.run()
    assert summary["status"] == "completed"
    h = sim.history
    assert list(h.keys()) == header
    assert h.rows == len(rows)
    for c, name in enumerate(header):
        # Written with the shortest round-trip decimals: equal to the last bit.
        np.testing.assert_array_equal(np.asarray(h[name], dtype=float), rows[:, c], err_msg=name)
    assert h["step"].dtype == np.int64 and h["total"].dtype == np.float64


def test_step_by_step_equals_one_run():
    a, b = frame_sim(), frame_sim()
    for _ in range(7):
        assert a.step() is True
    b.run(t_end=7 * b.dt)
    assert a.steps == b.steps == 7
    assert a.t == pytest.approx(7 * a.dt, rel=0, abs=1e-15)
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.history["total"], b.history["total"])
    # Continuing a run reaches the scene's end time with its step count.
    b.run()
    assert b.steps == round(b.summary["t_end"] / b.dt)


def test_every_thins_the_history_and_keeps_the_last_step():
    sim = frame_sim()
    sim.run(t_end=2.0, every=3)
    steps = list(sim.history["step"])
    assert steps == [0, 3, 6, 9, 10]


def test_writable_velocities_scale_the_kinetic_energy():
    sim = frame_sim()
    k0 = sim.energy["kinetic"]
    sim.velocities = 2.0 * sim.velocities
    # The director velocities are untouched: K is quadratic in (v, ẇ), so check it grew.
    assert sim.energy["kinetic"] > k0
    v = np.zeros_like(sim.velocities)
    sim.velocities = v
    np.testing.assert_array_equal(sim.velocities, v)
    assert sim.history["kinetic"][0] == sim.energy["kinetic"]
    with pytest.raises(ValueError, match="shape"):
        sim.velocities = np.zeros((2, 3))


def test_supported_nodes_refuse_a_velocity():
    sim = cosserat.Simulation(cosserat.Scene.builtin("cantilever"))
    v = np.ones_like(sim.velocities)
    with pytest.raises(ValueError, match="supported"):
        sim.velocities = v


def test_callback_sees_records_and_can_stop_the_run():
    sim = frame_sim()
    seen = []

    def cb(rec):
        seen.append(rec["step"])
        return rec["step"] < 4

    s = sim.run(callback=cb)
    assert s["status"] == "stopped" == sim.status
    assert seen == [1, 2, 3, 4] and sim.steps == 4


def test_newton_failure_is_a_result_not_an_exception():
    scene = cosserat.Scene.builtin("frame")
    scene.set("integrator.max_iter", 1)
    sim = cosserat.Simulation(scene)
    s = sim.run()
    assert s["status"] == "failed" == sim.status
    assert "failed" in s["reason"] and sim.reason == s["reason"]
    # The state stays at the last accepted step, which ends the history.
    assert sim.history["step"][-1] == sim.steps
    assert np.isfinite(sim.positions).all()
    assert sim.step() is False


def test_bad_options_raise_value_error():
    scene = cosserat.Scene.builtin("frame")
    with pytest.raises(ValueError, match="unknown scheme"):
        cosserat.Simulation(scene, scheme="rk4")
    with pytest.raises(ValueError, match="alpha"):
        cosserat.Simulation(scene, alpha=-1.0)
    with pytest.raises(ValueError, match="alpha sets the EDMC-2"):
        cosserat.Simulation(scene, scheme="em", alpha=0.5)
    with pytest.raises(ValueError, match="backend"):
        cosserat.Simulation(scene, backend="tpu")
    with pytest.raises(ValueError, match="dt"):
        cosserat.Simulation(scene, dt=0.0)


def test_summary_and_pandas():
    sim = frame_sim()
    s = sim.run(t_end=1.0)
    for k in ("status", "t_reached", "steps", "energy_initial", "energy_final", "newton_iters_total"):
        assert k in s
    assert s["steps"] == 5 and s["t_reached"] == pytest.approx(1.0)
    pd = pytest.importorskip("pandas")
    df = sim.history.to_pandas()
    assert isinstance(df, pd.DataFrame) and len(df) == 6


def long_cantilever():
    scene = cosserat.Scene.builtin("cantilever")
    scene.set("integrator.t_end", 1000.0)
    return cosserat.Simulation(scene)


def test_ctrl_c_stops_at_the_last_accepted_step():
    sim = long_cantilever()
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            sim.run()
    finally:
        timer.cancel()
    assert sim.status == "interrupted"
    assert 0 < sim.steps < 100_000
    assert sim.history["step"][-1] == sim.steps
    assert sim.t == pytest.approx(sim.steps * sim.dt)
    # The simulation goes on from there.
    n = sim.steps
    assert sim.step() and sim.steps == n + 1


def test_a_run_releases_the_gil():
    sim = long_cantilever()
    ticks = []
    stop = threading.Event()

    def count():
        while not stop.is_set():
            ticks.append(1)
            time.sleep(0.001)

    th = threading.Thread(target=count)
    th.start()
    try:
        before = len(ticks)
        sim.run(t_end=1.0)
        during = len(ticks) - before
    finally:
        stop.set()
        th.join()
    # 100 steps of the 50-element cantilever take well over 10 ms; a run holding the
    # GIL would let the counter tick at most at its few signal checks.
    assert during > 5, during


def test_trajectory_equals_the_cli_trajectory_npz(cli, tmp_path):
    cli("run", "frame", "--trajectory", "--every", "5", "--out", tmp_path)
    ref = np.load(tmp_path / "trajectory.npz")
    sim = frame_sim(trajectory=True)
    sim.run(every=5)
    tr = sim.trajectory
    n = cosserat.Scene.builtin("frame").nodes
    assert tr["positions"].shape == (len(tr["times"]), n, 3)
    assert tr["directors"].shape == (len(tr["times"]), n, 3, 3)
    for k in ("times", "steps", "positions", "velocities", "directors"):
        np.testing.assert_array_equal(tr[k], ref[k], err_msg=k)
    np.testing.assert_array_equal(tr["positions"][-1], sim.positions)
    with pytest.raises(ValueError, match="trajectory=True"):
        frame_sim().trajectory

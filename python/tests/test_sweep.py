"""Sweeps: the members equal `cosserat sweep`'s, resume, the GPU path on lavapipe, the
progress lines, and Ctrl-C stopping a sweep cleanly (resumable)."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import cosserat

GRID = {"integrator.alpha": [0.0, 0.25, 0.5, 1.0], "initial_velocity[1].v[2]": [1.0, 2.0]}


def short_frame():
    s = cosserat.Scene.builtin("frame")
    s.set("integrator.t_end", 2.0)
    return s


def cli_sweep(cli, tmp_path):
    spec = tmp_path / "cli.toml"
    spec.write_text(
        'base = "frame"\nmode = "grid"\n'
        '[[vary]]\nkey = "integrator.t_end"\nvalues = [2.0]\n'
        '[[vary]]\nkey = "integrator.alpha"\nvalues = [0.0, 0.25, 0.5, 1.0]\n'
        '[[vary]]\nkey = "initial_velocity[1].v[2]"\nvalues = [1.0, 2.0]\n'
    )
    cli("sweep", spec, "--out", tmp_path / "cli", "--backend", "cpu")
    return cosserat.read_members(tmp_path / "cli" / "members.csv")


def compare(a, b, rtol):
    assert list(a.keys()) == list(b.keys())
    for k in a:
        if k == "wall_s":
            continue
        if isinstance(a[k], list):
            assert a[k] == b[k], k
        elif rtol == 0:
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
        else:
            np.testing.assert_allclose(a[k], b[k], rtol=rtol, atol=0, err_msg=k)


def test_eight_members_equal_the_cli_sweep(cli, tmp_path):
    ref = cli_sweep(cli, tmp_path)
    t = cosserat.sweep(short_frame(), GRID, backend="cpu", out=tmp_path / "py")
    assert t.rows == 8
    assert t["status"] == ["completed"] * 8
    compare(t, ref, rtol=0)
    # Resuming a finished sweep runs nothing and returns the same table.
    again = cosserat.sweep(short_frame(), GRID, backend="cpu", out=tmp_path / "py", resume=True)
    compare(again, t, rtol=0)
    np.testing.assert_array_equal(again["wall_s"], t["wall_s"])


def test_list_mode_and_rejected_members(tmp_path):
    t = cosserat.sweep(
        short_frame(), {"integrator.dt": [0.1, -0.1]}, mode="list", backend="cpu", out=tmp_path
    )
    assert t["status"] == ["completed", "rejected"]
    assert "integrator.dt" in t["reason"][1]
    pd = pytest.importorskip("pandas")
    assert len(t.to_pandas()) == 2


def test_bad_sweep_arguments():
    with pytest.raises(ValueError, match="mode"):
        cosserat.sweep(short_frame(), GRID, mode="random")
    with pytest.raises(ValueError, match="empty"):
        cosserat.sweep(short_frame(), {})
    with pytest.raises(cosserat.SceneError, match="no_such"):
        cosserat.sweep(short_frame(), {"no_such.key": [1.0]}, backend="cpu")


def test_gpu_sweep_equals_the_cpu_sweep(tmp_path):
    try:
        g = cosserat.sweep(short_frame(), GRID, backend="gpu", out=tmp_path / "gpu")
    except RuntimeError as e:
        if os.environ.get("COSSERAT_REQUIRE_GPU") == "1" or "adapter" not in str(e):
            raise
        pytest.skip(f"no GPU adapter: {e}")
    c = cosserat.sweep(short_frame(), GRID, backend="cpu", out=tmp_path / "cpu")
    assert g["status"] == c["status"] == ["completed"] * 8
    # The GPU path runs EDMC-2 with the staggered strategy, the CPU path the monolithic
    # Newton: they agree to the staggered loop's outer tolerance (1e-10 of the
    # dissipation identity; tests/gpu_batch.rs measures final energies 1.1e-10 apart).
    for k in ("t_reached", "final_total"):
        np.testing.assert_allclose(g[k], c[k], rtol=1e-9, atol=0, err_msg=k)
    np.testing.assert_array_equal(g["member"], c["member"])


def test_progress_lines_go_to_stderr(capfd, tmp_path):
    t = cosserat.sweep(
        short_frame(), {"integrator.alpha": [0.0, 0.5, 1.0]}, backend="cpu", out=tmp_path,
        progress=True,
    )
    assert t.rows == 3
    err = capfd.readouterr().err
    # stderr is not a terminal here: plain lines instead of a bar, the last one at 3/3.
    assert "sweep: 3/3  completed 3, failed 0, rejected 0" in err, err
    sim = cosserat.Simulation(cosserat.Scene.builtin("frame"))
    sim.run(t_end=4.0, progress=True)
    lines = [l for l in capfd.readouterr().err.splitlines() if l.startswith("frame: ")]
    assert lines[-1].startswith("frame: 20/20  t = 4.0000"), lines
    assert len(lines) == 10  # one per tenth of the way


def test_ctrl_c_stops_a_sweep_cleanly_and_resume_completes_it(tmp_path):
    # Members run in groups of twice the worker threads; Ctrl-C (sent from a thread when
    # the first row is recorded) lets the group under way finish, starts no other.
    threads = int(os.environ.get("RAYON_NUM_THREADS") or os.cpu_count() or 1)
    n = 4 * threads
    scene = cosserat.Scene.builtin("frame")
    scene.set("integrator.t_end", 20.0)
    grid = {"integrator.alpha": list(np.linspace(0.0, 1.0, n))}
    csv = tmp_path / "members.csv"

    def rows():
        if not csv.exists():
            return 0
        return max(0, len(csv.read_text().splitlines()) - 1)

    def interrupt():
        while rows() == 0:
            time.sleep(0.002)
        os.kill(os.getpid(), signal.SIGINT)

    th = threading.Thread(target=interrupt, daemon=True)
    th.start()
    with pytest.raises(KeyboardInterrupt, match="resume=True"):
        cosserat.sweep(scene, grid, backend="cpu", out=tmp_path)
    th.join(timeout=60)
    kept = cosserat.read_members(csv)
    assert 0 < kept.rows < n, kept.rows
    assert kept["status"] == ["completed"] * kept.rows
    t = cosserat.sweep(scene, grid, backend="cpu", out=tmp_path, resume=True)
    assert t.rows == n and t["status"] == ["completed"] * n
    np.testing.assert_array_equal(t["member"], np.arange(n))
    # The rows kept from before the interruption are the same rows.
    for k in ("member", "t_reached", "final_total", "wall_s"):
        np.testing.assert_array_equal(t[k][kept["member"]], kept[k], err_msg=k)

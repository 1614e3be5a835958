"""sim.run() against the command's in-program time, and the cost of sim.step() from Python.

    python python/bench/bench_run.py [PATH/TO/cosserat] [REPEATS]

For the frame and the 50-element cantilever (t_end shortened to 2 s) it interleaves, REPEATS
times (default 5): `cosserat run` (its `summary.json` wall_s: the time loop, without start-up
and chart drawing), `sim.run()` (its summary wall_s and the wall time of the call) and the
same steps as a Python loop of `sim.step()`. Prints medians; the step overhead is
(step loop − run) / steps.
"""

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import cosserat

exe = sys.argv[1] if len(sys.argv) > 1 else os.path.join("target", "release", "cosserat")
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 5

for name, t_end in (("frame", None), ("cantilever", 2.0)):
    scene = cosserat.Scene.builtin(name)
    if t_end:
        scene.set("integrator.t_end", t_end)
    cli, run, call, loop = [], [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory() as d:
            args = [exe, "run", name, "--out", d] + (["--t-end", str(t_end)] if t_end else [])
            subprocess.run(args, check=True, capture_output=True)
            with open(os.path.join(d, "summary.json")) as f:
                cli.append(json.load(f)["wall_s"])
        sim = cosserat.Simulation(scene)
        t0 = time.perf_counter()
        s = sim.run()
        call.append(time.perf_counter() - t0)
        run.append(s["wall_s"])
        steps = s["steps"]
        sim = cosserat.Simulation(scene)
        t0 = time.perf_counter()
        for _ in range(steps):
            sim.step()
        loop.append(time.perf_counter() - t0)
    m = statistics.median
    print(
        f"{name}: {steps} steps; cli {m(cli) * 1e3:.2f} ms, sim.run() {m(run) * 1e3:.2f} ms "
        f"(call {m(call) * 1e3:.2f} ms, ratio {m(run) / m(cli):.3f}); step loop {m(loop) * 1e3:.2f} ms, "
        f"overhead {(m(loop) - m(run)) / steps * 1e6:.2f} µs/step"
    )

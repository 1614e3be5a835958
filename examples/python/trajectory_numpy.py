"""A trajectory post-processed with NumPy: the free-flying frame stepped from Python, its
node positions stacked into a [T, nodes, 3] array, the centre of mass and the spread of
the nodes about it computed with NumPy.

    python examples/python/trajectory_numpy.py
"""

import numpy as np

import cosserat

scene = cosserat.Scene.builtin("frame")
sim = cosserat.Simulation(scene, scheme="edmc2", alpha=0.5)
frames = [sim.positions]
while sim.t < scene.t_end - 0.5 * sim.dt:
    if not sim.step():
        raise SystemExit(f"failed: {sim.reason}")
    frames.append(sim.positions)
x = np.stack(frames)  # [T, nodes, 3]
t = sim.history["t"]
assert x.shape == (len(t), scene.nodes, 3)

# The frame flies freely: with equal element masses the node average is not the centre of
# mass, but its velocity is nearly constant; fit a line and report the residual.
c = x.mean(axis=1)  # [T, 3]
fit = np.polyfit(t, c, 1)  # [2, 3]
resid = np.abs(c - (np.outer(t, fit[0]) + fit[1])).max()
spread = np.linalg.norm(x - c[:, None, :], axis=2).max(axis=1)  # [T]
print(f"{len(t)} frames; node-average velocity {fit[0]}, max line residual {resid:.3g}")
print(f"largest node distance from the node average: {spread.min():.4f} … {spread.max():.4f}")
h = sim.history["total"]
assert np.all(np.diff(h) <= 1e-12 * h[0]), "EDMC-2 energy must not grow"
print(f"H: {h[0]:.6f} → {h[-1]:.6f} (EDMC-2, α = 0.5)")

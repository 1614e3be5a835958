"""A controller in the loop: a flexible arm whose clamp is carried sideways by a PD
controller (from Python, every step) so that the arm's free tip reaches a target, then a
second one. The controller reads the tip's position and velocity and commands the clamp's
velocity; the engine books the clamp's work W (and the damping's dissipation D), so the
energy balance H - H0 = W - D still closes to round-off and Newton's tolerance.

    python examples/python/clamp_controller.py [OUT_DIR]

Writes OUT_DIR/clamp_controller.png (default: out/python) without opening a window.
"""

import os
import sys

import matplotlib

matplotlib.use("Agg")  # files only, no window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import cosserat  # noqa: E402

out = sys.argv[1] if len(sys.argv) > 1 else os.path.join("out", "python")
os.makedirs(out, exist_ok=True)

# A 1 m arm along e1 (first bending mode ≈ 1.8 Hz) with a little Kelvin-Voigt damping,
# clamped at the origin; the clamp is made drivable with `controlled=`.
scene = cosserat.Scene.from_toml(
    """
name = "flexible arm"
[material.m]
E = 1e8
nu = 0.5
density = 1000
damping = 0.02
[section.s]                    # circle R = 0.02
A = 1.2566370614359173e-3
I11 = 1.2566370614359173e-7
I22 = 1.2566370614359173e-7
J = 2.5132741228718346e-7
[[rod]]
name = "arm"
material = "m"
section = "s"
points = [[0, 0, 0], [1, 0, 0]]
elements = 20
d1 = [0, 0, 1]
[[clamp]]
at = [0, 0, 0]
[integrator]
scheme = "em"
dt = 0.005
t_end = 6.0
"""
)
sim = cosserat.Simulation(scene, controlled=[[0, 0, 0]])
tip = scene.nodes - 1
kp, kd = 2.0, 0.5  # 1/s and 1 (clamp velocity per tip error, per tip velocity)


def target(t):
    """Where the tip should be (its e2 coordinate): 0.2 m, then back to 0.05 m at t = 3 s."""
    return 0.2 if t < 3.0 else 0.05


t, tip_y, clamp_y, goal = [0.0], [0.0], [0.0], [target(0.0)]
while sim.t < scene.t_end - 1e-9:
    error = target(sim.t) - sim.positions[tip, 1]
    v_clamp = kp * error - kd * sim.velocities[tip, 1]
    sim.set_support(0, velocity=[0.0, v_clamp, 0.0])  # held over the next step
    assert sim.step(), sim.reason
    t.append(sim.t)
    tip_y.append(sim.positions[tip, 1])
    clamp_y.append(sim.positions[0, 1])
    goal.append(target(sim.t))

h = sim.history
balance = h["total"] - h["total"][0] - h["work_total"] + h["dissipation_total"]
print(
    f"{sim.steps} steps; tip at {tip_y[-1]:.4f} m (target {goal[-1]} m); "
    f"clamp work {h['work_total'][-1]:.3e} J, dissipated {h['dissipation_total'][-1]:.3e} J; "
    f"max |H - H0 - W + D| = {np.abs(balance).max():.1e} J"
)

fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
ax1.plot(t, goal, "k--", lw=1, label="target")
ax1.plot(t, tip_y, label="tip")
ax1.plot(t, clamp_y, label="clamp (commanded)")
ax1.set_xlabel("t (s)")
ax1.set_ylabel("e2 position (m)")
ax1.set_title("PD control of the tip through the clamp")
ax1.legend()
ax2.plot(h["t"], h["total"] - h["total"][0], label="H - H0")
ax2.plot(h["t"], h["work_total"], "--", label="W (clamp work)")
ax2.plot(h["t"], h["dissipation_total"], ":", label="D (damping)")
ax2.set_xlabel("t (s)")
ax2.set_ylabel("J")
ax2.set_title("energy balance H - H0 = W - D")
ax2.legend()
fig.tight_layout()
path = os.path.join(out, "clamp_controller.png")
fig.savefig(path, dpi=100)
print(f"chart in {path}")

# The tip settles on the second target; the clamp's work closes the balance.
assert abs(tip_y[-1] - goal[-1]) < 0.01, tip_y[-1]
scale = max(np.abs(h["total"]).max(), np.abs(h["work_total"]).max())
# (round-off and the Newton tolerance over 1200 steps: measured 1.5e-12 relative)
assert np.abs(balance).max() <= 1e-10 * scale, np.abs(balance).max()

"""A controller in the loop: loads and support motions set between steps. A load set
before every step gives bit for bit the trajectory of a scene whose load table is that
piecewise-constant function, and EM closes the energy balance with its work; a
commanded clamp sits at its targets; bad commands raise ValueError naming the reason."""

import numpy as np
import pytest

import cosserat

DT = 0.01
STEPS = 30


def rod(extra, scheme="em"):
    """A 1 m rod along e1 (10 elements, E = 1e6, ρ = 1000, round R = 0.02) with `extra`."""
    return cosserat.Scene.from_toml(
        f"""
name = "control"
[material.m]
E = 1e6
nu = 0.5
density = 1000
[section.s]
A = 1.2566370614359173e-3
I11 = 1.2566370614359173e-7
I22 = 1.2566370614359173e-7
J = 2.5132741228718346e-7
[[rod]]
name = "beam"
material = "m"
section = "s"
points = [[0, 0, 0], [1, 0, 0]]
elements = 10
d1 = [0, 1, 0]
{extra}
[integrator]
scheme = "{scheme}"
dt = {DT!r}
t_end = {DT * STEPS!r}
"""
    )


def force(k):
    return 0.05 * np.sin(0.7 * k) + 0.02


CLAMP = "[[clamp]]\nat = [0, 0, 0]\n"
TIP_LOAD = "[[load]]\nat = [1, 0, 0]\nforce = [0, 0, -1]\n"


@pytest.mark.parametrize("scheme", ["em", "edmc2"])
def test_a_load_set_between_steps_equals_its_piecewise_table(scheme):
    times, factors = [], []
    for k in range(STEPS):
        times += [k * DT, (k + 1) * DT]
        factors += [force(k), force(k)]
    table = rod(
        CLAMP + TIP_LOAD + f"time = {times!r}\nfactor = {[float(f) for f in factors]!r}\n",
        scheme,
    )
    a = cosserat.Simulation(table)
    b = cosserat.Simulation(rod(CLAMP + TIP_LOAD, scheme))
    assert [l["node"] for l in b.loads] == [10]
    for k in range(STEPS):
        b.set_load(0, force=[0.0, 0.0, -force(k)])
        np.testing.assert_array_equal(b.loads[0]["force"], [0.0, 0.0, -force(k)])
        assert a.step() and b.step()
        np.testing.assert_array_equal(a.positions, b.positions)
    ha, hb = a.history, b.history
    np.testing.assert_array_equal(ha["work_total"], hb["work_total"])
    assert abs(hb["work_total"][-1]) > 1e-4
    if scheme == "em":
        # EM: H − H0 = W to round-off, the controller's work included.
        res = hb["total"] - hb["total"][0] - hb["work_total"]
        scale = max(np.abs(hb["total"]).max(), np.abs(hb["work_total"]).max())
        assert np.abs(res).max() <= 1e-13 * scale


def test_an_added_load_at_a_position_is_a_scene_load():
    a = cosserat.Simulation(rod(CLAMP + "[[load]]\nat = [1, 0, 0]\nforce = [0, 0.03, 0]\n"))
    b = cosserat.Simulation(rod(CLAMP))
    assert b.add_load([1.0, 0.0, 0.0], force=np.array([0.0, 0.03, 0.0])) == 0
    a.run(t_end=0.1)
    b.run(t_end=0.1)
    np.testing.assert_array_equal(a.positions, b.positions)


def test_a_controlled_clamp_sits_at_its_targets_and_closes_the_balance():
    sim = cosserat.Simulation(rod(CLAMP + "[[clamp]]\nat = [1, 0, 0]\n"), controlled=[[1, 0, 0]])
    sup = {s["node"]: s for s in sim.supports}
    assert sup[0]["kind"] == "clamp" and not sup[0]["driven"]
    assert sup[10]["driven"]
    np.testing.assert_array_equal(sup[10]["rotation"], np.eye(3))
    for k in range(1, STEPS + 1):
        x = k / STEPS
        p = [1.0 - 0.05 * x, 0.03 * np.sin(3 * x), 0.02 * x]
        sim.set_support(10, position=p, rotation=[0.4 * x, 0.0, 0.0])
        assert sim.step()
        np.testing.assert_allclose(sim.positions[10], p, rtol=0, atol=1e-15)
    tip = {s["node"]: s for s in sim.supports}[10]
    # Turned by 0.4 rad about e1: d2, d3 of the tip turned so.
    c, s = np.cos(0.4), np.sin(0.4)
    np.testing.assert_allclose(tip["rotation"], [[1, 0, 0], [0, c, -s], [0, s, c]], atol=1e-14)
    h = sim.history
    assert np.abs(h["support_work"]).max() > 0
    res = h["total"] - h["total"][0] - h["work_total"]
    scale = max(np.abs(h["total"]).max(), np.abs(h["work_total"]).max())
    assert np.abs(res).max() <= 1e-13 * scale
    # A velocity command holds until changed.
    sim.set_support(10, velocity=[0.0, 0.0, 0.1])
    z = sim.positions[10, 2]
    sim.run(t_end=sim.t + 5 * DT)
    assert sim.positions[10, 2] == pytest.approx(z + 5 * DT * 0.1, abs=1e-15)


def test_bad_commands_raise_value_error():
    sim = cosserat.Simulation(rod(CLAMP + "[[pin]]\nat = [1, 0, 0]\n"), controlled=[10])
    with pytest.raises(ValueError, match="not a driven support"):
        sim.set_support(0, velocity=[0, 0, 1])
    with pytest.raises(ValueError, match="a pin leaves the rotation free"):
        sim.set_support(10, angular_velocity=[1, 0, 0])
    with pytest.raises(ValueError, match="not a node"):
        sim.set_support([0.55, 0, 0], velocity=[0, 0, 1])
    with pytest.raises(ValueError, match="no such load"):
        sim.set_load(0, force=[1, 0, 0])
    with pytest.raises(ValueError, match="force: expected 3 numbers"):
        sim.add_load(3, force=[1, 0])
    with pytest.raises(ValueError, match="position or a velocity, not both"):
        sim.set_support(10, position=[1, 0, 0], velocity=[0, 0, 1])
    with pytest.raises(ValueError, match="controlled: node 5: not a support"):
        cosserat.Simulation(rod(CLAMP), controlled=[5])
    with pytest.raises(ValueError, match="gen-alpha"):
        cosserat.Simulation(rod(CLAMP), scheme="gen-alpha", controlled=[0])

"""cosserat as a solver of the cosseratbench suite (cosseratbench >= 0.3), in process.

The package declares the entry point `cosseratbench.solvers: cosserat`, so with both
installed::

    cosseratbench run cantilever -s cosserat

runs the experiment through `CosseratSolver`: each scenario is translated into a cosserat
scene (`scene_toml`), run by the engine in this process exactly as `cosserat run SCENE
--output-dt DT --cosseratbench` runs it, and its `cosseratbench/trajectory.npz` (node
positions and each element's d1, the exporter of the command) is handed back to the suite
as its `Trajectory`. A run that fails is `Diverged` at the time it reached.

The translation is the one docs/scenes.md offers a user: each rod's stress-free reference
is straight (the suite's rods are), along its mean direction, with `d1` its `normal`; the
start shape, pre-stretch included, goes to `[rod.initial] positions`; supports, end loads,
gravity, obstacles and contact map key for key; EM throughout. Quasi-static experiments
(the suite lets a solver add dissipation to reach equilibrium) get Kelvin-Voigt damping
η = Δt/2 and drag that makes the suite's slowest mode (frequency ω) critically damped
(docs/scenes.md, "Material damping"): `2 ω ρA` where that mode swings under gravity (the
viscous stresses hardly see it), `2 ω ρA (1 − η ω / 2)` where it is a bending mode, whose
ratio η ω / 2 from the viscous stresses adds to the drag's. Contact stiffness is
cosserat's default; friction against obstacles uses the elastic-stick law
(`friction_law = "stick"`, tangential stiffness the contact stiffness), the one
docs/scenes.md offers for a load that must hold; FRICTION_LAW=regularized in the
environment writes the regularized law at its default slip speed instead. Frictionless
contact between two rods (the crossing) uses the smooth contact model. A driven
sliding end (twist) is a driven `[[clamp]]` with `slide` along a coordinate axis.
Rods that may turn far per element (self contact, a turned end: the pile, the twist) get
`curvature_measure = "rational"` (docs/scenes.md); CURVATURE_MEASURE=sine or =rational in
the environment sets every rod's measure instead.

This module imports the engine only when a run starts, so scripts/cosseratbench_scene.py
can load it without the compiled extension.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path

import numpy as np
from cosseratbench.scenario import Cylinder, End, EndCondition, Scenario
from cosseratbench.solver import Capability, Diverged
from cosseratbench.trajectory import Trajectory


def steps_per_frame(sc: Scenario) -> int:
    """Time steps per frame of the suite: the settings a user picks from docs/scenes.md
    (a step that resolves the motion asked about, larger for quasi-static). Dynamics
    (the pendulum) and contact against obstacles or between rods: 20; a driven end (the
    twist): 5; a quasi-static rod on its own (cantilever, catenary): 1."""
    moving = any(rod.motion(e) is not None for rod in sc.rods for e in End)
    if not sc.quasi_static or sc.obstacles:
        return 20
    if moving:
        return 5
    if len(sc.rods) > 1:
        return 20
    return 1


def curvature_measure(sc: Scenario) -> str:
    """The rods' curvature measure (docs/scenes.md, "Curvature measure"): `rational`
    where a rod may turn far per element: it folds onto itself (self contact: the pile)
    or an end is turned (the twist); `sine`, the default, elsewhere (one element at a time
    costs the rational measure 1.2–2.5x the wall time where its accuracy is not needed)."""
    turned = any(
        (mo := rod.motion(e)) is not None and np.abs(np.asarray(mo.rotation)).max() > 0
        for rod in sc.rods
        for e in End
    )
    return "rational" if sc.self_contact or turned else "sine"


def drag_rate(sc: Scenario, dt: float) -> float:
    """The drag per unit mass, c/(ρA), of a quasi-static scene: critical damping of the
    suite's slowest mode ω (`Scenario.slowest_frequency`) together with the Kelvin-Voigt
    damping η = Δt/2. A mode damped by drag c and by η has the ratio c/(2ωρA) + ηω/2
    (docs/scenes.md, "Material damping"), the second only where the mode strains the rod:
    a bending mode (the suite's bending estimate is the slowest), not a pendulum swing."""
    g = float(np.linalg.norm(sc.gravity))
    # The suite's estimate per rod (Scenario.slowest_frequency): the larger of its first
    # bending frequency and its pendulum frequency; the slowest rod's decides.
    modes = []
    for rod in sc.rods:
        m = rod.material
        bending = 3.516 * math.sqrt(
            m.youngs_modulus * rod.second_moment_of_area / (m.density * rod.area)
        ) / rod.length**2
        pendulum = math.sqrt(g / rod.length)
        modes.append((max(bending, pendulum), bending >= pendulum))
    omega, elastic = min(modes)
    eta = dt / 2
    return 2.0 * omega * max(1.0 - eta * omega / 2.0, 0.0) if elastic else 2.0 * omega


def vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def node_rotations(chords, normal, t0, d1):
    """Rotation vectors carrying the reference triad (d1, t0 × d1, t0) to each node's
    initial triad: tangent the bisector of its chords (the end chord at an end), d1 the
    suite's `normal` at the first node, carried along by parallel transport."""
    tangents = np.vstack([chords[:1], chords[:-1] + chords[1:], chords[-1:]])
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    ref = np.column_stack([d1, np.cross(t0, d1), t0])
    a = normal - (normal @ tangents[0]) * tangents[0]
    a /= np.linalg.norm(a)
    out = []
    for i, t in enumerate(tangents):
        if i > 0:
            prev = tangents[i - 1]
            axis = np.cross(prev, t)
            sin, cos = np.linalg.norm(axis), prev @ t
            if sin > 1e-14:
                axis /= sin
                a = a * cos + np.cross(axis, a) * sin + axis * (axis @ a) * (1.0 - cos)
            a = a - (a @ t) * t
            a /= np.linalg.norm(a)
        rot = np.column_stack([a, np.cross(t, a), t]) @ ref.T
        w = 0.5 * np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
        angle = math.atan2(np.linalg.norm(w), 0.5 * (np.trace(rot) - 1.0))
        if angle > 3.0:
            raise NotImplementedError("a node turned about π from the rod's mean direction")
        sin = np.linalg.norm(w)
        out.append(w * (angle / sin) if sin > 1e-300 else w)
    return out


def motion_table(motion):
    """(displacement, rotation, factors) with the motion = factor × vector, or None."""
    times = np.asarray(motion.times, float)
    d = np.asarray(motion.displacement, float)
    r = np.asarray(motion.rotation, float)
    found = []
    for a in (d, r):
        peak = a[np.argmax(np.linalg.norm(a, axis=1))]
        scale = float(peak @ peak)
        if scale == 0.0:
            found.append((np.zeros(3), None))
            continue
        f = a @ peak / scale
        if np.abs(a - np.outer(f, peak)).max() > 1e-12 * math.sqrt(scale):
            return None
        found.append((peak, f))
    (dv, fd), (rv, fr) = found
    if fd is not None and fr is not None and np.abs(fd - fr).max() > 1e-12:
        return None
    return dv, rv, fd if fd is not None else fr, times


def scene_toml(
    sc: Scenario, n_elements: int, n_frames: int, time_step_scale: float = 1.0, name: str = "scenario"
) -> tuple[str, float]:
    """The cosserat scene of `sc` with `n_elements` elements per rod (TOML text), and the
    spacing of the suite's `n_frames` frames (a whole multiple of the scene's Δt)."""
    n = n_elements
    output_dt = sc.duration / (n_frames - 1)
    dt = output_dt / steps_per_frame(sc) * time_step_scale
    out = [
        f'name = "cb_{name}"',
        f'description = "cosseratbench {name}, {n} elements per rod"',
        f"gravity = {vec(sc.gravity)}",
        "",
    ]
    rate = drag_rate(sc, dt)
    supports, loads = [], []
    for i, rod in enumerate(sc.rods):
        m = rod.material
        nodes = rod.nodes(n)
        chords = np.diff(nodes, axis=0)
        chords /= np.linalg.norm(chords, axis=1, keepdims=True)
        # The straight reference along the rod's mean direction, so that no node turns
        # far from it (a rope draped over a drum turns π from end to end).
        t0 = chords.mean(axis=0)
        t0 = t0 / np.linalg.norm(t0) if np.linalg.norm(t0) > 1e-6 else chords[0]
        start = nodes[0]
        end = start + rod.length * t0
        normal = np.asarray(rod.normal, float)
        d1 = normal - (normal @ t0) * t0
        d1 /= np.linalg.norm(d1)
        area, second = rod.area, rod.second_moment_of_area
        out += [
            f"[material.m{i}]",
            f"E = {m.youngs_modulus!r}",
            f"G = {m.shear_modulus!r}",
            f"density = {m.density!r}",
        ]
        if sc.quasi_static:
            out.append(f"damping = {dt / 2!r}")
        out += [
            "",
            f"[section.s{i}]",
            f"A = {area!r}",
            f"I11 = {second!r}",
            f"I22 = {second!r}",
            f"J = {2 * second!r}",
            "",
            "[[rod]]",
            f'name = "r{i}"',
            f'material = "m{i}"',
            f'section = "s{i}"',
            f"points = [{vec(start)}, {vec(end)}]",
            f"elements = {n}",
            f"d1 = {vec(d1)}",
        ]
        measure = os.environ.get("CURVATURE_MEASURE") or curvature_measure(sc)
        if measure != "sine":
            out.append(f'curvature_measure = "{measure}"')
        if sc.quasi_static:
            out.append(f"drag = {rate * m.density * area!r}")
        out += ["", "[rod.initial]", "positions = [", *(f"  {vec(p)}," for p in nodes), "]"]
        rotations = node_rotations(chords, normal, t0, d1)
        out += ["rotations = [", *(f"  {vec(r)}," for r in rotations), "]", ""]

        at = {End.START: start, End.END: end}
        ends = {e: rod.condition(e) for e in End}
        motions = {e: rod.motion(e) for e in End}
        slide_on, drive_on = {}, {}
        for e, mo in motions.items():
            if mo is None:
                continue
            moving = np.abs(np.asarray(mo.displacement)).max() > 0 or np.abs(
                np.asarray(mo.rotation)
            ).max() > 0
            if mo.slides_along is None:
                drive_on[e] = mo
            elif not moving:
                slide_on[e] = mo.axis
            elif np.count_nonzero(mo.axis) == 1:
                # A coordinate slide can be driven across its axis and turned about it
                # (the suite allows no other motion of a sliding end).
                slide_on[e], drive_on[e] = mo.axis, mo
            else:
                raise NotImplementedError("a clamp that slides and is driven")
        for e in End:
            c = ends[e]
            if c is EndCondition.FREE:
                continue
            block = ["[[clamp]]" if c is EndCondition.CLAMPED else "[[pin]]", f"at = {vec(at[e])}"]
            if e in slide_on:
                block.append(f"slide = {vec(slide_on[e])}")
            if e in drive_on:
                table = motion_table(drive_on[e])
                if table is None:
                    raise NotImplementedError("a motion that is not one vector times a factor")
                dv, rv, f, times = table
                if dv.any():
                    block.append(f"displacement = {vec(dv)}")
                if rv.any():
                    block.append(f"rotation = {vec(rv)}")
                block += [f"time = {vec(times)}", f"factor = {vec(f)}"]
            supports += block + [""]
        for load in rod.loads:
            loads += ["[[load]]", f"at = {vec(at[load.at])}", f"force = {vec(load.force)}", ""]
    out += supports + loads
    for ob in sc.obstacles:
        mu = max([ob.friction] + [r.friction for r in sc.rods])
        if isinstance(ob, Cylinder):
            out += ["[[obstacle]]", 'kind = "cylinder"', f"point = {vec(ob.center)}",
                    f"axis = {vec(ob.axis)}", f"radius = {ob.radius!r}"]
        else:
            out += ["[[obstacle]]", 'kind = "plane"', f"point = {vec(ob.point)}",
                    f"normal = {vec(ob.normal)}"]
        if mu > 0:
            out.append(f"friction = {mu!r}")
            law = os.environ.get("FRICTION_LAW", "stick")
            if law != "regularized":
                out.append(f"friction_law = {law!r}".replace("'", '"'))
        out.append("")
    k = len(sc.rods)
    pairs = [(i, j) for i in range(k) for j in range(i + 1, k)]
    if sc.self_contact:
        pairs += [(i, i) for i in range(k)]
    for i, j in pairs:
        mu = max(sc.rods[i].friction, sc.rods[j].friction)
        rods = f'["r{i}"]' if i == j else f'["r{i}", "r{j}"]'
        out += ["[[contact]]", f"rods = {rods}"]
        if i != j and mu == 0:
            # Frictionless contact between two rods rides on the smooth contact curve
            # (docs/scenes.md): on sphere chains or the polyline a sliding rope settles
            # off-centre next to a node.
            out.append('model = "smooth"')
        if mu > 0:
            out.append(f"friction = {mu!r}")
        out.append("")
    out += ["[integrator]", 'scheme = "em"', f"dt = {dt!r}", f"t_end = {sc.duration!r}", ""]
    return "\n".join(out), output_dt


class CosseratSolver:
    """The cosseratbench adapter of cosserat (entry point `cosserat`): an implicit EM
    integration of the scene `scene_toml` writes, run in process."""

    name = "cosserat"
    capabilities = frozenset(
        {
            Capability.STRETCH,
            Capability.SHEAR,
            Capability.ROD_CONTACT,
            Capability.ROD_FRICTION,
            Capability.CYLINDER_CONTACT,
            Capability.PLANE_CONTACT,
        }
    )

    def __init__(self, time_step_scale: float = 1.0) -> None:
        from importlib.metadata import version

        self.time_step_scale = float(time_step_scale)
        self.backend_version = version("cosserat")

    def settings(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> dict:
        """The numerical choices this adapter makes for a scenario, as it makes them."""
        output_dt = scenario.duration / (n_frames - 1)
        dt = output_dt / steps_per_frame(scenario) * self.time_step_scale
        return {
            "integrator": "energy-momentum (EM, implicit, Newton)",
            "time_step": dt,
            "drag_rate": drag_rate(scenario, dt) if scenario.quasi_static else 0.0,
            "kelvin_voigt_retardation": dt / 2 if scenario.quasi_static else 0.0,
            "contact": "cosserat defaults (docs/scenes.md)",
        }

    def run(self, scenario: Scenario, *, n_elements: int, n_frames: int) -> Trajectory:
        import cosserat

        text, output_dt = scene_toml(scenario, n_elements, n_frames, self.time_step_scale)
        scene = cosserat.Scene.from_toml(text, "cosseratbench scenario")
        with tempfile.TemporaryDirectory(prefix="cosserat-cb-") as out:
            summary = json.loads(
                cosserat._cosserat._run_to_dir(
                    scene, out, output_dt=output_dt, cosseratbench=True
                )
            )
            if summary["status"] != "completed":
                raise Diverged(summary.get("reason") or "failed", time=summary.get("t_reached"))
            return Trajectory.load(Path(out) / "cosseratbench" / "trajectory.npz")

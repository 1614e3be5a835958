"""Nonlinear dynamics of geometrically exact (Cosserat) rods from Python.

The engine is the `cosserat` Rust crate; this package is a thin layer over it:

>>> import cosserat
>>> scene = cosserat.Scene.builtin("frame")
>>> sim = cosserat.Simulation(scene, scheme="edmc2", alpha=0.5)
>>> summary = sim.run()
>>> sim.history["total"]        # energy per recorded step, a NumPy array

See docs/python.md for the whole API.
"""

from __future__ import annotations

import csv
import json
import itertools
import os
import tempfile
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

import numpy as np

from ._cosserat import Scene, SceneError, __version__, builtin_scenes
from ._cosserat import Simulation as _Simulation
from ._cosserat import _bench, _run_sweep

__all__ = [
    "Scene",
    "SceneError",
    "Simulation",
    "History",
    "Table",
    "sweep",
    "bench",
    "read_members",
    "builtin_scenes",
    "__version__",
]


class _Columns(dict):
    """A dict of equally long NumPy arrays, one per column."""

    def to_pandas(self):
        """The columns as a pandas DataFrame (needs pandas installed)."""
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the environment
            raise ImportError("to_pandas() needs pandas: pip install pandas") from e
        return pd.DataFrame({k: v for k, v in self.items()})

    @property
    def rows(self) -> int:
        """Number of rows."""
        for v in self.values():
            return len(v)
        return 0


class History(_Columns):
    """The recorded steps of a simulation: one array per column of `history.csv`."""


class Table(_Columns):
    """The members of a sweep: one array (or list of str) per column of `members.csv`."""


def _vec3(key: str, v) -> Optional[List[float]]:
    """`v` as a list of 3 floats (None stays None)."""
    if v is None:
        return None
    a = np.asarray(v, dtype=np.float64)
    if a.shape != (3,):
        raise ValueError(f"{key}: expected 3 numbers, got shape {a.shape}")
    return a.tolist()


def _at(at):
    """A node index (int) or a reference position (list of 3 floats)."""
    if isinstance(at, (int, np.integer)) and not isinstance(at, bool):
        return int(at)
    return _vec3("at", at)


class Simulation(_Simulation):
    """One simulation of a scene, stepped from Python (see `cosserat._cosserat.Simulation`)."""

    @property
    def velocities(self) -> np.ndarray:
        """Node velocities, float64 [nodes, 3] (a copy); assign any array-like [nodes, 3]."""
        return _Simulation.velocities.__get__(self)

    @velocities.setter
    def velocities(self, v) -> None:
        _Simulation.velocities.__set__(self, np.ascontiguousarray(v, dtype=np.float64))

    def set_load(self, index: int, force=None, moment=None) -> None:
        """Sets load `index` (see `loads`) to a constant force and/or moment [3] from the
        current level on (a part not given keeps its current value)."""
        _Simulation.set_load(self, int(index), _vec3("force", force), _vec3("moment", moment))

    def add_load(self, at, force=None, moment=None) -> int:
        """Adds a constant force and/or moment [3] at `at` (node index or reference
        position) from the current level on; returns its index in `loads`."""
        return _Simulation.add_load(self, _at(at), _vec3("force", force), _vec3("moment", moment))

    def set_support(
        self, at, position=None, rotation=None, velocity=None, angular_velocity=None
    ) -> None:
        """Moves the driven support at `at` (node index or reference position) from the
        current level on: `position` [3] / `rotation` (rotation vector [3] or matrix
        [3, 3]) are reached at the next level and held; `velocity` / `angular_velocity`
        [3] hold until commanded again; a part not given keeps its command."""
        if rotation is not None:
            r = np.asarray(rotation, dtype=np.float64)
            if r.shape not in ((3,), (3, 3)):
                raise ValueError(
                    f"rotation: expected a rotation vector [3] or matrix [3, 3], got shape {r.shape}"
                )
            rotation = r.tolist()
        _Simulation.set_support(
            self,
            _at(at),
            position=_vec3("position", position),
            rotation=rotation,
            velocity=_vec3("velocity", velocity),
            angular_velocity=_vec3("angular_velocity", angular_velocity),
        )

    @property
    def trajectory(self) -> Dict[str, np.ndarray]:
        """The states kept with the history (needs `Simulation(..., trajectory=True)`):
        `times` [T], `steps` [T], `positions`/`velocities` [T, nodes, 3], `directors`
        [T, nodes, 3, 3], as in `trajectory.npz`."""
        return self._trajectory()

    @property
    def history(self) -> History:
        """The recorded steps as a dict of NumPy arrays (columns of `history.csv`)."""
        return History(self._history())


def _sweep_toml(base: str, params: Mapping[str, Sequence[float]], mode: str) -> str:
    lines = [f"base = {_toml_str(base)}", f"mode = {_toml_str(mode)}", ""]
    for key, values in params.items():
        vals = [float(v) for v in np.asarray(values, dtype=float).ravel()]
        if not vals:
            raise ValueError(f"sweep: {key}: no values")
        lines += [
            "[[vary]]",
            f"key = {_toml_str(key)}",
            "values = [" + ", ".join(repr(v) for v in vals) + "]",
            "",
        ]
    return "\n".join(lines)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


_INT_COLUMNS = {"member", "newton_iters_total"}
_STR_COLUMNS = {"status", "reason"}


def read_members(path: Union[str, os.PathLike]) -> Table:
    """Reads a sweep's `members.csv` into a Table sorted by member (empty cells are NaN)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    body.sort(key=lambda r: int(r[0]))
    table = Table()
    for c, name in enumerate(header):
        cells = [r[c] if c < len(r) else "" for r in body]
        if name in _STR_COLUMNS:
            table[name] = cells
        elif name in _INT_COLUMNS:
            table[name] = np.array([int(x) if x else -1 for x in cells], dtype=np.int64)
        else:
            table[name] = np.array([float(x) if x else np.nan for x in cells], dtype=np.float64)
    return table


def sweep(
    scene: Scene,
    params: Mapping[str, Sequence[float]],
    backend: str = "auto",
    mode: str = "grid",
    out: Optional[Union[str, os.PathLike]] = None,
    resume: bool = False,
    adapter: Optional[str] = None,
    histories: bool = False,
    progress: bool = False,
) -> Table:
    """Runs an ensemble of `scene` with the values of `params` ({key path: values}) written
    in, as `cosserat sweep` does: `mode="grid"` (Cartesian product, the first key varying
    slowest) or `"list"` (values zipped). The members run on `backend` (`"cpu"`, `"gpu"`,
    `"auto"`) into the folder `out` (a temporary one when None) with the same files,
    resume and streaming guarantees as the command; returns the rows of `members.csv`
    as a Table (dict of arrays; `to_pandas()`). Values set on `scene` with `Scene.set`
    are varied as single-valued keys ahead of `params`. `progress=True` shows a bar on
    stderr (plain lines when stderr is not a terminal). Ctrl-C stops the sweep cleanly:
    no further member starts, those under way finish and are recorded in `out`, then
    KeyboardInterrupt is raised; `sweep(..., out=the same folder, resume=True)` runs the
    rest.
    """
    if mode not in ("grid", "list"):
        raise ValueError(f"mode: expected 'grid' or 'list', got {mode!r}")
    if not params:
        raise ValueError("sweep: params is empty (expected {key path: [values]})")
    folder = os.fspath(out) if out is not None else tempfile.mkdtemp(prefix="cosserat-sweep-")
    os.makedirs(folder, exist_ok=True)
    base = os.path.join(folder, "base.toml")
    with open(base, "w") as f:
        f.write(scene.text)
    varied: Dict[str, Sequence[float]] = {}
    for key, value in scene.sets:
        if key not in params:
            varied[key] = [value] if mode == "grid" else None  # type: ignore[assignment]
    n = None
    if mode == "list":
        lengths = {len(v) for v in params.values()}
        if len(lengths) != 1:
            raise ValueError("sweep: mode 'list' needs value lists of one length")
        n = lengths.pop()
        varied = {k: [v] * n for k, v in scene.sets if k not in params}
    varied.update(params)
    spec = os.path.join(folder, "sweep.toml")
    with open(spec, "w") as f:
        f.write(_sweep_toml("base.toml", varied, mode))
    try:
        _run_sweep(
            spec,
            folder,
            backend=backend,
            adapter=adapter,
            resume=resume,
            histories=histories,
            progress=progress,
        )
    except KeyboardInterrupt as e:
        raise KeyboardInterrupt(
            f"sweep interrupted: the members finished so far are in {folder}/members.csv; "
            "sweep(..., out=that folder, resume=True) runs the rest"
        ) from e
    return read_members(os.path.join(folder, "members.csv"))


def bench(
    rods: int = 64,
    elements: int = 30,
    steps: int = 20,
    adapter: Optional[str] = None,
    cpu_only: bool = False,
    gpu_only: bool = False,
    newton: str = "full",
    strategy: str = "auto",
    slots: int = 0,
    solve: str = "host",
    host_update: bool = False,
) -> Dict[str, Any]:
    """Times the batch benchmark of `cosserat bench`: the benchmark cantilever as `rods`
    members of `elements` elements over `steps` EDMC-2 steps, on the CPU path and (unless
    `cpu_only`, where a GPU exists) the GPU path. The options are the command's
    (`newton`: full, fresh, modified; `strategy`: auto, staggered, monolithic, inexact;
    `solve`: host, device, both, resident, whole). Returns the dict `cosserat bench --json` prints
    (`cpu_element_steps_per_s`, `gpu_element_steps_per_s`, `ratio`, `adapter`, the stage
    timers, ...). The GIL is released while it runs."""
    return json.loads(
        _bench(
            rods=rods,
            elements=elements,
            steps=steps,
            adapter=adapter,
            cpu_only=cpu_only,
            gpu_only=gpu_only,
            newton=newton,
            strategy=strategy,
            slots=slots,
            solve=solve,
            host_update=host_update,
        )
    )

"""Type stubs of the compiled extension `cosserat._cosserat`."""

from os import PathLike
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

class SceneError(ValueError):
    """An invalid scene or value: message `FILE[:LINE:COL]: KEY: REASON`."""

    file: Optional[str]
    key: Optional[str]
    line: Optional[int]
    column: Optional[int]
    reason: Optional[str]

class Scene:
    @staticmethod
    def builtin(name: str) -> Scene: ...
    @staticmethod
    def load(path: Union[str, PathLike[str]]) -> Scene: ...
    @staticmethod
    def from_toml(text: str, source: str = "<string>") -> Scene: ...
    def set(self, key: str, value: float) -> None: ...
    def copy(self) -> Scene: ...
    def check(self) -> str: ...
    @property
    def text(self) -> str: ...
    @property
    def name(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def sets(self) -> List[Tuple[str, float]]: ...
    @property
    def dt(self) -> float: ...
    @property
    def t_end(self) -> float: ...
    @property
    def scheme(self) -> str: ...
    @property
    def nodes(self) -> int: ...
    @property
    def elements(self) -> int: ...

class Simulation:
    def __init__(
        self,
        scene: Scene,
        scheme: Optional[str] = None,
        alpha: Optional[float] = None,
        rho_inf: Optional[float] = None,
        dt: Optional[float] = None,
        t_end: Optional[float] = None,
        backend: str = "cpu",
        adapter: Optional[str] = None,
        trajectory: bool = False,
        controlled: Optional[Sequence[Union[int, Sequence[float]]]] = None,
    ) -> None: ...
    def step(self) -> bool: ...
    def run(
        self,
        t_end: Optional[float] = None,
        every: int = 1,
        callback: Optional[Callable[[Dict[str, Any]], Optional[bool]]] = None,
        progress: bool = False,
    ) -> Dict[str, Any]: ...
    @property
    def status(self) -> str: ...
    @property
    def reason(self) -> Optional[str]: ...
    @property
    def t(self) -> float: ...
    @property
    def steps(self) -> int: ...
    @property
    def dt(self) -> float: ...
    @property
    def positions(self) -> npt.NDArray[np.float64]: ...
    @property
    def velocities(self) -> npt.NDArray[np.float64]: ...
    @velocities.setter
    def velocities(self, v: npt.ArrayLike) -> None: ...
    @property
    def directors(self) -> npt.NDArray[np.float64]: ...
    @property
    def energy(self) -> Dict[str, float]: ...
    @property
    def loads(self) -> List[Dict[str, Any]]: ...
    def set_load(
        self,
        index: int,
        force: Optional[npt.ArrayLike] = None,
        moment: Optional[npt.ArrayLike] = None,
    ) -> None: ...
    def add_load(
        self,
        at: Union[int, npt.ArrayLike],
        force: Optional[npt.ArrayLike] = None,
        moment: Optional[npt.ArrayLike] = None,
    ) -> int: ...
    @property
    def supports(self) -> List[Dict[str, Any]]: ...
    def set_support(
        self,
        at: Union[int, npt.ArrayLike],
        position: Optional[npt.ArrayLike] = None,
        rotation: Optional[npt.ArrayLike] = None,
        velocity: Optional[npt.ArrayLike] = None,
        angular_velocity: Optional[npt.ArrayLike] = None,
    ) -> None: ...
    @property
    def summary(self) -> Dict[str, Any]: ...
    @property
    def trajectory(self) -> Dict[str, npt.NDArray[Any]]: ...
    def _trajectory(self) -> Dict[str, npt.NDArray[Any]]: ...
    def _history(self) -> Dict[str, npt.NDArray[Any]]: ...

def builtin_scenes() -> List[str]: ...
def _run_sweep(
    sweep: Union[str, PathLike[str]],
    out: Union[str, PathLike[str]],
    backend: str = "auto",
    adapter: Optional[str] = None,
    resume: bool = False,
    histories: bool = False,
    progress: bool = False,
) -> Dict[str, Any]: ...
def _bench(
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
) -> str: ...
def _run_to_dir(
    scene: Scene,
    out: Union[str, PathLike[str]],
    output_dt: Optional[float] = None,
    cosseratbench: bool = False,
    scenario_digest: Optional[str] = None,
    experiment: Optional[str] = None,
) -> str: ...

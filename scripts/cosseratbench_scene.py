"""Writes a cosserat scene for the default variant of a cosseratbench experiment.

    python scripts/cosseratbench_scene.py EXPERIMENT SCENE.toml

prints `DIGEST OUTPUT_DT` (the suite's scenario digest, and the spacing of its frames)
for `cosserat run SCENE.toml --output-dt OUTPUT_DT --cosseratbench --scenario-digest DIGEST`.
Used by scripts/cosseratbench.sh; needs the suite installed (cosseratbench 0.3).

The translation is the Python package's (`cosserat.cosseratbench.scene_toml`, whose
header describes it), loaded from python/pysrc without the compiled extension; the
package's `CosseratSolver` runs the same scene in process (`cosseratbench run EXPERIMENT
-s cosserat`).
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from cosseratbench import registry
from cosseratbench.provenance import scenario_digest

_path = Path(__file__).resolve().parents[1] / "python" / "pysrc" / "cosserat" / "cosseratbench.py"
_spec = importlib.util.spec_from_file_location("cosserat_cosseratbench", _path)
adapter = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(adapter)


def scene(name: str) -> tuple[str, float, str]:
    experiment = registry.load_experiment(name)
    sc = experiment.scenario
    text, output_dt = adapter.scene_toml(sc, experiment.n_elements, experiment.n_frames, name=name)
    return text, output_dt, scenario_digest(sc)


def main() -> None:
    name, path = sys.argv[1], sys.argv[2]
    text, output_dt, digest = scene(name)
    with open(path, "w") as f:
        f.write(text)
    print(digest, repr(output_dt))


if __name__ == "__main__":
    main()

"""Shared fixtures: the `cosserat` command-line tool the results are compared against."""

import os
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def cli():
    """Runs the `cosserat` binary (COSSERAT_BIN, else target/debug/cosserat of the repository)."""
    exe = Path(os.environ.get("COSSERAT_BIN", ROOT / "target" / "debug" / "cosserat"))
    if not exe.exists():
        pytest.fail(f"{exe}: no cosserat binary (build it with `cargo build` or set COSSERAT_BIN)")

    def run(*args):
        p = subprocess.run([str(exe), *map(str, args)], capture_output=True, text=True, timeout=600)
        assert p.returncode == 0, f"cosserat {' '.join(map(str, args))}: {p.stderr}"
        return p

    return run

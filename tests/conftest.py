import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
ARTIFACTS = ROOT / "artifacts"


@pytest.fixture(scope="session")
def plants():
    from sim_core.plant import Plant

    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = Plant.from_robot(name)
        return cache[name]

    return get


def run_cli(*args, check=False, timeout=600):
    """Run ``hydrohil`` in a subprocess (the real console entry point)."""
    proc = subprocess.run([sys.executable, "-m", "sim_core.cli", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, cwd=ROOT)
    if check and proc.returncode != 0:
        raise AssertionError(f"hydrohil {' '.join(map(str, args))} failed ({proc.returncode}):\n{proc.stderr}")
    return proc


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture(scope="session")
def artifacts():
    ARTIFACTS.mkdir(exist_ok=True)
    return ARTIFACTS

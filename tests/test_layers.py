"""Layers are enforced: the import contracts in pyproject.toml hold, and they do catch a violation."""

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LINT = Path(sys.executable).with_name("lint-imports")


def run_lint(cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([str(LINT), "--no-cache"], cwd=cwd, capture_output=True, text=True, timeout=300)


def test_the_project_keeps_its_layer_contracts():
    r = run_lint(ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert " 0 broken" in r.stdout


def test_the_contracts_catch_sim_core_importing_the_service(tmp_path):
    """The same contracts on a copy of the packages in which sim_core imports hil_server: broken."""
    for pkg in ("sim_core", "hil_server", "web", "controllers"):
        shutil.copytree(ROOT / pkg, tmp_path / pkg, ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path / "pyproject.toml")
    (tmp_path / "sim_core" / "leak.py").write_text("import hil_server.service  # a layer violation\n")
    (tmp_path / "sim_core" / "identification" / "peek.py").write_text("from sim_core.kernel import compose\n")
    r = subprocess.run([str(LINT), "--no-cache"], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env={"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin"})
    assert r.returncode != 0
    contracts = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"]
    broken = [c["name"] for c in contracts if f"{c['name']} BROKEN" in " ".join(r.stdout.split())]
    assert any("sim_core knows nothing" in n for n in broken), r.stdout
    assert any("identification uses the simulator" in n for n in broken), r.stdout

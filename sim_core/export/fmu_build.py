"""Build a co-simulation FMU (FMI 2.0) of a robot with pythonfmu.

The FMU holds pythonfmu's binaries (linux64, win64), a copy of pythonfmu's Python part, a small
script (:data:`SCRIPT`) that imports :class:`~.fmu_slave.PlantSlave` from the installed hydrohil, and
under ``resources/hydrohil/``: the robot as a self-contained ``robot.toml`` and its URDF
(:mod:`.robot_snapshot`), the ``--params``/``--set``/``--effect`` changes as a parameter file
(``overrides.toml``, the format of ``hydrohil simulate --params``) and ``fmu.json`` naming them and
the hydrohil version that exported them. The model inside is therefore the one exported, whatever
robot files the importing machine has; only the equations come from its hydrohil.
"""

from __future__ import annotations

import importlib.metadata
import json
import os
import sys
import tempfile
from pathlib import Path

from ..model.spec import load_robot
from ..params_file import apply_params_file, overrides, write_params
from .robot_snapshot import write_snapshot

MODULE = "hydrohil_plant"   # the script's module name inside the FMU
DATA_DIR = "hydrohil"       # folder of the robot files inside the FMU's resources
MANIFEST = "fmu.json"

SCRIPT = '''"""HydroHIL plant, FMI 2.0 co-simulation (exported by `hydrohil fmu`).

The model runs in Python: the importing tool loads pythonfmu's binary, which starts a Python
interpreter; that Python needs the hydrohil package (pip install hydrohil). The robot and its
parameters are in resources/hydrohil/.
"""

try:
    from sim_core.export.fmu_slave import PlantSlave, hold_namespace
except ImportError as exc:
    import sys as _sys

    _msg = ("this HydroHIL FMU simulates the plant in Python and needs the hydrohil package in the Python "
            f"that loads it ({_sys.executable}, Python {_sys.version.split()[0]}): install it there "
            f"(pip install hydrohil), or point PYTHONPATH at a Python environment that has it; import error: {exc}")
    print(f"HydroHIL FMU: {_msg}", file=_sys.stderr)  # also where the tool shows no FMI log
    raise ImportError(_msg) from None


hold_namespace(globals())


class HydroHILPlant(PlantSlave):
    """The plant of the robot in resources/hydrohil/robot.toml."""
'''


class FmuExportError(ValueError):
    """The FMU cannot be written (names the file or the reason)."""


def _hydrohil_version() -> str:
    try:
        return importlib.metadata.version("hydrohil")
    except importlib.metadata.PackageNotFoundError:
        return ""


def stage(spec, base, folder: Path, sources: str = "") -> None:
    """Write the FMU's resources for ``spec`` (``base`` plus overrides) into ``folder``, and check
    that they load back to ``spec``."""
    data = folder / DATA_DIR
    write_snapshot(base, data, header=f"Robot {base.name} as exported by hydrohil fmu: every parameter explicit.")
    changes = overrides(spec, reference=base)
    manifest = {"format": 1, "robot": spec.name, "hydrohil": _hydrohil_version(), "robot_file": "robot.toml",
                "overrides": None}
    if set(changes) - {"robot"}:
        write_params(data / "overrides.toml", changes,
                     header=f"Changes to robot {spec.name} given to hydrohil fmu{f' ({sources})' if sources else ''}.")
        manifest["overrides"] = "overrides.toml"
    (data / MANIFEST).write_text(json.dumps(manifest, indent=2) + "\n")
    back = load_robot(data / "robot.toml")
    if manifest["overrides"]:
        apply_params_file(back, data / "overrides.toml")
    if back.parameters() != spec.parameters() or [e.to_dict() for e in back.effects] != [e.to_dict() for e in spec.effects]:
        diff = sorted(k for k, v in spec.parameters().items() if back.parameters().get(k) != v)
        raise AssertionError(f"the exported robot files do not load back to the model (differ: {', '.join(diff) or 'effects'})")


def build_fmu(spec, out: str | Path, base=None, sources: str = "") -> Path:
    """Write the FMU of ``spec`` to ``out`` (``*.fmu``), atomically. ``base`` is the robot as built
    in (default: loaded again from the spec's source), so that the FMU's overrides.toml lists what
    was changed."""
    try:
        from pythonfmu import FmuBuilder
    except ImportError:
        raise FmuExportError("FMU export needs pythonfmu: pip install 'hydrohil[fmu]'") from None
    out = Path(out)
    if out.suffix != ".fmu":
        raise FmuExportError(f"--out {out}: an FMU file name must end in .fmu")
    if out.is_dir():
        raise FmuExportError(f"--out {out}: is a directory")
    if base is None:
        base = load_robot(spec.source or spec.name)
    ancestor = out.parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise FmuExportError(f"--out {out}: {ancestor} is not a directory")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".fmu", dir=out.parent)
        os.close(fd)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)   # a normal new file, not mkstemp's private one
    except OSError as exc:
        raise FmuExportError(f"--out {out}: cannot write there: {exc.strerror or exc}") from None
    saved_path, saved_module = list(sys.path), sys.modules.get(MODULE)
    try:
        with tempfile.TemporaryDirectory(prefix="hydrohil_fmu_") as d:
            folder = Path(d)
            stage(spec, base, folder, sources)
            script = folder / f"{MODULE}.py"
            script.write_text(SCRIPT)
            FmuBuilder.build_FMU(script, dest=tmp, project_files=[folder / DATA_DIR])
        os.replace(tmp, out)
    except OSError as exc:
        raise FmuExportError(f"--out {out}: cannot write it: {exc.strerror or exc}") from None
    finally:
        # pythonfmu imports the script from the staging folder: leave this process as it was
        sys.path[:] = saved_path
        if saved_module is None:
            sys.modules.pop(MODULE, None)
        else:
            sys.modules[MODULE] = saved_module
        if os.path.exists(tmp):
            os.unlink(tmp)
    return out

"""Equations of motion as a self-contained Python module (needs only math and numpy)."""

from __future__ import annotations

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from .derivation import EquationsOfMotion
from .header import header_lines
from .program import Block


class _Printer(PythonCodePrinter):
    """Floats as the shortest literal that reads back as the same double (``repr``)."""

    def _print_Float(self, expr):
        return repr(float(expr))


def _body(block: Block, inputs: list[tuple[str, list[sp.Symbol]]], printer: PythonCodePrinter) -> list[str]:
    used = block.symbols_used()
    lines = []
    for arg, syms in inputs:
        lines.append(f"    _check(len({arg}) == {len(syms)}, {arg!r})")
        names = [s.name if s in used else "_" for s in syms]
        if any(n != "_" for n in names):
            lines.append(f"    {', '.join(names)}{',' if len(names) == 1 else ''} = (float(v) for v in {arg})")
    for s, e in block.assignments:
        lines.append(f"    {s.name} = {printer.doprint(e)}")
    return lines


def python_source(eom: EquationsOfMotion, source: str) -> str:
    """Module text with ``mass_matrix(q)``, ``coriolis(q, qd)``, ``gravity(q)`` and
    ``inverse_dynamics(q, qd, qdd)``, returning numpy arrays."""
    n = eom.n
    pr = _Printer({"fully_qualified_modules": True, "standard": "python3"})
    doc = "\n".join(header_lines(eom, source))
    out = [f'"""{doc}\n"""', "", "import math", "", "import numpy as np", "",
           f"NAME = {eom.name!r}",
           f"DOF_NAMES = {tuple(eom.dof_names)!r}",
           f"JOINT_TYPES = {tuple(eom.joint_types)!r}",
           f"GRAVITY = {tuple(float(x) for x in eom.gravity)!r}  # m/s^2, root frame",
           "",
           "",
           "def _check(ok, name):",
           "    if not ok:",
           f"        raise ValueError(f\"{{name}} needs {n} values (one per joint of DOF_NAMES)\")",
           "",
           "",
           "def mass_matrix(q):",
           f'    """Joint-space inertia M(q), [{n}, {n}] (kg m^2, kg m or kg by the joint pair)."""']
    out += _body(eom.mass_matrix, [("q", eom.q)], pr)
    out.append(f"    M = np.zeros(({n}, {n}))")
    for k, e in enumerate(eom.mass_matrix.outputs):
        r, c = divmod(k, n)
        if e != 0:
            out.append(f"    M[{r}, {c}] = {pr.doprint(e)}")
    out += ["    return M", "", "",
            "def coriolis(q, qd):",
            f'    """Coriolis and centrifugal forces c(q, qd) = C(q, qd) qd, [{n}] (N m or N)."""']
    out += _body(eom.coriolis, [("q", eom.q), ("qd", eom.qd)], pr)
    out.append(f"    return np.array([{', '.join(pr.doprint(e) for e in eom.coriolis.outputs)}], dtype=float)")
    out += ["", "", "def gravity(q):", f'    """Gravity forces g(q), [{n}] (N m or N)."""']
    out += _body(eom.gravity_torque, [("q", eom.q)], pr)
    out.append(f"    return np.array([{', '.join(pr.doprint(e) for e in eom.gravity_torque.outputs)}], dtype=float)")
    out += ["", "",
            "def inverse_dynamics(q, qd, qdd):",
            '    """Joint forces tau = M(q) qdd + C(q, qd) qd + g(q) (N m or N)."""',
            "    return mass_matrix(q) @ np.asarray(qdd, dtype=float) + coriolis(q, qd) + gravity(q)",
            ""]
    return "\n".join(out)

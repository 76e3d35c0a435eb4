"""Equations of motion as one self-contained C99 file (libm only, no allocation)."""

from __future__ import annotations

import re

import sympy as sp
from sympy.printing.c import C99CodePrinter

from .derivation import EquationsOfMotion
from .header import header_lines
from .program import Block


def c_identifier(name: str) -> str:
    """A C identifier made from a robot name (``mars-nd 2`` -> ``mars_nd_2``)."""
    ident = re.sub(r"\W", "_", name, flags=re.ASCII) or "robot"
    return "_" + ident if ident[0].isdigit() else ident


class _Printer(C99CodePrinter):
    """Floats as the shortest literal that reads back as the same double (``repr``)."""

    def _print_Float(self, expr):
        return repr(float(expr))


def _body(block: Block, inputs: list[tuple[str, list[sp.Symbol]]], printer: C99CodePrinter) -> list[str]:
    used = block.symbols_used()
    lines = []
    for arg, syms in inputs:
        for k, s in enumerate(syms):
            if s in used:
                lines.append(f"    const double {s.name} = {arg}[{k}];")
    for s, e in block.assignments:
        lines.append(f"    const double {s.name} = {printer.doprint(e)};")
    return lines


def c_source(eom: EquationsOfMotion, source: str, prefix: str | None = None) -> str:
    """C99 text defining ``<prefix>_mass_matrix``, ``<prefix>_coriolis``, ``<prefix>_gravity`` and
    ``<prefix>_inverse_dynamics`` (``prefix``: the robot name made an identifier)."""
    n = eom.n
    p = c_identifier(prefix or eom.name)
    pr = _Printer()
    doc = header_lines(eom, source) + [
        "",
        "Functions (arrays of doubles, matrices row-major; outputs may not alias inputs):",
        f"  void {p}_mass_matrix(const double q[{n}], double M[{n * n}]);",
        f"  void {p}_coriolis(const double q[{n}], const double qd[{n}], double c[{n}]);  (c = C(q, qd) qd)",
        f"  void {p}_gravity(const double q[{n}], double g[{n}]);",
        f"  void {p}_inverse_dynamics(const double q[{n}], const double qd[{n}], const double qdd[{n}], double tau[{n}]);",
        "Build: cc -std=c99 -O2 -c FILE.c (link with -lm).",
    ]
    out = ["/*"] + [(" * " + line.replace("*/", "* /")).rstrip() for line in doc] + [" */", "", "#include <math.h>", "",
           f"#define {p.upper()}_NDOF {n}", "",
           f"const char *const {p}_dof_names[{n}] = {{{', '.join(_c_string(x) for x in eom.dof_names)}}};",
           f"const int {p}_prismatic[{n}] = {{{', '.join('1' if t == 'prismatic' else '0' for t in eom.joint_types)}}};",
           "", f"void {p}_mass_matrix(const double *q, double *M)", "{"]
    out += _body(eom.mass_matrix, [("q", eom.q)], pr)
    for k, e in enumerate(eom.mass_matrix.outputs):
        out.append(f"    M[{k}] = {pr.doprint(e)};")
    out += ["}", "", f"void {p}_coriolis(const double *q, const double *qd, double *c)", "{"]
    out += _body(eom.coriolis, [("q", eom.q), ("qd", eom.qd)], pr)
    out += [f"    c[{k}] = {pr.doprint(e)};" for k, e in enumerate(eom.coriolis.outputs)]
    out += ["}", "", f"void {p}_gravity(const double *q, double *g)", "{"]
    out += _body(eom.gravity_torque, [("q", eom.q)], pr)
    out += [f"    g[{k}] = {pr.doprint(e)};" for k, e in enumerate(eom.gravity_torque.outputs)]
    out += ["}", "",
            f"void {p}_inverse_dynamics(const double *q, const double *qd, const double *qdd, double *tau)",
            "{",
            f"    double M[{n * n}], c[{n}], g[{n}];",
            f"    {p}_mass_matrix(q, M);",
            f"    {p}_coriolis(q, qd, c);",
            f"    {p}_gravity(q, g);",
            f"    for (int i = 0; i < {n}; ++i) {{",
            "        double acc = c[i] + g[i];",
            f"        for (int j = 0; j < {n}; ++j)",
            f"            acc += M[i * {n} + j] * qdd[j];",
            "        tau[i] = acc;",
            "    }",
            "}",
            ""]
    return "\n".join(out)


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'

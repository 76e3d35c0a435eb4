"""Symbolic equations of motion ``M(q) qdd + C(q, qd) qd + g(q) = tau`` (sympy) of a kinematic tree,
and printers that turn them into LaTeX, Python or C (``hydrohil eom``)."""

from .c_printer import c_source
from .derivation import EquationsOfMotion, derive_equations
from .latex_printer import latex_source
from .python_printer import python_source

FORMATS = {"latex": latex_source, "python": python_source, "c": c_source}

__all__ = ["EquationsOfMotion", "derive_equations", "latex_source", "python_source", "c_source", "FORMATS"]

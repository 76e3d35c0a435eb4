"""A straight-line program of sympy assignments: how a recursive algorithm becomes symbolic.

Expanding the recursive Newton-Euler or composite-rigid-body recursions into one expression per
output grows exponentially with the depth of the tree; naming every intermediate quantity keeps
the program linear in the number of bodies. :meth:`Program.let` names an expression (or returns
the name it already has, or the expression itself when it is a number, a symbol or a scaled
symbol), so identical sub-results are computed once while deriving. :func:`extract` then keeps
what some outputs need, and common subexpressions across the kept assignments are factored out
with :func:`sympy.cse`.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import count

import sympy as sp


def _trivial(expr: sp.Expr) -> bool:
    if expr.is_Number or expr.is_Symbol:
        return True
    return expr.is_Mul and len(expr.args) == 2 and expr.args[0].is_Number and expr.args[1].is_Symbol


class Program:
    """Assignments ``symbol = expression`` in evaluation order (each uses only earlier symbols)."""

    def __init__(self, prefix: str = "x"):
        self.prefix = prefix
        self.assignments: list[tuple[sp.Symbol, sp.Expr]] = []
        self._names: dict[sp.Expr, sp.Symbol] = {}

    def let(self, expr, name: str | None = None) -> sp.Expr:
        """A symbol standing for ``expr`` (new, or the one an equal expression already has); numbers,
        symbols and number*symbol are returned as they are."""
        expr = sp.sympify(expr)
        if _trivial(expr):
            return expr
        known = self._names.get(expr)
        if known is not None:
            return known
        known = self._names.get(-expr)
        if known is not None:
            return -known
        sym = sp.Symbol(name or f"{self.prefix}{len(self.assignments)}", real=True)
        self.assignments.append((sym, expr))
        self._names[expr] = sym
        return sym


@dataclass
class Block:
    """A self-contained piece of a program: ``assignments`` in order, then the ``outputs``
    (expressions of the inputs and of the assigned symbols)."""

    assignments: list[tuple[sp.Symbol, sp.Expr]]
    outputs: list[sp.Expr]

    def symbols_used(self) -> set[sp.Symbol]:
        """Every symbol read by an assignment or an output (inputs among them)."""
        used: set[sp.Symbol] = set()
        for _, e in self.assignments:
            used |= e.free_symbols
        for e in self.outputs:
            used |= e.free_symbols
        return used

    def operation_count(self) -> int:
        """Arithmetic operations and function calls to evaluate the block (sympy.count_ops)."""
        return int(sum(sp.count_ops(e) for _, e in self.assignments) + sum(sp.count_ops(e) for e in self.outputs))


def extract(program: Program, outputs: list[sp.Expr], cse: bool = True, cse_prefix: str = "t",
            taken: set[str] | None = None) -> Block:
    """The assignments that ``outputs`` depend on (dead code dropped), with common subexpressions
    across them factored out by :func:`sympy.cse` when ``cse``, named ``<cse_prefix><k>`` with
    names not in ``taken`` (which receives the new names: blocks extracted in turn with the same
    set never share a name for different quantities)."""
    defined = dict(program.assignments)
    needed: set[sp.Symbol] = set()
    stack = [s for e in outputs for s in e.free_symbols if s in defined]
    while stack:
        s = stack.pop()
        if s in needed:
            continue
        needed.add(s)
        stack.extend(x for x in defined[s].free_symbols if x in defined and x not in needed)
    kept = [(s, e) for s, e in program.assignments if s in needed]
    if not cse or not kept:
        return Block(kept, list(outputs))
    taken = set() if taken is None else taken
    taken |= {s.name for s, _ in program.assignments}

    def fresh_names():
        for k in count():
            name = f"{cse_prefix}{k}"
            if name not in taken:
                taken.add(name)
                yield sp.Symbol(name, real=True)

    fresh = fresh_names()
    exprs = [e for _, e in kept] + list(outputs)
    repl, reduced = sp.cse(exprs, symbols=fresh, order="none")
    # a replacement goes right before the first assignment that uses it; cse lists replacements
    # so that each uses only earlier ones
    repl_of = dict(repl)
    placed: set[sp.Symbol] = set()
    out: list[tuple[sp.Symbol, sp.Expr]] = []

    def place(expr: sp.Expr) -> None:
        for s in sorted(expr.free_symbols & repl_of.keys() - placed, key=lambda x: order[x]):
            if s in placed:
                continue
            place(repl_of[s])
            placed.add(s)
            out.append((s, repl_of[s]))

    order = {s: k for k, (s, _) in enumerate(repl)}
    for (sym, _), expr in zip(kept, reduced[: len(kept)]):
        place(expr)
        out.append((sym, expr))
    final = reduced[len(kept):]
    for expr in final:
        place(expr)
    return Block(out, final)

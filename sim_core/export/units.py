"""Parameter unit strings (``"m^3/(s Pa)"``, ``"N m s/rad"``) as FMI units.

FMI 2.0 names a unit by a string and defines it by SI base-unit exponents (``<BaseUnit kg="1"
m="-1" s="-2"/>``), so importers can check and convert units. The project writes units the way its
docstrings do: symbols with ``^n`` exponents, a space for a product, ``/`` for a quotient,
parentheses for a grouped denominator. This module parses that form into exponents and writes the
FMI name in Modelica's unit syntax (``m3/(s.Pa)``, ``N.m.s/rad``), which OpenModelica reads
directly and Simulink maps through the base units.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

BASE = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")

# symbol -> SI base-unit exponents
SYMBOLS: dict[str, dict[str, int]] = {
    "1": {},
    "kg": {"kg": 1},
    "m": {"m": 1},
    "s": {"s": 1},
    "A": {"A": 1},
    "K": {"K": 1},
    "mol": {"mol": 1},
    "cd": {"cd": 1},
    "rad": {"rad": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "Pa": {"kg": 1, "m": -1, "s": -2},
    "J": {"kg": 1, "m": 2, "s": -2},
    "W": {"kg": 1, "m": 2, "s": -3},
    "Hz": {"s": -1},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
}

# unit strings of dimensionless quantities: no FMI unit
DIMENSIONLESS = {"", "-", "1", "substeps"}

_TOKEN = re.compile(r"\s*(?:(?P<sym>[A-Za-z]+|1)(?:\^(?P<exp>-?\d+))?|(?P<op>[/()]))")


class UnitError(ValueError):
    """A unit string this module cannot read (names the string)."""


@dataclass(frozen=True)
class FmiUnit:
    name: str                       # the FMI unit name (Modelica syntax)
    base: tuple[tuple[str, int], ...]  # non-zero SI base-unit exponents, in BASE order


def _tokens(text: str):
    pos = 0
    out = []
    while pos < len(text):
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if not m or m.end() == pos:
            raise UnitError(f"unit {text!r}: cannot read {text[pos:]!r}")
        out.append(m)
        pos = m.end()
    return out


def parse(text: str) -> list[tuple[str, int]]:
    """``"m^3/(s Pa)"`` -> ``[("m", 3), ("s", -1), ("Pa", -1)]`` (symbols in order of appearance,
    exponents summed)."""
    factors: dict[str, int] = {}
    sign = 1          # +1 in the numerator, -1 after '/': 'a/b c' is a/(b c), as the docstrings mean it
    group = None      # sign of the parenthesised group, if inside one
    for m in _tokens(text):
        op = m.group("op")
        if op == "/":
            if group is not None:
                raise UnitError(f"unit {text!r}: '/' inside parentheses")
            sign = -1
            continue
        if op == "(":
            if group is not None:
                raise UnitError(f"unit {text!r}: nested parentheses")
            group = sign
            continue
        if op == ")":
            if group is None:
                raise UnitError(f"unit {text!r}: unbalanced ')'")
            group = None
            continue
        sym = m.group("sym")
        if sym not in SYMBOLS:
            raise UnitError(f"unit {text!r}: unknown symbol {sym!r} (known: {', '.join(SYMBOLS)})")
        exp = int(m.group("exp") or 1) * (group if group is not None else sign)
        if sym != "1":
            factors[sym] = factors.get(sym, 0) + exp
    if group is not None:
        raise UnitError(f"unit {text!r}: unbalanced '('")
    return [(s, e) for s, e in factors.items() if e != 0]


def _write(factors: list[tuple[str, int]]) -> str:
    def term(items):
        return ".".join(s + (str(abs(e)) if abs(e) != 1 else "") for s, e in items)

    num = [(s, e) for s, e in factors if e > 0]
    den = [(s, e) for s, e in factors if e < 0]
    text = term(num) or "1"
    if den:
        text += "/" + (f"({term(den)})" if len(den) > 1 else term(den))
    return text


def fmi_unit(text: str) -> FmiUnit | None:
    """The FMI unit of a project unit string; None for a dimensionless quantity."""
    if text.strip() in DIMENSIONLESS:
        return None
    factors = parse(text)
    if not factors:
        return None
    base: dict[str, int] = {}
    for sym, exp in factors:
        for b, e in SYMBOLS[sym].items():
            base[b] = base.get(b, 0) + e * exp
    return FmiUnit(_write(factors), tuple((b, base[b]) for b in BASE if base.get(b, 0)))


def for_joint_type(text: str, prismatic: bool) -> str:
    """A parameter unit as it applies to one joint: a prismatic joint's positions are metres, so its
    ``rad`` becomes ``m`` (the component declarations are written for the revolute case)."""
    if not prismatic:
        return text
    return re.sub(r"\brad\b", "m", text)

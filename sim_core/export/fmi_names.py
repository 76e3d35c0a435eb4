"""Parameter paths and signal names as FMI 2.0 variable names (naming convention "structured").

A parameter path ``joints.j2.valve.rated_flow`` is already a structured FMI name: each dot-separated
part is an identifier (a letter or ``_``, then letters, digits, ``_``). A part that is not one (a
joint named ``boom-lift``) is written as an FMI q-name, in single quotes with ``'``, ``"`` and ``\\``
escaped: ``joints.'boom-lift'.valve.rated_flow``, and a signal of that joint as ``'u_boom-lift'``.
A character outside the q-name alphabet of FMI 2.0 (printable ASCII but the backtick) cannot be
exported and is refused with the name. So a path maps to exactly one FMI name and back.
"""

from __future__ import annotations

import re

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
# FMI 2.0 q-chars (besides letters, digits and _); ' " and \ are written escaped
_QCHAR = set("!#$%&()*+,-./:;<>=?@[]^{}|~ ")
_ESCAPE = {"\\": "\\\\", "'": "\\'", '"': '\\"'}


class FmiNameError(ValueError):
    """A name that FMI 2.0 cannot express (names it)."""


def part(text: str) -> str:
    """One component of a structured name: the text itself if it is an identifier, else a q-name."""
    if _IDENT.match(text):
        return text
    bad = sorted({c for c in text if not (c.isascii() and (c.isalnum() or c == "_" or c in _QCHAR or c in _ESCAPE))})
    if not text or bad:
        raise FmiNameError(f"{text!r} cannot be part of an FMI 2.0 variable name"
                           + (f" (character(s) {' '.join(map(repr, bad))})" if bad else ""))
    return "'" + "".join(_ESCAPE.get(c, c) for c in text) + "'"


def path_name(path: str) -> str:
    """A parameter path (``joints.j2.valve.rated_flow``) as a structured FMI name."""
    return ".".join(part(p) for p in path.split("."))


def signal_name(prefix: str, joint: str, suffix: str = "") -> str:
    """A joint's signal (``u_`` + joint, ``p_`` + joint + ``_a``) as one FMI name component."""
    return part(f"{prefix}{joint}{suffix}")

"""Where a key sits in a TOML file: the line number that a spec error names.

tomllib gives positions only for syntax errors, so semantic errors (an unknown key, a value out of
range) are located by a plain scan of the text: table headers (``[a.b]``, ``[[a]]``, counted per
array) and ``key = value`` lines, each turned into its full dotted path. Inline tables and multi-line
values are not descended into; a key inside them is reported at the line that opens them.
"""

from __future__ import annotations

import re
from pathlib import Path

_HEADER = re.compile(r"^\s*(\[\[?)\s*(.+?)\s*\]\]?\s*(#.*)?$")
_ASSIGN = re.compile(r"^\s*((?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_\-]+)(?:\s*\.\s*(?:\"[^\"]*\"|'[^']*'|[A-Za-z0-9_\-]+))*)\s*=")


def split_key(text: str) -> tuple[str, ...]:
    """``a."b.c".d`` -> ("a", "b.c", "d")."""
    parts, cur, quote = [], "", ""
    for ch in text.strip():
        if quote:
            if ch == quote:
                quote = ""
            else:
                cur += ch
        elif ch in "\"'":
            quote = ch
        elif ch == ".":
            parts.append(cur.strip())
            cur = ""
        else:
            cur += ch
    parts.append(cur.strip())
    return tuple(parts)


class TomlLines:
    """Line numbers (1-based) of the tables and keys of one TOML text."""

    def __init__(self, text: str):
        self.lines: dict[tuple[str, ...], int] = {}
        arrays: dict[tuple[str, ...], int] = {}
        table: tuple[str, ...] = ()
        in_multiline = False
        for n, raw in enumerate(text.splitlines(), start=1):
            line = raw.strip()
            if in_multiline:
                if '"""' in line or "'''" in line:
                    in_multiline = False
                continue
            if not line or line.startswith("#"):
                continue
            m = _HEADER.match(line)
            if m and not _ASSIGN.match(line):
                key = split_key(m.group(2))
                if m.group(1) == "[[":
                    idx = arrays.get(key, -1) + 1
                    arrays[key] = idx
                    table = key + (str(idx),)
                    self.lines.setdefault(key, n)
                else:
                    table = key
                self.lines.setdefault(table, n)
                continue
            m = _ASSIGN.match(line)
            if m:
                self.lines.setdefault(table + split_key(m.group(1)), n)
                rest = line[m.end():]
                if rest.count('"""') == 1 or rest.count("'''") == 1:
                    in_multiline = True

    @classmethod
    def of_file(cls, path: Path) -> "TomlLines":
        try:
            return cls(Path(path).read_text(encoding="utf-8", errors="replace"))
        except OSError:
            return cls("")

    def exact(self, key: str | tuple[str, ...]) -> int | None:
        parts = split_key(key) if isinstance(key, str) else tuple(key)
        return self.lines.get(parts)

    def find(self, *keys: str | tuple[str, ...]) -> int | None:
        """Line of the first key found exactly; else of the longest leading part of any key found."""
        cands = [split_key(k) if isinstance(k, str) else tuple(k) for k in keys if k]
        for parts in cands:
            if parts in self.lines:
                return self.lines[parts]
        best: tuple[int, int] | None = None
        for parts in cands:
            for n in range(len(parts) - 1, 0, -1):
                if parts[:n] in self.lines:
                    if best is None or n > best[0]:
                        best = (n, self.lines[parts[:n]])
                    break
        return best[1] if best else None

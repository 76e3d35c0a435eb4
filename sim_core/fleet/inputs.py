"""What a fleet re-run compares: a record's name under the report directory and its input key.

The key has four parts, each a sha256 (first 16 hex digits): the record file's bytes, the robot spec
(every parameter, effect and the URDF), the options that change the diagnosis or its files, and the
hydrohil code (:func:`sim_core.backends.fingerprint.code_fingerprint`). A record is skipped when all
four match those stored beside its finished diagnosis; the part that differs says why it is not.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from pathlib import Path

from ..backends.fingerprint import code_fingerprint

INPUT_FILE = "fleet-input.json"      # beside diagnosis.json: the key it was made from
KEY_PARTS = ("record", "robot", "options", "code")
_SUFFIXES = (".gz", ".csv", ".txt", ".tsv", ".dat", ".log", ".parquet", ".pq")
_UNSAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _h(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()[:16]


def file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()[:16]


def spec_digest(spec) -> str:
    """Every parameter and effect of ``spec``, its name and its URDF's bytes."""
    data = {"name": spec.name, "parameters": spec.parameters(),
            "effects": sorted((e.to_dict() for e in spec.effects), key=lambda d: json.dumps(d, sort_keys=True, default=repr))}
    text = json.dumps(data, sort_keys=True, default=repr).encode()
    urdf = Path(spec.urdf_path).read_bytes() if spec.urdf_path and Path(spec.urdf_path).is_file() else b""
    return _h(text + b"\0" + urdf)


def options_digest(options: dict) -> str:
    return _h(json.dumps(options, sort_keys=True, default=repr).encode())


def input_key(path: Path, spec_hash: str, options_hash: str) -> dict[str, str]:
    return {"record": file_digest(path), "robot": spec_hash, "options": options_hash, "code": code_fingerprint()}


def record_names(paths: list[Path]) -> list[str]:
    """A directory name per record: the file name without its data suffixes, made unique by the
    parent directories where two records share a name (a/rec.csv, b/rec.csv -> a-rec, b-rec)."""
    def base(p: Path) -> str:
        name = p.name
        while True:
            low = name.lower()
            cut = next((s for s in _SUFFIXES if low.endswith(s) and len(name) > len(s)), None)
            if cut is None:
                break
            name = name[: -len(cut)]
        return _UNSAFE.sub("_", name).strip("._") or "record"

    resolved = [p.resolve() for p in paths]
    depth = [0] * len(paths)
    while True:
        names = []
        for p, d in zip(resolved, depth):
            parents = [_UNSAFE.sub("_", q.name) for q in list(p.parents)[:d]][::-1]
            names.append("-".join([*parents, base(p)]))
        clash = {n for n in names if names.count(n) > 1}
        if not clash:
            return names
        grew = False
        for i, n in enumerate(names):
            if n in clash and depth[i] < len(resolved[i].parents) - 1:
                depth[i] += 1
                grew = True
        if not grew:    # only the same file twice can get here (checked by the caller)
            return [f"{n}-{i}" if n in clash else n for i, n in enumerate(names)]


def stored_key(record_dir: Path) -> dict | None:
    try:
        return json.loads((record_dir / INPUT_FILE).read_text())
    except (OSError, ValueError):
        return None


def store_key(record_dir: Path, data: dict) -> None:
    """Written last, atomically: a key on disk means the files beside it are complete."""
    tmp = record_dir / (INPUT_FILE + ".tmp")
    tmp.write_text(json.dumps(data, indent=2))
    os.replace(tmp, record_dir / INPUT_FILE)


def changed_parts(old: dict | None, new: dict) -> list[str]:
    if not old:
        return ["new"]
    return [k for k in KEY_PARTS if old.get(k) != new.get(k)]

"""The reading options, defined once for ``import``, ``simulate --input``, ``fit`` and ``diagnose``."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from .missing import MAX_RUN, POLICIES as MISSING_POLICIES

SATURATION_POLICIES = ("mask", "fail")
GLITCH_POLICIES = ("repair", "keep", "fail")


@dataclass(frozen=True)
class ReadOptions:
    """How to read a log file. The defaults read a dataset file as it is."""

    columns: tuple[str, ...] = ()     # "NAME=SOURCE[:UNIT]"
    no_header: bool = False           # the first line is data (default: detected)
    delimiter: str | None = None      # one character, 'tab' or 'space' (default: detected)
    rate: float | None = None         # Hz, when the file has no time column
    skip_rows: int = 0                # lines before the header (or the data)
    saturation: str = "mask"          # converter saturation on a measured column: mask or fail
    glitches: str = "repair"          # 1-3 sample excursions of a position (ingest/glitches.py): repair, keep or fail
    missing: str = "fail"             # empty or NaN cells (ingest/missing.py): fail, or repair runs of up to 3

    @property
    def given(self) -> bool:
        """Whether any option asks for more than reading a dataset file as it is (``glitches`` applies to a
        dataset file too)."""
        return bool(self.columns or self.no_header or self.delimiter is not None or self.rate is not None
                    or self.skip_rows or self.saturation != "mask" or self.missing != "fail")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["columns"] = list(self.columns)
        return d


def add_reading_options(p) -> None:
    """Add the reading options to an argparse (sub)parser."""
    g = p.add_argument_group(
        "reading a log file",
        "Any delimited text (or Parquet) file, mapped onto the dataset columns; without these options the "
        "file must be a dataset (time, u_<joint>, q_<joint>, p_<joint>_a/_b in SI units). See 'hydrohil import'.")
    g.add_argument("--column", action="append", default=[], metavar="NAME=SOURCE[:UNIT]",
                   help="dataset column NAME (time, u_<joint>, q_<joint>, p_<joint>_a, p_<joint>_b) from the file "
                        "column SOURCE (header name or 0-based index) in UNIT: s, ms; V, mV; rad, deg (revolute) or m, "
                        "mm (prismatic); Pa, kPa, bar, MPa, psi; sensor_volts (the joint's sensor model A*v+B); "
                        "*SCALE+OFFSET (raw counts). Default unit: the file's (a Parquet file's metadata, a row of "
                        "units under the header), else SI. A time column of clock readings (2026-11-26 "
                        "12:03:45.120, 12:03:45.120) is read as seconds from its first row. Repeatable; header "
                        "columns named like dataset columns are read as they are")
    g.add_argument("--no-header", action="store_true",
                   help="the first line is data (default: detected, a first line of numbers only is data)")
    g.add_argument("--delimiter", metavar="D", help="one character, 'tab' or 'space' (default: detected: tab, ';', "
                                                    "',', '|' or whitespace)")
    g.add_argument("--rate", type=float, metavar="HZ", help="sample rate when the file has no time column")
    g.add_argument("--skip-rows", type=int, default=0, metavar="N", help="lines to skip before the header or data")
    g.add_argument("--saturation", choices=SATURATION_POLICIES, default="mask",
                   help="measured samples at a converter's full scale: mask (keep, report and mark them; default) "
                        "or fail")
    g.add_argument("--glitches", choices=GLITCH_POLICIES, default="repair",
                   help="1-3 samples of a measured position that leave the signal and come back faster than the joint "
                        "moves anywhere else in the record (a wiper lifting, a loose connector): repair (replace them by "
                        "interpolation and say where; default), keep, or fail")
    g.add_argument("--missing", choices=MISSING_POLICIES, default="fail",
                   help="cells that hold no sample (empty, NaN, NA, #N/A, null: a logger's missed read): fail (an "
                        f"error naming the column and row; default), or repair runs of up to {MAX_RUN} samples (a "
                        "position, pressure or time interpolated, a command held at its value before) and say where")


def options_from_args(args) -> ReadOptions:
    return ReadOptions(
        columns=tuple(getattr(args, "column", None) or ()),
        no_header=bool(getattr(args, "no_header", False)),
        delimiter=getattr(args, "delimiter", None),
        rate=getattr(args, "rate", None),
        skip_rows=int(getattr(args, "skip_rows", 0) or 0),
        saturation=getattr(args, "saturation", "mask"),
        glitches=getattr(args, "glitches", "repair"),
        missing=getattr(args, "missing", "fail"),
    )

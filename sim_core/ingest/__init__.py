"""Reading measured records: any delimited text or Parquet log file, mapped onto the dataset columns of
a robot, converted to SI and checked (time grid, converter saturation, position glitches, command range).

    text.py        delimited text tables (fast path, and a slow path naming the bad cell)
    parquet.py     datasets as Parquet (units and robot in the schema metadata)
    columns.py     --column NAME=SOURCE[:UNIT]; dataset columns of a robot
    units.py       units and their conversion to SI (incl. sensor volts, raw counts)
    timegrid.py    jitter, gaps, repeated timestamps, time going backwards
    counter_wrap.py  a time column that is a wrapping tick counter (unwrapped)
    saturation.py  samples at a converter's full scale
    glitches.py    1-3 sample excursions of a position faster than the joint moves (repaired)
    missing.py     empty or NaN cells: refused, or runs of up to 3 filled (--missing repair)
    runs.py        runs of flagged samples and the line that bridges them
    options.py     the reading options, one definition for every command
    reader.py      import_record / read_input: all of the above for one file
"""

from .options import ReadOptions, add_reading_options, options_from_args
from .reader import ColumnReport, ImportResult, import_record, read_input

__all__ = ["ReadOptions", "add_reading_options", "options_from_args", "ColumnReport", "ImportResult",
           "import_record", "read_input"]

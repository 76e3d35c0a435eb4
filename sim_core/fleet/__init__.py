"""Diagnose a fleet's records: each record diagnosed like ``hydrohil diagnose`` (on the local pool or
Ray, :mod:`sim_core.backends`), then a summary across the fleet.

    inputs.py      record names, the input key a re-run compares (record bytes, robot, options, code)
    dates.py       a record's date: from its file name or from a column of the file
    task.py        one record's diagnosis as a backend task (the worker side)
    rows.py        one summary row per record; the view per effect across the fleet (and its trend)
    summary.py     fleet.json and fleet.csv
    index_html.py  index.html: the records, and each effect's parameter across records and over time
    progress.py    records done, the ones running, time left
    runner.py      run_fleet: skip unchanged records, map the rest over a backend, write everything
"""

from .runner import FleetOptions, FleetResult, run_fleet

__all__ = ["FleetOptions", "FleetResult", "run_fleet"]

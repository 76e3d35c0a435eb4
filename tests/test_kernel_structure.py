"""The kernel's structure: declared columns, composition from the effect files, a cache that cannot go stale."""

import pytest

from sim_core.effects import EFFECTS
from sim_core.effects.base import Effect
from sim_core.kernel import compose, layout
from sim_core.kernel.hooks import PHASE, hook_phase


def test_every_table_is_unique_and_contiguous():
    layout.check()
    for table in layout.TABLES:
        covered = []
        for c in table.columns:
            covered.extend(range(c.index, c.index + c.size))
        assert covered == list(range(table.N)), table.key            # no hole, no overlap
        names = [c.symbol for c in table.columns]
        assert len(names) == len(set(names)), table.key
        for c in table.columns:                                    # the published constant is the column
            assert getattr(layout, c.name) == c.index


def test_a_second_owner_of_a_column_is_refused():
    with pytest.raises(layout.LayoutError, match="P_A"):
        layout.XS.declare("somebody_else", layout.col("P_A", "Pa", "again"))


def test_every_column_has_a_unit_and_an_owner():
    for d in layout.describe():
        assert d["unit"] and d["owner"] and d["doc"], d


def test_effects_own_their_switches_and_columns():
    for eff in EFFECTS.values():
        if eff.switch:
            table = layout.GP if eff.scope == "global" else layout.AP
            switch = table.column(f"E_{eff.name.upper()}")
            assert switch.owner == eff.name and switch.index == eff.switch_column


def test_every_hook_is_composed_into_its_phase_behind_its_switch():
    text = compose.generate()
    for eff in EFFECTS.values():
        for hook, fname in eff.HOOKS.items():
            phase, off = hook_phase(hook)
            body = text.split(f"def fx_{phase.name}(")[1].split("\n\n\n")[0]
            assert f"_{eff.name}__{fname}(" in body, (eff.name, hook)
            if eff.switch:
                table = "GP[" if eff.scope == "global" else "AP[a, "
                assert f"{table}{eff.switch_column}] != 0.0" in body, (eff.name, hook)


def test_two_effects_replacing_one_phase_are_refused(monkeypatch):
    class Rival(Effect):
        switch = False
        HOOKS = {"metering": "lagged_spool_position"}

    Rival.name = "rival"
    Rival.__module__ = "sim_core.effects.spool_lag"
    monkeypatch.setitem(EFFECTS, "rival", Rival)
    with pytest.raises(compose.CompositionError, match="metering"):
        compose.generate()


def test_the_cache_key_follows_every_source_and_the_layout(monkeypatch):
    text = compose.generate()
    sources = {}
    for d in compose.SOURCE_DIRS:
        for p in sorted((compose.PACKAGE / d).glob("*.py")):
            sources[f"{d}/{p.name}"] = p.read_bytes()
    assert {"kernel/skeleton.py", "kernel/layout.py", "effects/deadband.py", "components/spool.py",
            "dynamics/rigid_body.py"} <= set(sources)
    key = compose.source_key(text, sources)
    assert compose.source_key(text, dict(sources)) == key
    for name in sources:                                           # any inlined source: a new kernel
        edited = dict(sources)
        edited[name] = sources[name] + b"\n# edited\n"
        assert compose.source_key(text, edited) != key, name
    assert compose.source_key(text + "\n", sources) != key
    scratch = layout.Table("ZZ", "test", "a table that exists only in this test")
    monkeypatch.setattr(layout, "TABLES", layout.TABLES + (scratch,))
    before = layout.fingerprint()
    scratch.declare("test", layout.col("X", "-", "moves the layout"))
    assert layout.fingerprint() != before
    assert compose.source_key(text, sources) != key


def test_the_loaded_kernel_is_the_one_for_the_current_sources():
    mod = compose.kernel()
    assert compose.source_key(compose.generate()) in mod.__name__
    for p in PHASE:
        assert hasattr(mod, f"fx_{p}")

"""A commanded joint whose reading never leaves its noise (identification/record.py: the pump off, the
valve unplugged, the wrong column mapped): noted beside joints that move, refused when none does,
with the column and the spans named. Signals are written here (no simulation)."""

import numpy as np
import pytest

from sim_core.dataset import Dataset, DatasetError
from sim_core.identification.record import STILL_SPAN, record_from_dataset
from sim_core.model.spec import load_robot

N, DT, SIGMA = 2000, 0.005, 3e-4


@pytest.fixture(scope="module")
def hydrolek():
    return load_robot("hydrolek")


def _record(spec, moves: dict[str, float]):
    """j2 and j3 commanded with a square wave; each joint's reading a ramp of ``moves[j]`` rad plus
    white noise of SIGMA rad."""
    rng = np.random.default_rng(0)
    t = np.arange(N) * DT
    u = np.where((np.arange(N) // 200) % 2, 3.0, -3.0)
    cols, data = ["time"], [t]
    for j, span in moves.items():
        cols += [f"u_{j}", f"q_{j}"]
        data += [u, 0.3 + span * np.linspace(0.0, 1.0, N) + rng.normal(0.0, SIGMA, N)]
    return record_from_dataset(Dataset(cols, np.column_stack(data)), spec, source="rec.csv")


def test_a_record_where_no_commanded_joint_moves_is_refused_naming_the_column(hydrolek):
    with pytest.raises(DatasetError) as err:
        _record(hydrolek, {"j2": 0.0})
    msg = str(err.value)
    assert msg.startswith("rec.csv: no commanded joint moves") and "q_j2 spans" in msg and "u_j2 spans -3 .. 3 V" in msg
    assert "pump" in msg


def test_a_still_joint_beside_a_moving_one_is_noted(hydrolek):
    rec = _record(hydrolek, {"j2": 0.5, "j3": 0.0})
    (note,) = [n for n in rec.notes if n.startswith("commanded but not moving")]
    assert "q_j3 spans" in note and "q_j2" not in note
    assert rec.targets == ["j2", "j3"]            # kept: its misfit is the diagnosis's to show


def test_the_threshold_is_noise_sigmas(hydrolek):
    # the 1st-99th percentile span of a ramp of s plus noise is about 0.98 s + 4.7 sigma
    below = (STILL_SPAN - 6.0) * SIGMA
    above = (STILL_SPAN + 6.0) * SIGMA
    with pytest.raises(DatasetError):
        _record(hydrolek, {"j2": below})
    assert not any(n.startswith("commanded but not moving") for n in _record(hydrolek, {"j2": above}).notes)


def test_diagnose_refuses_it_without_a_traceback(cli, tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(N) * DT
    u = np.where((np.arange(N) // 200) % 2, 3.0, -3.0)
    rows = np.column_stack([t, u, 0.3 + rng.normal(0.0, SIGMA, N)])
    np.savetxt(tmp_path / "log.csv", rows, delimiter=",", header="time,u_j2,q_j2", comments="")
    proc = cli("diagnose", "--robot", "hydrolek", tmp_path / "log.csv", "--report", tmp_path / "rep")
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert "no commanded joint moves" in proc.stderr and "q_j2 spans" in proc.stderr

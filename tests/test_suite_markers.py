"""Every test that runs against the wall clock is marked ``realtime``: ``make test`` runs the unmarked
tests in parallel over the cores, and a server, a browser or a timed wait beside a busy neighbour
would make its timing, not the code, decide the result."""

import ast
import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent

# what starts a server, a browser or a local Ray, or times the code under test
WALL_CLOCK = re.compile(r"\b(ServerProcess|InProcessServer|ViewProcess|HilService|ViserServer|run_scenario)\("
                        r"|\bCHROMIUM\b|\bray\.|\bperf_counter\(\)|\bmonotonic\(\)")


def _is_realtime_mark(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Attribute) and n.attr == "realtime" for n in ast.walk(node))


def _needs_and_marks(path: Path):
    """(test name, needs the mark, has it) for every test function of one file. A test needs the mark
    when its body, or a fixture of the same file it takes, matches WALL_CLOCK."""
    src = path.read_text()
    tree = ast.parse(src)
    module_marked = any(isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "pytestmark" for t in n.targets)
                        and _is_realtime_mark(n.value) for n in tree.body)
    funcs = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
    fixtures = {name for name, f in funcs.items()
                if any("fixture" in ast.unparse(d) for d in f.decorator_list)}

    def uses_clock(f: ast.FunctionDef) -> bool:
        return bool(WALL_CLOCK.search(ast.get_source_segment(src, f)))

    out = []
    for name, f in funcs.items():
        if not name.startswith("test_"):
            continue
        args = {a.arg for a in f.args.args}
        needs = uses_clock(f) or any(uses_clock(funcs[a]) for a in args & fixtures)
        marked = module_marked or any(_is_realtime_mark(d) for d in f.decorator_list)
        out.append((name, needs, marked))
    return out


def test_every_wall_clock_test_is_marked_realtime():
    unmarked = [f"{p.name}::{name}" for p in sorted(TESTS.glob("test_*.py")) if p.name != Path(__file__).name
                for name, needs, marked in _needs_and_marks(p) if needs and not marked]
    assert not unmarked, "run against the wall clock but not marked realtime: " + ", ".join(unmarked)


def test_the_check_sees_a_server_in_a_fixture_and_a_missing_mark(tmp_path):
    """The scan itself: a test taking a fixture that starts a server needs the mark; one without the
    mark is reported, one with it (on the function or the module) is not."""
    body = ("import pytest\n\n@pytest.fixture\ndef srv():\n    return ServerProcess(robot='hydrolek')\n\n"
            "def test_a(srv):\n    pass\n\ndef test_b():\n    pass\n\n"
            "@pytest.mark.realtime\ndef test_c(srv):\n    pass\n")
    p = tmp_path / "test_x.py"
    p.write_text(body)
    assert _needs_and_marks(p) == [("test_a", True, False), ("test_b", False, False), ("test_c", True, True)]
    p.write_text(body.replace("import pytest\n", "import pytest\n\npytestmark = pytest.mark.realtime\n"))
    assert all(marked for _, _, marked in _needs_and_marks(p))

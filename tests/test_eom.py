"""hydrohil eom: symbolic M(q), C(q, qd) qd and g(q), printed as Python, C and LaTeX, against the
numba CRBA/RNEA (themselves checked against Pinocchio in test_rigid_body/test_prismatic_dynamics).

Units: q in rad (revolute) or m (prismatic); M, c, g in SI (N m or N)."""

import ctypes
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from sim_core.dynamics.rigid_body import RigidBodyModel
from sim_core.model.spec import load_robot
from sim_core.model.urdf import PRISMATIC, load_urdf
from sim_core.symbolic import c_source, derive_equations, latex_source, python_source
from sim_core.symbolic.c_printer import c_identifier

ROOT = Path(__file__).resolve().parent.parent
MIXED = Path(__file__).parent / "data" / "mixed_prismatic.urdf"
CASES = ["hydrolek", "mars_nd", "harvester", "mixed_prismatic"]
CC = shutil.which("cc") or shutil.which("gcc")


def tree_of(case):
    return load_urdf(MIXED) if case == "mixed_prismatic" else load_robot(case).tree


@pytest.fixture(scope="module")
def derived():
    cache = {}

    def get(case):
        if case not in cache:
            tree = tree_of(case)
            cache[case] = (tree, derive_equations(tree))
        return cache[case]

    return get


def import_file(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def random_states(tree, count=20, seed=0):
    rng = np.random.default_rng(seed)
    pris = tree.jtype == PRISMATIC
    for _ in range(count):
        q = np.where(pris, rng.uniform(-0.8, 0.8, tree.n), rng.uniform(-3.0, 3.0, tree.n))
        yield q, rng.normal(0, 1.5, tree.n), rng.normal(0, 4.0, tree.n)


def reference(rb, q, qd):
    """M, c = C qd (RNEA with qdd = 0, no gravity), g (RNEA with qd = qdd = 0) from the numba kernel."""
    z = np.zeros_like(q)
    return rb.mass_matrix(q), rb.inverse_dynamics(q, qd, z, gravity=False), rb.inverse_dynamics(q, z, z)


def close(actual, expected):
    np.testing.assert_allclose(actual, expected, rtol=1e-9, atol=1e-9 * max(np.abs(expected).max(), 1e-12))


@pytest.mark.parametrize("case", CASES)
def test_generated_python_matches_numba(derived, case, tmp_path):
    tree, eom = derived(case)
    path = tmp_path / f"eom_{case}.py"
    path.write_text(python_source(eom, case))
    mod = import_file(path, f"eom_{case}")
    assert list(mod.DOF_NAMES) == tree.dof_names
    rb = RigidBodyModel(tree)
    for q, qd, qdd in random_states(tree):
        M, c, g = reference(rb, q, qd)
        close(mod.mass_matrix(q), M)
        close(mod.coriolis(q, qd), c)
        close(mod.gravity(q), g)
        close(mod.inverse_dynamics(q, qd, qdd), rb.inverse_dynamics(q, qd, qdd))
    with pytest.raises(ValueError, match=f"needs {tree.n} values"):
        mod.gravity(np.zeros(tree.n + 1))


@pytest.fixture(scope="module")
def compiled(derived, tmp_path_factory):
    if CC is None:
        pytest.skip("no C compiler (cc or gcc) on PATH: the generated C is not compiled here")
    libs = {}

    def get(case):
        if case not in libs:
            tree, eom = derived(case)
            d = tmp_path_factory.mktemp(f"c_{case}")
            src = d / f"{case}_eom.c"
            src.write_text(c_source(eom, case))
            so = d / f"{case}_eom.so"
            # warnings are errors: the generated file must be clean C99
            subprocess.run([CC, "-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-shared", "-fPIC",
                            "-o", str(so), str(src), "-lm"], check=True, capture_output=True, text=True)
            libs[case] = ctypes.CDLL(str(so))
        return libs[case]

    return get


@pytest.mark.parametrize("case", CASES)
def test_generated_c_matches_numba(derived, compiled, case):
    tree, eom = derived(case)
    lib = compiled(case)
    p = c_identifier(eom.name)
    ptr = lambda a: a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))  # noqa: E731
    n = tree.n
    rb = RigidBodyModel(tree)
    for q, qd, qdd in random_states(tree, seed=1):
        M, c, g = reference(rb, q, qd)
        Mc, cc, gc, tau = np.zeros(n * n), np.zeros(n), np.zeros(n), np.zeros(n)
        getattr(lib, f"{p}_mass_matrix")(ptr(q), ptr(Mc))
        getattr(lib, f"{p}_coriolis")(ptr(q), ptr(qd), ptr(cc))
        getattr(lib, f"{p}_gravity")(ptr(q), ptr(gc))
        getattr(lib, f"{p}_inverse_dynamics")(ptr(q), ptr(qd), ptr(qdd), ptr(tau))
        close(Mc.reshape(n, n), M)
        close(cc, c)
        close(gc, g)
        close(tau, rb.inverse_dynamics(q, qd, qdd))


def ancestors(tree, i):
    out = set()
    while i >= 0:
        out.add(i)
        i = int(tree.parent[i])
    return out


def test_structure_symmetry_and_branch_zeros(derived):
    """M is symmetric by construction and exactly zero between joints on different branches."""
    tree, eom = derived("mixed_prismatic")
    n = tree.n
    M = eom.mass_matrix.outputs
    for i in range(n):
        for j in range(n):
            related = i in ancestors(tree, j) or j in ancestors(tree, i)
            assert (M[i * n + j] != 0) == related, (tree.dof_names[i], tree.dof_names[j])
            assert M[i * n + j] == M[j * n + i]


def test_prismatic_diagonal_is_the_moved_mass(derived):
    """Physics without the kernel: a prismatic joint's M_jj is the mass it carries (kg), whatever q."""
    tree, eom = derived("mixed_prismatic")
    n = tree.n
    mod_env = {}
    exec(compile(python_source(eom, "test"), "eom_mixed", "exec"), mod_env)
    for name in ("extend", "plunge", "shift", "sled_travel"):
        j = tree.index(name)
        moved = sum(tree.mass[k] for k in range(n) if j in ancestors(tree, k))
        for q, _, _ in random_states(tree, count=5, seed=3):
            assert mod_env["mass_matrix"](q)[j, j] == pytest.approx(moved, rel=1e-12)


def test_latex_is_a_complete_ordered_derivation(derived):
    """Every quantity is defined before it is used, each entry of M (upper triangle, non-zero),
    C qd and g appears exactly once, and numbers carry the requested digits."""
    tree, eom = derived("mixed_prismatic")
    n = tree.n
    tex = latex_source(eom, "mixed_prismatic.urdf", digits=6)
    assert tex.count(r"\begin{document}") == 1 and tex.rstrip().endswith(r"\end{document}")
    rows = re.findall(r"^(.+?) &= (.+?)(?: \\\\)?$", tex, flags=re.M)
    lhs = [r for r, _ in rows]
    defined = set()
    for left, right in rows:
        for used in re.findall(r"\b([xsc])_\{(\d+)\}", right):
            assert used in defined, f"{used} used in {left} before its definition"
        m = re.fullmatch(r"([xsc])_\{(\d+)\}", left)
        if m:
            assert m.groups() not in defined, f"{left} defined twice"
            defined.add(m.groups())
    expected_M = {f"M_{{{i + 1},{j + 1}}}" for i in range(n) for j in range(i, n)
                  if i in ancestors(tree, j) or j in ancestors(tree, i)}
    assert {x for x in lhs if x.startswith("M_")} == expected_M
    for k in range(1, n + 1):
        assert lhs.count(rf"(C\dot{{q}})_{{{k}}}") == 1 and lhs.count(f"g_{{{k}}}") == 1
    for _, right in rows:
        for num in re.findall(r"\d+\.\d+", right):
            assert len(num.replace(".", "").lstrip("0")) <= 6, num
    for i, name in enumerate(tree.dof_names):
        assert rf"\texttt{{{name.replace('_', chr(92) + '_')}}}" in tex


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="no pdflatex on PATH: the LaTeX is not typeset here")
def test_latex_typesets(derived, tmp_path):
    _, eom = derived("harvester")
    (tmp_path / "eom.tex").write_text(latex_source(eom, "harvester"))
    proc = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "eom.tex"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-3000:]


def test_no_cse_gives_the_same_equations(derived):
    """cse only renames repeated work: without it the outputs evaluate to the same numbers."""
    tree, eom = derived("harvester")
    plain = derive_equations(tree, cse=False)
    env_a, env_b = {}, {}
    exec(compile(python_source(eom, "a"), "a", "exec"), env_a)
    exec(compile(python_source(plain, "b"), "b", "exec"), env_b)
    assert eom.mass_matrix.operation_count() < plain.mass_matrix.operation_count()
    for q, qd, _ in random_states(tree, count=5):
        close(env_a["mass_matrix"](q), env_b["mass_matrix"](q))
        close(env_a["coriolis"](q, qd), env_b["coriolis"](q, qd))


# ---- the command line ------------------------------------------------------------------------

def test_cli_python_end_to_end(cli, tmp_path):
    out = tmp_path / "hydrolek_eom.py"
    proc = cli("eom", "--robot", "hydrolek", "--format", "python", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == ""
    assert "hydrolek" in proc.stderr and "7 joints" in proc.stderr and str(out) in proc.stderr
    mod = import_file(out, "hydrolek_eom_cli")
    tree = load_robot("hydrolek").tree
    rb = RigidBodyModel(tree)
    for q, qd, qdd in random_states(tree, count=5, seed=4):
        close(mod.inverse_dynamics(q, qd, qdd), rb.inverse_dynamics(q, qd, qdd))


def test_cli_robot_forms_give_the_same_equations(cli):
    """A built-in name, its directory and its robot.toml are the same robot."""
    d = ROOT / "sim_core" / "robots" / "harvester"
    outs = [cli("eom", "--robot", r, "--format", "latex") for r in ("harvester", d, d / "robot.toml")]
    for p in outs:
        assert p.returncode == 0, p.stderr
    assert outs[0].stdout == outs[1].stdout == outs[2].stdout
    assert r"\section*{Equations of motion of" in outs[0].stdout


@pytest.mark.skipif(CC is None, reason="no C compiler (cc or gcc) on PATH")
def test_cli_c_from_a_urdf_compiles(cli, tmp_path):
    proc = cli("eom", "--robot", MIXED, "--format", "c")
    assert proc.returncode == 0, proc.stderr
    assert "4 prismatic" in proc.stderr
    src = tmp_path / "m.c"
    src.write_text(proc.stdout)
    subprocess.run([CC, "-std=c99", "-Wall", "-Werror", "-c", str(src), "-o", str(tmp_path / "m.o")], check=True)


def test_cli_output_does_not_depend_on_hash_seed(tmp_path):
    outs = []
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        proc = subprocess.run([sys.executable, "-m", "sim_core.cli", "eom", "--robot", "harvester", "--format", "c"],
                              capture_output=True, text=True, cwd=ROOT, env=env, timeout=600)
        assert proc.returncode == 0, proc.stderr
        outs.append(proc.stdout)
    assert outs[0] == outs[1]


@pytest.mark.parametrize("args, message", [
    (["--robot", "nosuch", "--format", "c"], "unknown robot 'nosuch'"),
    (["--robot", "hydrolek", "--format", "fortran"], "invalid choice: 'fortran'"),
    (["--robot", "hydrolek", "--format", "c", "--out", "{tmp}/missing/eom.c"], "--out {tmp}/missing/eom.c: no directory"),
    (["--robot", "hydrolek", "--format", "c", "--out", "{tmp}"], "--out {tmp}: is a directory"),
    (["--robot", "{tmp}", "--format", "c"], "the directory holds no robot.toml"),
    (["--robot", "{tmp}/none.urdf", "--format", "c"], "no such URDF file"),
    (["--robot", "{tmp}/bad.urdf", "--format", "c"], "{tmp}/bad.urdf: malformed URDF"),
    (["--robot", "{tmp}/planar.urdf", "--format", "c"], "joint 'shift': type 'planar' is not supported"),
])
def test_cli_bad_input_is_a_message_not_a_traceback(cli, tmp_path, args, message):
    (tmp_path / "bad.urdf").write_text("<robot><link")
    (tmp_path / "planar.urdf").write_text(MIXED.read_text().replace('name="shift" type="prismatic"',
                                                                     'name="shift" type="planar"'))
    proc = cli("eom", *[a.format(tmp=tmp_path) for a in args])
    assert proc.returncode == 2
    assert message.format(tmp=tmp_path) in proc.stderr
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "missing").exists()

"""hydrohil eom: time to derive the symbolic equations of motion of each built-in robot (and of the
mixed revolute/prismatic test tree), their size, and what evaluating the generated code costs
against the numba kernel functions, all measured in this run.

* derive: ``derive_equations`` (sympy), seconds; operations: sympy.count_ops of M, C qd, g.
* C vs numba: ns per evaluation inside a compiled loop (a C driver timing the generated functions
  with clock_gettime; an @njit loop around kinematics+crba / kinematics+rnea): no call overhead.
* Python vs numba from Python: us per call of the generated module's functions against
  ``RigidBodyModel.mass_matrix`` / ``inverse_dynamics`` (both called from the interpreter).

    .venv/bin/python benchmarks/bench_eom.py [--json] [--robots hydrolek,mars_nd,...]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from numba import njit

from sim_core.dynamics.rigid_body import RigidBodyModel, RigidBodyWorkspace, crba, kinematics, rnea
from sim_core.model.spec import load_robot
from sim_core.model.urdf import load_urdf
from sim_core.symbolic import c_source, derive_equations, python_source
from sim_core.symbolic.c_printer import c_identifier

ROOT = Path(__file__).resolve().parent.parent
MIXED = ROOT / "tests" / "data" / "mixed_prismatic.urdf"
STATES = 64


@njit(cache=False)
def _numba_loop(which, reps, t, Q, QD, ws, jt):
    parent, R_tree, p_tree, axis, com, inertia, mass, gravity = t
    Rw, ow, aw, cw, Iw, tmp33, mc, hc, Ic, M, w, dw, ao, F, N, tau, zero = ws
    acc = 0.0
    for k in range(reps):
        q = Q[k % Q.shape[0]]
        kinematics(parent, R_tree, p_tree, axis, com, inertia, q, Rw, ow, aw, cw, Iw, tmp33, jt)
        if which == 0:
            crba(parent, mass, ow, aw, cw, Iw, mc, hc, Ic, M, jt)
            acc += M[0, 0]
        elif which == 1:
            rnea(parent, mass, gravity, ow, aw, cw, Iw, QD[k % Q.shape[0]], zero, 0.0, w, dw, ao, F, N, tau, jt)
            acc += tau[0]
        else:
            rnea(parent, mass, gravity, ow, aw, cw, Iw, zero, zero, 1.0, w, dw, ao, F, N, tau, jt)
            acc += tau[0]
    return acc


def numba_ns(tree, Q, QD) -> dict:
    ws = RigidBodyWorkspace(tree.n)
    n = tree.n
    t = (tree.parent, tree.R_tree, tree.p_tree, tree.axis, tree.com, tree.inertia, tree.mass, tree.gravity)
    w = (ws.Rw, ws.ow, ws.aw, ws.cw, ws.Iw, ws.tmp33, ws.mc, ws.hc, ws.Ic, ws.M, ws.w, ws.dw, ws.ao, ws.F, ws.N,
         np.zeros(n), np.zeros(n))
    out = {}
    for which, key in enumerate(("M", "Cqd", "g")):
        _numba_loop(which, 10, t, Q, QD, w, tree.jtype)
        best = np.inf
        for _ in range(5):
            reps = 20000
            t0 = time.perf_counter()
            _numba_loop(which, reps, t, Q, QD, w, tree.jtype)
            best = min(best, (time.perf_counter() - t0) / reps * 1e9)
        out[key] = best
    return out


_DRIVER = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>
void {p}_mass_matrix(const double *q, double *M);
void {p}_coriolis(const double *q, const double *qd, double *c);
void {p}_gravity(const double *q, double *g);
static double now(void) {{ struct timespec ts; clock_gettime(CLOCK_MONOTONIC, &ts); return ts.tv_sec + 1e-9 * ts.tv_nsec; }}
int main(void)
{{
    static double Q[{S}][{n}], QD[{S}][{n}], M[{nn}], c[{n}], g[{n}];
    double acc = 0.0, best[3] = {{1e30, 1e30, 1e30}};
    unsigned s = 12345u;
    for (int k = 0; k < {S}; ++k)
        for (int i = 0; i < {n}; ++i) {{
            s = s * 1103515245u + 12345u; Q[k][i] = ((s >> 8) % 60000) / 10000.0 - 3.0;
            s = s * 1103515245u + 12345u; QD[k][i] = ((s >> 8) % 40000) / 10000.0 - 2.0;
        }}
    for (int rep = 0; rep < 5; ++rep)
        for (int which = 0; which < 3; ++which) {{
            double t0 = now();
            for (int k = 0; k < {reps}; ++k) {{
                const double *q = Q[k % {S}];
                if (which == 0) {{ {p}_mass_matrix(q, M); acc += M[0]; }}
                else if (which == 1) {{ {p}_coriolis(q, QD[k % {S}], c); acc += c[0]; }}
                else {{ {p}_gravity(q, g); acc += g[0]; }}
            }}
            double dt = (now() - t0) / {reps} * 1e9;
            if (dt < best[which]) best[which] = dt;
        }}
    printf("%.3f %.3f %.3f %g\n", best[0], best[1], best[2], acc);
    return 0;
}}
"""


def c_ns(eom, workdir: Path) -> dict | None:
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    p = c_identifier(eom.name)
    (workdir / "eom.c").write_text(c_source(eom, eom.name))
    (workdir / "driver.c").write_text(_DRIVER.format(p=p, n=eom.n, nn=eom.n * eom.n, S=STATES, reps=20000))
    exe = workdir / "bench"
    t0 = time.perf_counter()
    subprocess.run([cc, "-std=c99", "-O2", "-o", str(exe), str(workdir / "eom.c"), str(workdir / "driver.c"), "-lm"],
                   check=True)
    compile_s = time.perf_counter() - t0
    vals = subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()
    return {"M": float(vals[0]), "Cqd": float(vals[1]), "g": float(vals[2]), "compile_s": compile_s}


def python_us(eom, tree, Q, QD, workdir: Path) -> tuple[dict, dict]:
    path = workdir / "eom_gen.py"
    path.write_text(python_source(eom, eom.name))
    spec = importlib.util.spec_from_file_location(f"eom_gen_{eom.name}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rb = RigidBodyModel(tree)
    z = np.zeros(tree.n)
    calls = {
        "generated": {"M": lambda q, qd: mod.mass_matrix(q), "Cqd": lambda q, qd: mod.coriolis(q, qd),
                      "g": lambda q, qd: mod.gravity(q)},
        "numba": {"M": lambda q, qd: rb.mass_matrix(q), "Cqd": lambda q, qd: rb.inverse_dynamics(q, qd, z, gravity=False),
                  "g": lambda q, qd: rb.inverse_dynamics(q, z, z)},
    }
    out = {}
    for side, fns in calls.items():
        out[side] = {}
        for key, f in fns.items():
            f(Q[0], QD[0])
            best = np.inf
            for _ in range(3):
                reps = 300
                t0 = time.perf_counter()
                for k in range(reps):
                    f(Q[k % STATES], QD[k % STATES])
                best = min(best, (time.perf_counter() - t0) / reps * 1e6)
            out[side][key] = best
    return out["generated"], out["numba"]


def bench(case: str) -> dict:
    tree = load_urdf(MIXED) if case == "mixed_prismatic" else load_robot(case).tree
    t0 = time.perf_counter()
    eom = derive_equations(tree)
    derive_s = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    Q = np.ascontiguousarray(rng.uniform(-3.0, 3.0, (STATES, tree.n)))
    QD = np.ascontiguousarray(rng.normal(0, 1.0, (STATES, tree.n)))
    with tempfile.TemporaryDirectory() as d:
        py_gen, py_numba = python_us(eom, tree, Q, QD, Path(d))
        c = c_ns(eom, Path(d))
    return {
        "dofs": tree.n, "prismatic": int(tree.jtype.sum()), "derive_s": derive_s,
        "operations": {"M": eom.mass_matrix.operation_count(), "Cqd": eom.coriolis.operation_count(),
                       "g": eom.gravity_torque.operation_count()},
        "compiled_ns": {"c": c, "numba": numba_ns(tree, Q, QD)},
        "python_us": {"generated": py_gen, "numba_from_python": py_numba},
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--robots", default="hydrolek,mars_nd,harvester,mixed_prismatic")
    args = ap.parse_args()
    res = {case: bench(case) for case in args.robots.split(",")}
    if args.json:
        json.dump(res, sys.stdout, indent=2)
        print()
        return
    print(f"{'robot':<16} {'dofs':>4} {'derive s':>8}  {'ops M/Cqd/g':>16}   "
          f"{'C ns M/Cqd/g':>20} {'numba ns M/Cqd/g':>22} {'C/numba':>14}   "
          f"{'gen.py us M/Cqd/g':>20} {'numba-from-py us':>20}")
    for case, r in res.items():
        ops = "/".join(str(r["operations"][k]) for k in ("M", "Cqd", "g"))
        nb = r["compiled_ns"]["numba"]
        c = r["compiled_ns"]["c"]
        cs = "/".join(f"{c[k]:.0f}" for k in ("M", "Cqd", "g")) if c else "no compiler"
        ratio = "/".join(f"{c[k] / nb[k]:.2f}" for k in ("M", "Cqd", "g")) if c else "-"
        pg, pn = r["python_us"]["generated"], r["python_us"]["numba_from_python"]
        print(f"{case:<16} {r['dofs']:>4} {r['derive_s']:>8.2f}  {ops:>16}   {cs:>20} "
              f"{'/'.join(f'{nb[k]:.0f}' for k in ('M', 'Cqd', 'g')):>22} {ratio:>14}   "
              f"{'/'.join(f'{pg[k]:.0f}' for k in ('M', 'Cqd', 'g')):>20} "
              f"{'/'.join(f'{pn[k]:.1f}' for k in ('M', 'Cqd', 'g')):>20}")


if __name__ == "__main__":
    main()

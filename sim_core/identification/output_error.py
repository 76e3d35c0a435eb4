"""Output-error fitting: bounded least squares on free-run simulated channels.

A hydraulic joint integrates its command, so one wrong gain turns into a growing angle error; the
cost therefore stacks, per joint, the angle and its smoothed velocity (and the chamber pressures when
recorded), each normalised by the measured channel's spread, so each term is about (1 - fit)^2.
Non-smooth parameters (deadband, delay, backlash, ...) are started from the best point of a grid;
``scipy.optimize.least_squares`` ('trf', box bounds) refines, its Jacobian by forward differences
and, between them, by secant updates of the steps it takes. Uncertainties come from a Jacobian of differences,
``cov = s^2 (J'J)^-1``, inflated by N/N_eff because output-error residuals are coloured.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.stats import chi2, norm

from .metrics import effective_samples, nrmse_fit, savgol_window, smoothed, velocity
from .parameters import FreeParameter
from .record import Record
from .simulation import Outputs, Runner

PRESSURE_WEIGHT = 0.5      # each of p_a, p_b: together they weigh as much as the angle
DIFF_STEP = 1e-5           # least_squares' relative finite-difference step in the fit coordinate
# after a Jacobian of forward differences (one simulation per free parameter), up to this many
# accepted steps update it by their secants instead (Broyden: no simulation), each only while the
# Jacobian predicted the step just taken within BROYDEN_TRUST of what it did; 0: differences at every step
BROYDEN_UPDATES = 2
BROYDEN_TRUST = 0.3
FAIL_RESIDUAL = 10.0       # normalised residual of a simulation that failed (far worse than any fit)


class Problem:
    """The measured channels of ``joints`` on samples [start, n) of a record, normalised."""

    def __init__(self, rec: Record, joints: list[str], n: int | None = None, start: int = 0,
                 pressures: bool = True, restart: int = 0):
        self.rec = rec
        self.restart = int(restart)
        self.n = rec.n if n is None else n
        self.start = start
        self.joints = list(joints)
        self.use_pressures = pressures and any(j in rec.pressures for j in self.joints)
        sl = slice(start, self.n)
        self.meas: dict[tuple[str, str], np.ndarray] = {}
        self.weight: dict[tuple[str, str], float] = {}
        for j in self.joints:
            y = rec.angles[j][: self.n]
            self.meas[(j, "angle")] = y[sl]
            self.meas[(j, "velocity")] = velocity(y, rec.dt)[sl]
            self.weight[(j, "angle")] = self.weight[(j, "velocity")] = 1.0
            if self.use_pressures and j in rec.pressures:
                pa, pb = rec.pressures[j]
                self.meas[(j, "p_a")] = pa[: self.n][sl]
                self.meas[(j, "p_b")] = pb[: self.n][sl]
                self.weight[(j, "p_a")] = self.weight[(j, "p_b")] = PRESSURE_WEIGHT
        self.scale = {}
        for k, y in self.meas.items():
            s = float(np.linalg.norm(y - y.mean()))
            self.scale[k] = s if s > 0 else 1.0
        self.size = sum(y.size for y in self.meas.values())
        if self.restart:
            self._anchor_index = start + (np.arange(self.n - start) // self.restart) * self.restart
            self._anchor = {j: smoothed(rec.angles[j][: self.n], rec.dt)[self._anchor_index] for j in self.joints}

    def simulated(self, out: Outputs) -> dict[tuple[str, str], np.ndarray]:
        sl = slice(self.start, self.n)
        sim = {}
        for j in self.joints:
            y = out.angles[j][: self.n]
            sim[(j, "angle")] = y[sl]
            sim[(j, "velocity")] = velocity(y, self.rec.dt)[sl]
            if (j, "p_a") in self.meas:
                sim[(j, "p_a")] = out.pressures[j][0][: self.n][sl]
                sim[(j, "p_b")] = out.pressures[j][1][: self.n][sl]
        return sim

    def residuals(self, out: Outputs) -> np.ndarray:
        if not out.ok:
            return np.full(self.size, FAIL_RESIDUAL / math.sqrt(self.size))
        sim = self.simulated(out)
        parts = [(self.meas[k] - sim[k]) * (math.sqrt(self.weight[k]) / self.scale[k]) for k in self.meas]
        return np.concatenate(parts)

    def profiled_cost(self, out: Outputs) -> tuple[float, dict[str, float]]:
        """Cost after the best rescaling of each joint's motion, and those scales.

        A valve-controlled joint's speed is proportional to its flow gain, so scaling the simulated
        motion (angle about its start, velocity) by a factor is, to first order, re-calibrating the
        flow gain. Ranking grid points by this cost compares each with its own best calibration: a
        friction or a deadband that also slows the joint is not penalised for the slowing the
        baseline calibration already absorbed."""
        if not out.ok:
            return FAIL_RESIDUAL ** 2, {}
        return self._profiled(out, None)

    def profiled_bound(self, out: Outputs) -> float:
        """A lower bound of :meth:`profiled_cost` from the outputs of a run stopped early (its first
        samples): every term of the cost is a sum over samples, so the best rescaling of the samples
        so far costs no more than any rescaling of them all does there. The last half window of the
        smoothed velocity is left out: there it depends on samples still to come."""
        n = min(y.size for y in out.angles.values()) - self.start - savgol_window(self.rec.rate) // 2
        return self._profiled(out, max(n, 0))[0]

    def _profiled(self, out: Outputs, stop: int | None) -> tuple[float, dict[str, float]]:
        sim = self.simulated(out)
        cost = 0.0
        scales = {}
        for j in self.joints:
            ya = out.angles[j][0]
            pairs = [((j, "angle"), sim[(j, "angle")][:stop] - ya, self.meas[(j, "angle")][:stop] - ya),
                     ((j, "velocity"), sim[(j, "velocity")][:stop], self.meas[(j, "velocity")][:stop])]
            num = den = 0.0
            for k, x, m in pairs:
                w = self.weight[k] / self.scale[k] ** 2
                num += w * float(x @ m)
                den += w * float(x @ x)
            a = min(max(num / den, 1.0 / 3.0), 3.0) if den > 0 else 1.0
            scales[j] = a
            for k, x, m in pairs:
                r = m - a * x
                cost += self.weight[k] * float(r @ r) / self.scale[k] ** 2
            for ch in ("p_a", "p_b"):
                if (j, ch) in self.meas:
                    r = self.meas[(j, ch)][:stop] - sim[(j, ch)][:stop]
                    cost += self.weight[(j, ch)] * float(r @ r) / self.scale[(j, ch)] ** 2
        return cost, scales

    def redrawn(self, out: Outputs, noise: dict[str, float], pressure_noise: dict[str, float], rng) -> "Problem":
        """This problem measuring ``out``'s channels plus freshly drawn white sensor noise (standard
        deviation per joint: ``noise`` in rad, ``pressure_noise`` in Pa): another record of the same
        motion, to see how the fits spread over the noise."""
        angles, pressures = {}, {}
        for j in self.joints:
            y = out.angles[j][: self.n]
            angles[j] = y + rng.normal(0.0, noise.get(j, 0.0), y.size)
            if (j, "p_a") in self.meas:
                sp = pressure_noise.get(j, 0.0)
                pa, pb = out.pressures[j]
                pressures[j] = (pa[: self.n] + rng.normal(0.0, sp, self.n), pb[: self.n] + rng.normal(0.0, sp, self.n))
        rec = Record("noise", self.rec.time[: self.n], self.rec.U[: self.n], angles, pressures, self.rec.joint_names,
                     self.rec.excited, self.rec.initial_pose)
        return Problem(rec, self.joints, n=self.n, start=self.start, pressures=self.use_pressures, restart=self.restart)

    def channel_residuals(self, out: Outputs) -> dict[tuple[str, str], np.ndarray]:
        sim = self.simulated(out)
        return {k: self.meas[k] - sim[k] for k in self.meas}

    def fits(self, out: Outputs) -> dict[str, dict[str, float]]:
        """Per joint: NRMSE fit of angle, velocity, (recorded) pressures and, with restarts, the restarted
        angle, and their score."""
        if not out.ok:
            failed = {"angle": -math.inf, "velocity": -math.inf, "score": -math.inf}
            if self.restart:
                failed["restarted"] = -math.inf
            return {j: dict(failed) for j in self.joints}
        return self.fits_of(self.simulated(out))

    def fits_of(self, sim: dict[tuple[str, str], np.ndarray]) -> dict[str, dict[str, float]]:
        """:meth:`fits` of channels already taken from a simulation (:meth:`simulated`)."""
        res: dict[str, dict[str, float]] = {}
        for j in self.joints:
            f = {"angle": nrmse_fit(self.meas[(j, "angle")], sim[(j, "angle")]),
                 "velocity": nrmse_fit(self.meas[(j, "velocity")], sim[(j, "velocity")])}
            if self.restart:
                f["restarted"] = nrmse_fit(self.meas[(j, "angle")], self.restarted(j, sim[(j, "angle")]))
            if (j, "p_a") in self.meas:
                f["pressure"] = 0.5 * (nrmse_fit(self.meas[(j, "p_a")], sim[(j, "p_a")])
                                       + nrmse_fit(self.meas[(j, "p_b")], sim[(j, "p_b")]))
            f["score"] = score(f)
            res[j] = f
        return res

    def restarting(self, samples: int) -> "Problem":
        """This problem with a 'restarted' channel beside the angle: the angle fit over windows of
        ``samples``, each restarted from the record (closed-loop records: closed_loop.py)."""
        return Problem(self.rec, self.joints, n=self.n, start=self.start, pressures=self.use_pressures, restart=samples)

    def restarted(self, joint: str, angle: np.ndarray) -> np.ndarray:
        """The simulated angle moved, window by window, to start where the record's (smoothed) angle
        starts: what the model predicts over ``restart`` samples from the record's position."""
        return angle - angle[self._anchor_index - self.start] + self._anchor[joint]


def score(f: dict[str, float]) -> float:
    """The decision score of one joint: the mean of its channel fits."""
    vals = [f[k] for k in ("angle", "restarted", "velocity", "pressure") if k in f]
    return float(np.mean(vals))


@dataclass
class FitResult:
    free: list[FreeParameter]
    values: dict[str, float]
    cost: float                       # sum of squared normalised residuals
    sigma: dict[str, float] = field(default_factory=dict)
    ci95: dict[str, list[float]] = field(default_factory=dict)
    correlation: np.ndarray | None = None
    sims: int = 0
    ok: bool = True
    spec: object = None
    x: np.ndarray | None = None       # optimum in the normalised coordinates
    residual: np.ndarray | None = None
    start_spec: object = None         # the spec the free values are applied to
    jacobian: np.ndarray | None = None   # d residual / d x at the optimum (add_uncertainty's)
    # the cost that one unit of a parameter's (value/sigma)^2 is worth: s^2 N/N_eff (add_uncertainty's);
    # how far the cost must rise when parameters are reset for the record to have identified them
    cost_scale: float | None = None
    # the simulation at the optimum, where a least-squares evaluation made it: it carries its end, so a
    # longer run of the fitted model continues from it (Runner.simulate(resume=))
    outputs: Outputs | None = None

    def covariance(self, keys: list[str], given: list[str] = ()) -> np.ndarray | None:
        """The covariance of ``keys`` (physical units) from the sigmas and the correlation; None where
        the fit has none for one of them or one is not finite. ``given``: other free keys held at their
        fitted values (a later fit that keeps them where this one put them): the covariance of ``keys``
        conditional on them, ``C_kk - C_kg C_gg^-1 C_gk``. Along a valley the record fixes as a ratio,
        each parameter alone is uncertain; with its partner held, it is not."""
        order = [fp.key for fp in self.free]
        every = list(keys) + [g for g in given if g not in keys]
        if self.correlation is None or any(k not in order or k not in self.sigma for k in every):
            return None
        idx = [order.index(k) for k in every]
        s = np.array([self.sigma[k] for k in every])
        C = np.asarray(self.correlation)[np.ix_(idx, idx)] * np.outer(s, s)
        if not np.all(np.isfinite(C)):
            return None
        n = len(keys)
        if len(every) == n:
            return C
        cross = C[:n, n:]
        return C[:n, :n] - cross @ np.linalg.pinv(C[n:, n:]) @ cross.T

    def at_bound(self, key: str, tol: float = 2e-3) -> str | None:
        """'lower'/'upper' when the estimate sits on a search bound, else None."""
        fp = next(f for f in self.free if f.key == key)
        x = fp.to_x(self.values[key])
        if x <= tol:
            return "lower"
        if x >= 1.0 - tol:
            return "upper"
        return None


class _Budget(Exception):
    pass


class _Converged(Exception):
    """least_squares will stop after the step just taken: the Jacobian it asks for next is unused."""


def lsq_terminates(x0, f0, J0, x1, f1, ftol: float, xtol: float, lower: float = 0.0, upper: float = 1.0) -> bool:
    """Whether scipy's bounded 'trf' least_squares stops after its accepted step from ``x0`` (residual
    ``f0``, Jacobian ``J0``) to ``x1`` (residual ``f1``): its ``check_termination`` on that step, the
    ftol test with the step's ratio of actual to predicted reduction in its Coleman-Li scaled model
    (``x_scale=1``), and the xtol test. scipy evaluates the Jacobian at ``x1`` before it stops; a fit
    whose columns are simulations saves them by not computing it."""
    cost = 0.5 * float(f0 @ f0)
    actual = cost - 0.5 * float(f1 @ f1)
    step = np.asarray(x1, dtype=float) - np.asarray(x0, dtype=float)
    g = J0.T @ f0
    v, dv = np.ones_like(step), np.zeros_like(step)
    up, down = g < 0, g > 0
    v[up], dv[up] = upper - x0[up], -1.0
    v[down], dv[down] = x0[down] - lower, 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        step_h = np.where(v > 0, step / np.sqrt(v), 0.0)
    Js = J0 @ step
    predicted = -(float(g @ step) + 0.5 * float(Js @ Js) + 0.5 * float(np.sum(g * dv * step_h ** 2)))
    if predicted > 0:
        ratio = actual / predicted
    else:
        ratio = 1.0 if predicted == actual == 0 else 0.0
    ftol_met = actual < ftol * cost and ratio > 0.25
    xtol_met = float(np.linalg.norm(step)) < xtol * (xtol + float(np.linalg.norm(x0)))
    return ftol_met or xtol_met


def broyden_update(J: np.ndarray, step: np.ndarray, df: np.ndarray) -> np.ndarray:
    """Broyden's rank-one secant update of the Jacobian ``J`` after the step ``step`` changed the
    residual by ``df``: the least change of ``J`` that maps the step onto what it did."""
    ss = float(step @ step)
    if ss <= 0.0:
        return J
    return J + np.outer(df - J @ step, step / ss)


def _predicted_well(accepted: dict, x: np.ndarray, f1: np.ndarray) -> bool:
    """Whether the last Jacobian predicted the step to ``x`` well: the residual's change within
    BROYDEN_TRUST of the linear prediction, relative to the change itself."""
    step = x - accepted["x"]
    df = f1 - accepted["f"]
    miss = float(np.linalg.norm(df - accepted["J"] @ step))
    return miss <= BROYDEN_TRUST * float(np.linalg.norm(df))


def forward_steps(x: np.ndarray, rel: float, lower: float = 0.0, upper: float = 1.0) -> np.ndarray:
    """The forward-difference steps scipy's least_squares takes for ``diff_step=rel`` within
    [lower, upper]: ``rel |x|`` (sqrt(eps) where that vanishes), turned inward at a bound, shortened to
    the room left where neither direction fits."""
    sign = np.where(x >= 0, 1.0, -1.0)
    h = rel * sign * np.abs(x)
    h = np.where((x + h) - x == 0, np.sqrt(np.finfo(float).eps) * sign * np.maximum(1.0, np.abs(x)), h)
    lo, hi = x - lower, upper - x
    xh = x + h
    fitting = np.abs(h) <= np.maximum(lo, hi)
    h = np.where(((xh < lower) | (xh > upper)) & fitting, -h, h)
    h = np.where(~fitting & (hi >= lo), hi, h)
    h = np.where(~fitting & (hi < lo), -lo, h)
    return h


def _simulate_all(runner: Runner, specs: list, n: int, side=None) -> list[Outputs]:
    """``runner.simulate`` of every spec (each the caller's own copy), side by side when ``side``
    (:class:`.side_by_side.SideBySide`) is given."""
    if side is not None:
        return side.simulate(runner, specs, n)
    return [runner.simulate(s, n, owned=True) for s in specs]


def _spec_at(spec, free, x):
    s = spec.copy()
    for fp, xi in zip(free, x):
        fp.apply(s, fp.from_x(float(xi)))
    return s


def fit(runner: Runner, problem: Problem, spec, free: list[FreeParameter], *, grid: list[list[float]] | None = None,
        grid_problem: Problem | None = None, max_sims: int = 60, uncertainty: bool = True,
        tol: float = 1e-4, side=None, grid_start_too: bool = False, second_family: int | None = None) -> FitResult:
    """Fit the values of ``free`` in ``spec`` (a model spec) to the problem's channels.

    ``grid``: starting points (physical values, one list per point, in ``free``'s order), ranked on
    ``grid_problem`` (default: the problem itself; a shorter window is cheaper) by the
    flow-gain-profiled cost; the current values are a starting point too. ``grid_start_too``: where
    the current values rank first, the best grid point is fitted from as well and the lower cost
    kept (a new effect at its null: there its slope may vanish, a leak coefficient's or a
    deadband's, and a fit started there stays there, while its cost, next to starts whose other
    parameters were fitted without the effect, can rank it first; the null's own fit stays, since a
    grid start can end in a worse minimum). ``second_family``: the grid points from this index on
    are another family of starts (a rig's nuisances at their values before calibration, the others
    and the current values at the calibrated ones); the best-ranked start of each family is fitted
    from and the lower cost kept: the ranking window is shorter than the fit's, and the start it
    prefers can lead into a basin the whole window holds worse (a sensor offset the calibration set
    to stand in for a valve offset). ``side`` (:class:`.side_by_side.SideBySide`): where the
    uncertainty's Jacobian columns run."""
    spec = spec.copy()
    x0 = np.array([fp.to_x(fp.get(spec)) for fp in free])
    sims = [0]
    best = {"cost": math.inf, "x": x0.copy(), "r": None}

    def spec_at(x):
        return _spec_at(spec, free, x)

    def spec_at_or_none(x):
        """The spec at ``x``, or None where the model refuses the values (ValueError)."""
        try:
            return spec_at(x)
        except ValueError:
            return None

    last: dict = {}

    def failed():          # the residual of a model spec_at refuses
        return np.full(problem.size, FAIL_RESIDUAL / math.sqrt(problem.size))

    def scored(x, out):
        r = problem.residuals(out)
        c = float(r @ r)
        if c < best["cost"]:
            best.update(cost=c, x=np.array(x, dtype=float), r=r, out=out)
        return r

    def resid(x):
        if sims[0] >= max_sims:
            raise _Budget
        sims[0] += 1
        try:
            s = spec_at(x)
        except ValueError:
            return failed()
        r = scored(x, runner.simulate(s, problem.n, owned=True, keep_end=True))
        last.update(x=np.array(x, dtype=float), r=r)
        return r

    accepted: dict = {}

    def jacobian(x):
        """least_squares' forward differences ('2-point', relative step DIFF_STEP, one-sided inside
        the bounds), the columns simulated side by side when ``side`` is given; the budget and the
        best point as resid's. Not computed where least_squares stops after the step to ``x``; after
        a step the last Jacobian predicted well, its secant update (up to BROYDEN_UPDATES in a row)."""
        x = np.asarray(x, dtype=float)
        f0 = last["r"] if "r" in last and np.array_equal(last["x"], x) else resid(x)
        if accepted and lsq_terminates(accepted["x"], accepted["f"], accepted["J"], x, f0, tol, tol):
            raise _Converged
        if accepted and accepted["fresh"] < BROYDEN_UPDATES and _predicted_well(accepted, x, f0):
            J = broyden_update(accepted["J"], x - accepted["x"], f0 - accepted["f"])
            accepted.update(x=x.copy(), f=f0, J=J, fresh=accepted["fresh"] + 1)
            return J
        h = forward_steps(x, DIFF_STEP)
        cols = [x + np.eye(x.size)[i] * h[i] for i in range(x.size)]
        budget = max_sims - sims[0]
        todo = cols[:budget]
        sims[0] += len(todo)
        specs, ok = [], []
        for xi in todo:
            try:
                specs.append(spec_at(xi))
                ok.append(True)
            except ValueError:
                ok.append(False)
        outs = iter(_simulate_all(runner, specs, problem.n, side))
        J = np.empty((f0.size, x.size))
        for i, (xi, good) in enumerate(zip(todo, ok)):
            r = scored(xi, next(outs)) if good else failed()
            J[:, i] = (r - f0) / (xi[i] - x[i])
        if len(todo) < len(cols):
            raise _Budget
        accepted.update(x=x.copy(), f=f0, J=J, fresh=0)
        return J

    starts = [np.array([fp.to_x(v) for fp, v in zip(free, point)]) for point in grid or []]
    try:
        if starts:
            # rank the starting points by the flow-gain-profiled cost, then start the calibrated
            # flow gains where the best point's profile put them
            gp = grid_problem or problem
            starts.append(x0)
            costs, profiles = _rank(runner, gp, [spec_at_or_none(x) for x in starts],
                                    _rank_groups(len(starts), second_family, grid_start_too), sims, max_sims)

            def profiled(i):
                x_start = starts[i].copy()
                for k, fp in enumerate(free):
                    parts = fp.key.split(".")
                    if len(parts) == 4 and parts[0] == "joints" and parts[2:] == ["valve", "rated_flow"] and parts[1] in profiles[i]:
                        x_start[k] = fp.to_x(fp.from_x(float(x_start[k])) * profiles[i][parts[1]])
                return x_start

            i = int(np.argmin(costs))
            x_starts = [profiled(i)]
            first = list(range(len(starts)))
            if second_family is not None and second_family < len(starts) - 1:
                # the other family's best: fitted from as well (the current values, last, are the first's)
                first = list(range(second_family)) + [len(starts) - 1]
                second = range(second_family, len(starts) - 1)
                j = min(first if i in second else second, key=lambda k: costs[k])
                if np.isfinite(costs[j]):
                    x_starts.append(profiled(j))
            if grid_start_too and i == len(starts) - 1 and len(first) > 1:
                x_starts.append(profiled(min(first[:-1], key=lambda k: costs[k])))
        else:
            x_starts = [x0]
        if free:
            for x_start in x_starts:
                accepted.clear()
                try:
                    least_squares(resid, x_start, jac=jacobian,
                                  bounds=(0.0, 1.0), method="trf", diff_step=DIFF_STEP, x_scale=1.0,
                                  ftol=tol, xtol=tol, gtol=1e-8)
                except _Converged:
                    pass
        else:
            resid(x0)
    except (_Budget, _Converged):
        pass
    x = best["x"]
    values = {fp.key: fp.from_x(float(xi)) for fp, xi in zip(free, x)}
    out = FitResult(free, values, best["cost"], sims=sims[0], spec=spec_at(x), x=x, residual=best["r"], start_spec=spec,
                    outputs=best.get("out"))
    if best["r"] is None:
        out.ok = False
        return out
    if uncertainty and free:
        add_uncertainty(out, runner, problem, side)
    return out


def _rank_groups(count: int, second_family: int | None, grid_start_too: bool) -> list[int]:
    """The starts whose best :func:`fit` may pick, as group numbers: with one family and no second
    look at the grid, only the best of all counts; otherwise the best of the first family's grid
    points, of the second family's and the current values (last) each may."""
    last = count - 1
    families = second_family is not None and second_family < last
    if not (families or grid_start_too):
        return [0] * count
    split = second_family if families else last
    return [0 if k < split else 1 for k in range(last)] + [2]


def _rank(runner, gp: Problem, specs: list, groups: list[int], sims: list, max_sims: int) -> tuple[list, list]:
    """(profiled cost, flow-gain scales) of every starting point (``specs``: None where the model
    refused it), simulated on ``gp``'s window. A run whose cost is sure to exceed the best of its
    group so far (its early samples' profiled cost already does: Problem.profiled_bound) is abandoned
    and ranks last; the current values (last), a strong start, go first where all starts compete.
    ``sims``: the fit's simulation count (each start counts one, abandoned or not)."""
    count = len(specs)
    if sims[0] + count > max_sims:       # the budget ends the ranking: as many as it allows, in order
        order, abandon = list(range(count)), False
    else:
        order, abandon = ([count - 1] + list(range(count - 1)) if len(set(groups)) == 1 else list(range(count))), True
    costs, profiles = [math.inf] * count, [{}] * count
    best: dict[int, float] = {}
    for k in order:
        if sims[0] >= max_sims:
            raise _Budget
        sims[0] += 1
        limit = best.get(groups[k], math.inf)
        stop = None
        if abandon and math.isfinite(limit):
            stop = _exceeds(gp, limit)
        if specs[k] is None:
            out_g = Outputs({}, {}, ok=False)
        elif stop is None:
            out_g = runner.simulate(specs[k], gp.n, owned=True)
        else:
            out_g = runner.simulate(specs[k], gp.n, owned=True, abandon=stop)
            if out_g.abandoned:
                continue
        costs[k], profiles[k] = gp.profiled_cost(out_g)
        best[groups[k]] = min(limit, costs[k])
    return costs, profiles


def _exceeds(gp: Problem, limit: float):
    """A ranking run's abandon test: its early samples' profiled cost already exceeds ``limit``."""
    def stop(partial) -> bool:
        return gp.profiled_bound(partial) > limit * (1.0 + 1e-9)
    return stop


def sigma_level(sigmas: float, dof: int) -> float:
    """The chi-square of ``dof`` degrees of freedom whose tail is that of ``|value/sigma| = sigmas`` for
    one parameter (two-sided): the level that ``dof`` parameters taken together must pass."""
    return float(chi2.isf(2.0 * norm.sf(sigmas), dof))


def add_uncertainty(out: FitResult, runner, problem, side=None) -> None:
    """Forward-difference Jacobian at the optimum (steps of 1e-3 of the search range, pushed inward
    at the bounds; the columns side by side when ``side`` is given) and the covariance
    ``s^2 (J'J)^-1 N/N_eff`` mapped to physical units."""
    x, r0 = out.x, out.residual
    if x is None or r0 is None or not out.free:
        return
    k = x.size
    J = np.zeros((r0.size, k))
    steps, specs = [], []
    for i in range(k):
        h = 1e-3 if x[i] + 1e-3 <= 1.0 else -1e-3
        xp = x.copy()
        xp[i] += h
        steps.append(h)
        specs.append(_spec_at(out.start_spec, out.free, xp))
    out.sims += k
    outs = _simulate_all(runner, specs, problem.n, side)
    for i, (h, o) in enumerate(zip(steps, outs)):
        J[:, i] = (problem.residuals(o) - r0) / h
    out.jacobian = J
    m = r0.size
    dof = max(m - k, 1)
    s2 = float(r0 @ r0) / dof
    # coloured residuals: the information is that of N_eff independent samples, not N
    m_eff = 0.0
    pos = 0
    for key, y in problem.meas.items():
        seg = r0[pos: pos + y.size]
        m_eff += effective_samples(seg)
        pos += y.size
    inflate = max(1.0, m / max(m_eff, 1.0))
    out.cost_scale = s2 * inflate
    JtJ = J.T @ J
    try:
        cov = np.linalg.inv(JtJ) * s2 * inflate
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(JtJ) * s2 * inflate
    sx = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        out.correlation = cov / np.outer(sx, sx)
    for fp, xi, si in zip(out.free, x, sx):
        v = fp.from_x(float(xi))
        out.sigma[fp.key] = float(abs(fp.dv_dx(v)) * si) if np.isfinite(si) else math.inf
        lo = fp.from_x(float(xi - 1.96 * si)) if np.isfinite(si) else fp.lower
        hi = fp.from_x(float(xi + 1.96 * si)) if np.isfinite(si) else fp.upper
        # the CI is from the linearisation in the fit coordinate; clipping to the search bounds
        # happens in from_x
        out.ci95[fp.key] = [lo, hi]

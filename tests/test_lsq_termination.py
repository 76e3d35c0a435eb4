"""A fit skips the Jacobian scipy's least_squares computes after its last step and never uses (each
column is a simulation): the skip must foresee scipy's stop exactly, never earlier."""

import numpy as np
from scipy.optimize import least_squares

from sim_core.identification.output_error import lsq_terminates


def _problem(rng):
    """A bounded nonlinear least-squares problem on [0, 1]^k: decays and sines, with noise."""
    t = np.linspace(0.0, 3.0, 200)
    k = int(rng.integers(1, 4))

    def model(x):
        y = np.zeros_like(t)
        for i, xi in enumerate(x):
            y += (1 + i) * np.exp(-(1 + i) * (0.2 + 2 * xi) * t) + xi ** 2 * np.sin((i + 1) * t)
        return y

    data = model(rng.uniform(0, 1, k)) + rng.normal(0, 10 ** rng.uniform(-4, -1), t.size)
    return (lambda x: model(x) - data), rng.uniform(0, 1, k)


def test_the_stop_is_foreseen_at_scipys_last_jacobian_and_never_before():
    rng = np.random.default_rng(7)
    foreseen = stops = 0
    for _ in range(150):
        fun, x0 = _problem(rng)
        tol = float(rng.choice([1e-3, 1e-4, 1e-6]))
        said: list[bool] = []
        prev: dict = {}

        def jac(x):
            x = np.array(x)
            f = fun(x)
            said.append(bool(prev) and lsq_terminates(prev["x"], prev["f"], prev["J"], x, f, tol, tol))
            J = np.empty((f.size, x.size))
            for i in range(x.size):
                xp = x.copy()
                xp[i] += 1e-7 if x[i] + 1e-7 <= 1.0 else -1e-7
                J[:, i] = (fun(xp) - f) / (xp[i] - x[i])
            prev.update(x=x, f=f, J=J)
            return J

        r = least_squares(fun, x0, jac=jac, bounds=(0.0, 1.0), method="trf", ftol=tol, xtol=tol, gtol=1e-8,
                          x_scale=1.0)
        assert not any(said[:-1]), "a stop foreseen where least_squares went on"
        if r.status in (2, 3, 4) and len(said) > 1:        # stopped by ftol or xtol after a step
            stops += 1
            foreseen += said[-1]
    assert stops > 50
    assert foreseen == stops

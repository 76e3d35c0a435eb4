"""What a fitted value takes for granted (identification/conditional.py), on a model whose answer is
known in closed form, no simulation: a leak-like flow ``C p u(t)`` whose record fixes only the
product of the fitted coefficient C and the held pressure p, beside a term ``b w(t)`` that p does not
touch. Fitted by the same output-error fit as the diagnosis (scipy least squares, its Jacobian)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim_core.identification import output_error as oe
from sim_core.identification.conditional import (ELASTICITY_LIMIT, conditional_on, corrected, declared_ranges, describe,
                                                 elasticities, given, mark, span)
from sim_core.identification.parameters import FreeParameter

C, B, P, Z = "leak.coefficient", "drive.gain", "supply.pressure", "sensor.offset"


class Spec(dict):
    def get(self, key):
        return self[key]

    def set(self, key, value):
        self[key] = value

    def copy(self):
        return Spec(self)


class Out:
    def __init__(self, y):
        self.y, self.ok = y, True


class Model:
    """y = C p u(t) + b w(t) + z (a sensor offset, held at zero); the record made with p_true."""

    def __init__(self, n=400, seed=2, p_true=0.85e7, c_true=2e-7, b_true=1.5):
        rng = np.random.default_rng(seed)
        self.u, self.w = rng.standard_normal(n), np.sin(np.linspace(0.0, 20.0, n))
        self.n = self.size = n
        self.y = c_true * p_true * self.u + b_true * self.w + 1e-4 * rng.standard_normal(n)
        self.meas = {("j", "angle"): self.y}

    # the runner
    def simulate(self, spec, n, owned=False, **_):
        return Out(spec[C] * spec[P] * self.u + spec[B] * self.w + spec[Z])

    # the problem
    def residuals(self, out):
        return out.y - self.y


def _fit(model, spec):
    free = [FreeParameter(C, 1e-9, 1e-5, log=True), FreeParameter(B, 0.1, 10.0)]
    return oe.fit(model, model, spec, free, max_sims=80, tol=1e-10)


def test_a_coefficient_fixed_only_as_a_product_with_a_held_pressure_goes_as_its_inverse():
    """C p is what the record fixes: with p held 1/0.85 too high, C comes out 15 % low, and its
    elasticity to p is -1 (the exact answer); b, which p does not touch, does not depend on it, nor
    does anything on a held parameter whose value is zero (no percent to speak of)."""
    model = Model()
    spec = Spec({C: 1e-7, B: 1.0, P: 1e7, Z: 0.0})
    held = [FreeParameter(P, 5e6, 2e7), FreeParameter(Z, -1.0, 1.0)]
    fit = _fit(model, spec)
    assert fit.values[C] == pytest.approx(2e-7 * 0.85, rel=1e-3, abs=0)
    e = elasticities(fit, held, model, model)
    assert e[C][P] == pytest.approx(-1.0, abs=1e-2)
    assert abs(e[B][P]) < 1e-2
    assert Z not in e[C] and Z not in e[B]
    assert conditional_on(e[C]) == [P] and conditional_on(e[B]) == []
    # the correction the elasticity offers, with the pressure read off a gauge later
    assert fit.values[C] * 0.85 ** e[C][P] == pytest.approx(2e-7, rel=2e-3, abs=0)
    assert corrected(fit.values[C], e[C], {P: 0.85}) == pytest.approx(2e-7, rel=2e-3, abs=0)
    assert corrected(fit.values[B], e[B], {P: 0.85}) == pytest.approx(fit.values[B], rel=1e-3, abs=0)


def test_a_held_parameter_that_is_fitted_is_not_held_and_a_fit_without_jacobian_says_nothing():
    model = Model()
    spec = Spec({C: 1e-7, B: 1.0, P: 1e7, Z: 0.0})
    fit = _fit(model, spec)
    assert elasticities(fit, [FreeParameter(B, 0.1, 10.0)], model, model) == {}
    bare = oe.fit(model, model, spec, fit.free, max_sims=80, tol=1e-10, uncertainty=False)
    assert bare.jacobian is None
    assert elasticities(bare, [FreeParameter(P, 5e6, 2e7)], model, model) == {}


def test_the_limit_separates_what_matters():
    assert conditional_on({P: -ELASTICITY_LIMIT, Z: 0.5 * ELASTICITY_LIMIT, B: math.nan}) == [P]
    lines = describe({"elasticity_to_held": {"internal": {P: -1.29, Z: 0.1}}})
    assert len(lines) == 1 and P in lines[0] and "-1.29" in lines[0]
    lines = describe({"elasticity_to_held": {"internal": {P: -1.29}},
                      "range_given_held": {"internal": {"lower": 1e-12, "upper": 2e-12, "over": {P: [1.0, 2.0]}}}})
    assert len(lines) == 2 and lines[1] == f"internal lies between 1e-12 and 2e-12 as {P} spans its declared range, to first order"
    assert given({"conditional_on": [P, Z], "elasticity_to_held": {P: 0.98}}) == \
        f"given {P} (+0.98 % per %), {Z} at nominal"
    assert given({"elasticity_to_held": {P: 0.98}}) == ""


def test_a_value_spans_what_its_held_parameters_declared_ranges_allow():
    # a load fitted with the supply held at 14 MPa, declared 9.8-16.1 MPa (x0.7 / x1.15): +1.5 % per %
    ranges = {P: (9.8e6, 16.1e6, 14e6)}
    s = span(60.0, {P: 1.5}, ranges)
    assert s["lower"] == pytest.approx(60.0 * 0.7 ** 1.5) and s["upper"] == pytest.approx(60.0 * 1.15 ** 1.5)
    assert s["over"] == {P: [9.8e6, 16.1e6]}
    # a coefficient that goes as 1 / supply: the high supply gives the low end
    s = span(2e-12, {P: -1.0}, ranges)
    assert s["lower"] == pytest.approx(2e-12 / 1.15) and s["upper"] == pytest.approx(2e-12 / 0.7)
    # within the value's own range, never cut below the value itself
    s = span(60.0, {P: 1.5}, ranges, 20.0, 65.0)
    assert s["upper"] == 65.0 and s["lower"] == pytest.approx(60.0 * 0.7 ** 1.5)
    assert span(60.0, {P: 1.5}, ranges, 20.0, 50.0)["upper"] == 60.0
    # two held parameters: their ends multiply
    two = {P: (9.8e6, 16.1e6, 14e6), B: (0.5, 2.0, 1.0)}
    s = span(10.0, {P: 1.0, B: -0.5}, two)
    assert s["lower"] == pytest.approx(10.0 * 0.7 * 2.0 ** -0.5) and s["upper"] == pytest.approx(10.0 * 1.15 * 0.5 ** -0.5)
    # an elasticity the first order cannot carry over the range: bounded by the value's own range
    s = span(60.0, {P: 5e3}, ranges, 20.0, 85.0)
    assert (s["lower"], s["upper"]) == (20.0, 85.0)
    # what the value does not depend on, a range across zero, or no declared range: no span
    assert span(60.0, {P: 0.5 * ELASTICITY_LIMIT}, ranges) is None
    assert span(60.0, {Z: 1.0}, {Z: (-0.1, 0.1, 0.05)}) is None
    assert span(60.0, {P: 1.5}, {}) is None


def test_only_ranges_the_spec_declares_are_spanned():
    declared = FreeParameter(P, 9.8e6, 16.1e6, range_declared=True)
    searched = FreeParameter(B, 0.1, 10.0)                        # a search span, not the user's word
    ranges = declared_ranges([declared, searched], {P: 14e6, B: 1.0})
    assert ranges == {P: (9.8e6, 16.1e6, 14e6)}
    row = mark({"value": 60.0, "unit": "kg"}, {P: 1.5, B: 1.0}, ranges, FreeParameter("load", 20.0, 85.0))
    assert row["conditional_on"] == [B, P] and row["range_given_held"]["over"] == {P: [9.8e6, 16.1e6]}
    assert row["range_given_held"]["upper"] == pytest.approx(60.0 * 1.15 ** 1.5)   # B's search span is not spanned
    assert given(row).endswith(f"; {60.0 * 0.7 ** 1.5:.4g} to {60.0 * 1.15 ** 1.5:.4g} kg as {P} spans its declared range")

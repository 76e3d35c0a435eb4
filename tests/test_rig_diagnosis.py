"""A user's rig end to end: ``rig new`` -> a closed-loop log -> ``import`` -> ``diagnose``.

Each template rig is run under a P controller (the rig's own, tests/rig_records.py) tracking
operator-like steps; the truth has the valve 20 % larger and the supply 15 % lower than the written
robot.toml says, starts 5 % of the stroke off the template's initial position, and is logged at
50 Hz with jittered timestamps, the position in sensor volts and no pressures. Only the headerless
log reaches the commands under test. A hidden deadband, valve asymmetry, delay or valve null offset
is named with its parameter within 15 %, each on one template or two and every template with one
(``benchmarks/bench_rig_diagnosis.py`` runs every template x effect over seeds); a clean record of
every template is no_significant_discrepancy; a Coulomb friction is named where the user measured
the supply and the load.
"""

import json
import shutil

import pytest

from rig_records import as_record, closed_loop_record, measured, reference_steps, sine_reference, write_headerless
from sim_core.identification.calibration import plan
from sim_core.identification.candidates import actuator_scales
from sim_core.model.spec import estimable, load_robot
from sim_core.rigs import TEMPLATES

OFF = {"valve.rated_flow": 1.2, "supply.pressure": 0.85}
HIDDEN = {"deadband": ("width", 0.8), "valve_asymmetry": ("ratio", 0.7), "delay": ("delay", 0.06),
          "valve_offset": ("offset", 0.25)}


def _diagnose(cli, tmp_path, template, hidden, seed=5, rate=50.0, log_every=1, rig_set=(), off_nominal=None,
              reference=reference_steps, measure=()):
    """``measure``: keys of the truth (``supply.pressure``, ``effects.payload.<j>.mass``) the user measured
    and wrote into a copy of the rig, their [estimated] lines deleted; the diagnosis runs on that copy."""
    rig = tmp_path / "rig"
    cli("rig", "new", template, "--out", rig, *[a for kv in rig_set for a in ("--set", kv)], check=True)
    spec = load_robot(rig)
    j = spec.joint_names[0]
    i = spec.tree.index(spec.joint(j).dof)
    span = float(spec.tree.upper[i] - spec.tree.lower[i])
    off = {(k if k.startswith("supply") else f"joints.{j}.{k}"): f for k, f in (off_nominal or OFF).items()}
    rows, _ = closed_loop_record(rig, hidden=hidden, off=off, seed=seed, duration=60.0, start_offset=0.05 * span,
                                 rate=rate, log_every=log_every, reference=reference)
    write_headerless(rows, tmp_path / "log.csv")
    if measure:
        shutil.copytree(rig, tmp_path / "rig_measured")
        rig = tmp_path / "rig_measured"
        measured(rig, {k: estimable(spec, k)[1] * off.get(k, 1.0) for k in measure})
    cli("import", tmp_path / "log.csv", "--robot", rig, "--out", tmp_path / "rec.csv", "--no-header",
        "--column", "time=0", "--column", f"q_{j}=1:sensor_volts", "--column", f"u_{j}=2", check=True)
    proc = cli("diagnose", "--robot", rig, tmp_path / "rec.csv", "--report", tmp_path / "rep", "--quiet")
    assert proc.returncode == 0, proc.stderr
    (tmp_path / "stdout.txt").write_text(proc.stdout)
    return j, json.loads((tmp_path / "rep" / "diagnosis.json").read_text())


def _sized_leak(cli, tmp_path, template):
    """An internal leak coefficient (m^3/(s Pa)) of 4 % of the template's full valve flow at supply pressure."""
    cli("rig", "new", template, "--out", tmp_path / "sizing", check=True)
    spec = load_robot(tmp_path / "sizing")
    return 0.04 * actuator_scales(spec, spec.joint_names[0])["q_full"] / spec.supply["pressure"]


# a valve passing less one way and a cylinder whose annulus is smaller move the load alike when only
# the position is logged: on a cylinder the report may name either, marked ambiguous with the other as
# runner-up and chamber pressures as what would decide (README, "Diagnose your own rig")
POSITION_ONLY_TWINS = {"valve_asymmetry": "area_ratio"}
# wrong at the tests' seed, kept visible (strict: the case fails the run once it is right); none now
# (the boom's 60 ms delay, named an overdamped joint compliance until the calibration kept what the
# record needs together: docs/rig-diagnosis-rules.md)
KNOWN_MISSES: dict[tuple[str, str], str] = {}


# each effect on one template or two, each template with one: the cylinder's twin rule, the rotary
# actuator without a twin, the boom's delay (once named a joint compliance)
NAMED_ON = [("cylinder", "valve_asymmetry"), ("cylinder", "valve_offset"), ("rotary", "deadband"),
            ("rotary", "valve_asymmetry"), ("boom", "delay")]


def test_every_hidden_effect_and_every_template_has_a_case():
    assert {e for _, e in NAMED_ON} == set(HIDDEN) and {t for t, _ in NAMED_ON} == set(TEMPLATES)


@pytest.mark.parametrize("template, effect", NAMED_ON)
def test_a_hidden_effect_is_named_with_its_parameter(cli, tmp_path, request, template, effect):
    if (template, effect) in KNOWN_MISSES:
        request.applymarker(pytest.mark.xfail(strict=True, reason=KNOWN_MISSES[template, effect]))
    name, value = HIDDEN[effect]
    j, d = _diagnose(cli, tmp_path, template, (effect, {name: value}))
    assert d["closed_loop"] is True and d["verdict"] == "discrepancy"
    twin = [s for s in d["selected"] if s["effect"] == POSITION_ONLY_TWINS.get(effect)]
    if twin and load_robot(tmp_path / "rig").joint(j).kind == "cylinder":
        assert len(d["selected"]) == 1 and twin[0]["ambiguous"], d["selected"]
        assert twin[0]["runner_up"]["effect"] == effect and "pressure" in twin[0]["decided_by"]
        return
    hit = [s for s in d["selected"] if s["effect"] == effect]
    assert hit and hit[0]["joint"] == j, d["selected"]
    assert hit[0]["params"][name] == pytest.approx(value, rel=0.15)
    # the controller ran at the log's rate: held, and the period mean, refitted, scores no better
    assert d["closed_loop_evidence"]["command_hold"]["replay"] == "held"
    other = hit[0]["if_command_hold"]
    assert other["replay"] == "period_mean" and name in other["params"] and other["score_points"] < 0.5


def test_a_short_delay_is_named_once_the_oil_named_before_it_is_dropped(cli, tmp_path):
    """A 30 ms delay on the boom at 50 Hz (the matrix's draw, seed 200, the rig 10 % off): the first
    round named the oil 17 times softer (it buys back the open-loop replay's drift), the second a spool
    lag beside it, and the backward pass dropped the oil. The spool lag was chosen beside the oil; on
    the model without it the delay explains more, and is named in its place, within 15 %."""
    delay = 0.0299
    j, d = _diagnose(cli, tmp_path, "boom", ("delay", {"delay": delay}), seed=200,
                     off_nominal={"valve.rated_flow": 1.1, "supply.pressure": 0.9})
    assert [(s["effect"], s["joint"]) for s in d["selected"]] == [("delay", j)], d["selected"]
    assert d["selected"][0]["params"]["delay"] == pytest.approx(delay, rel=0.15)
    assert "named in place of" in d["decision"]["stopped"], d["decision"]["stopped"]


def test_what_a_value_takes_from_the_held_supply_agrees_with_diagnosing_again_at_the_gauged_supply(cli, tmp_path):
    """A 10 mm backlash on the cylinder (the matrix's held-out draw, seed 200), the rig's supply 10 % under
    its spec and held there. The report says how far each value hangs on that supply; a user who reads
    the gauge later corrects the values with it. Diagnosed again with the gauged supply in the spec,
    the values must be where the correction puts them: the width not at all (it is a length the record
    shows), the calibrated flow gain about as the orifice law's square root of the pressure, the load
    as the pressure, the sensor's gain not at all. The least-squares first order sent a direction the
    record hardly fixes (width, flow gain, the sensor's gain and the seals' friction together) far on a
    sliver of the supply's residual, out of their ranges: the width went as the supply to the power -5
    (70 % off at the gauge's value), the flow gain -5.3; the model did not follow that move."""
    seed, width = 200, 0.00995
    off = {"valve.rated_flow": 1.1, "supply.pressure": 0.9}
    hidden = ("backlash", {"width": width})
    (tmp_path / "held").mkdir()
    (tmp_path / "gauged").mkdir()
    j, held = _diagnose(cli, tmp_path / "held", "cylinder", hidden, seed=seed, off_nominal=off)
    _, gauged = _diagnose(cli, tmp_path / "gauged", "cylinder", hidden, seed=seed, off_nominal=off,
                          measure=("supply.pressure",))
    assert [(s["effect"], s["joint"]) for s in held["selected"]] == [("backlash", j)] == \
        [(s["effect"], s["joint"]) for s in gauged["selected"]], (held["selected"], gauged["selected"])
    a, b = held["selected"][0], gauged["selected"][0]
    e_width = a.get("elasticity_to_held", {}).get("width", {}).get("supply.pressure", 0.0)
    assert a["params"]["width"] * 0.9 ** e_width == pytest.approx(b["params"]["width"], rel=0.01), e_width
    rows, again = held["calibration"]["refitted_with_effects"], gauged["calibration"]["refitted_with_effects"]
    e_flow = rows[f"joints.{j}.valve.rated_flow"]["elasticity_to_held"]["supply.pressure"]
    assert -0.75 < e_flow < -0.4                      # Q ~ K sqrt(dp): the record fixes K sqrt(supply), the load aside
    # the flow gain, the sensor's gain and the load; the seals' viscous friction, the direction the record
    # fixes least, is not held to the first order over the gauge's 10 %
    for key in (f"joints.{j}.valve.rated_flow", f"effects.sensor_gain.{j}.gain", f"effects.payload.{j}.mass"):
        e = rows[key].get("elasticity_to_held", {}).get("supply.pressure", 0.0)
        there = again[key]["value"] if key in again else gauged["calibration"]["values"][key]   # not refitted: held
        assert rows[key]["value"] * 0.9 ** e == pytest.approx(there, rel=0.01), (key, e)


@pytest.mark.parametrize("template", list(TEMPLATES))
def test_a_clean_record_of_an_off_nominal_rig_is_no_discrepancy(cli, tmp_path, template):
    j, d = _diagnose(cli, tmp_path, template, None)
    assert d["verdict"] == "no_significant_discrepancy", d["selected"]
    # what that verdict cannot vouch for on a position-only log with the supply estimated
    spots = d["calibration"]["blind_spots"]
    assert len(spots) == 1 and spots[0].startswith(f"{j}: a Coulomb friction") and "supply.pressure" in spots[0]
    assert (tmp_path / "stdout.txt").read_text().count("not testable: ") == 1


def test_a_log_slower_than_its_controller_is_replayed_as_period_means_and_found_clean(cli, tmp_path):
    """The rig's controller runs at 1 kHz and a PLC logs every 100th sample (10 Hz): the reference steps
    fall between logged samples. The command is replayed as each period's mean (command_hold.py);
    where within its 100 ms each step came is not in the log, and what that alone leaves a perfect
    model joins the noise in the channels' ceilings (step_timing.py). Nothing is named: with the held
    replay the record was unexplained, and with the period mean alone a 2.6 % valve asymmetry bought
    back the whole-record angle's drift while the velocity and the restarted angle lost (the drift
    rule). The report says how the command was replayed."""
    j, d = _diagnose(cli, tmp_path, "cylinder", None, rate=10.0, log_every=100)
    assert d["closed_loop"] is True
    hold = d["closed_loop_evidence"]["command_hold"]
    assert hold["replay"] == "period_mean" and hold["joints"] == [j]
    lost = hold["step_timing"]["ceiling_points_lost"][j]
    assert lost["angle"] > 1.0 and lost["angle"] > lost["restarted"]
    assert d["verdict"] == "no_significant_discrepancy", (d["selected"], d["unexplained"])
    assert any("mean of each two logged samples" in n for n in d["data"]["notes"])
    assert "Command between samples" in (tmp_path / "rep" / "report.html").read_text()


def test_sensor_calibration_ranges_stay_inside_the_effects_bounds(tmp_path, cli):
    """The rotary template's sensor offset range (B +-0.52 rad) is wider than the sensor_offset
    effect allows (+-0.5 rad): the calibration searches the intersection instead of failing."""
    cli("rig", "new", "rotary", "--out", tmp_path / "rig", check=True)
    spec = load_robot(tmp_path / "rig")
    j = spec.joint_names[0]
    lo, hi = spec.estimated[f"joints.{j}.sensor.B"]
    nominal = spec.get(f"joints.{j}.sensor.B")
    assert max(hi - nominal, nominal - lo) > 0.5      # the premise
    rows, _ = closed_loop_record(tmp_path / "rig", hidden=None, off={}, seed=1, duration=5.0)
    rec = as_record(spec, rows)
    m = spec.copy()
    pl = plan(m, rec)
    fp = next(f for f in pl.free if f.key == f"effects.sensor_offset.{j}.offset")
    assert -0.5 <= fp.lower < 0.0 < fp.upper <= 0.5
    # the reason a user reads names what the spec estimates (B, in its range) and the range searched
    # for the offset it causes, not B's range under the offset's name
    why = pl.why[fp.key]
    assert f"joints.{j}.sensor.B in [{lo:g}, {hi:g}]" in why, why
    assert f"range [{fp.lower:g}, {fp.upper:g}]" in why, why


def test_a_leak_the_rigs_calibration_absorbs_is_still_named(cli, tmp_path):
    """An internal leak on the boom rig (4 % of the valve's full flow at supply pressure): with six
    estimated rig parameters free, the baseline calibration takes much of it up (load, sensor gain and
    offset move far from the truth), and a candidate started only from those values cannot get back.
    Each candidate also starts from the rig's values before calibration: the leak is named. Its
    coefficient is what the record fixes only through the leak flow C (p_a - p_b); without pressures
    the supply (15 % low here) is not identified and stays nominal, so C can carry up to
    1/0.85 - 1 = 18 % of the supply's error; the load, kept beside the flow gain because the two
    matter together (elimination.py), carries most of it: within 15 % (-8.2 % at this seed, -12.9 %
    when the supply and the load went back to nominal together). The diagnosis says the coefficient
    is conditional on the supply, with its elasticity (percent per percent of the supply)."""
    leak = _sized_leak(cli, tmp_path, "boom")
    j, d = _diagnose(cli, tmp_path, "boom", ("leakage", {"internal": leak}))
    assert d["verdict"] == "discrepancy"
    assert [s["effect"] for s in d["selected"]] == ["leakage"], d["selected"]
    named = d["selected"][0]
    assert named["params"]["internal"] == pytest.approx(leak, rel=0.15, abs=0)
    assert "supply.pressure" in named["conditional_on"], named
    e = named["elasticity_to_held"]["internal"]["supply.pressure"]
    # a leak flow C dp with dp about proportional to the supply: C goes as 1 / supply
    assert -1.5 < e < -0.5, e
    # as the supply spans the range the rig's spec declares, the coefficient spans one that holds the truth
    s = named["range_given_held"]["internal"]
    assert s["lower"] <= leak <= s["upper"] and s["over"] == {"supply.pressure": list(load_robot(tmp_path / "rig").estimated["supply.pressure"])}, s


def test_a_leak_fitted_beside_the_rigs_nuisances_is_fitted_to_its_optimum(cli, tmp_path):
    """The same leak at another seed: the calibration takes it up as a lighter load and a higher viscous
    friction, and the leak's candidate refits those beside its own two coefficients, ranked from 15
    starting points. With the candidates' fixed budget of 45 simulations it had three iterations
    left, stopped a decade short (1.8e-13) and nothing was named, with the angle 6 points under its
    noise ceiling; each fit now gets iterations for all its free parameters (selection.Setting.budget).
    The coefficient hangs on the supply held at nominal (the truth's is 15 % lower): corrected with
    its elasticity to the true supply it comes within 15 %."""
    from sim_core.identification.conditional import corrected

    leak = _sized_leak(cli, tmp_path, "boom")
    j, d = _diagnose(cli, tmp_path, "boom", ("leakage", {"internal": leak}), seed=3)
    assert d["verdict"] == "discrepancy", (d["verdict"], d.get("unexplained"))
    assert [s["effect"] for s in d["selected"]] == ["leakage"], d["selected"]
    named = d["selected"][0]
    held = named["elasticity_to_held"]["internal"]
    assert corrected(named["params"]["internal"], held, {"supply.pressure": OFF["supply.pressure"]}) == \
        pytest.approx(leak, rel=0.15, abs=0), (named["params"], held)


def test_a_leak_that_pushes_the_calibration_to_its_ranges_ends_is_named(cli, tmp_path):
    """An internal leak on the rotary rig (4 % of the valve's full flow at supply pressure): the rig's
    calibration, fitting the leaking record without a leak, runs its supply pressure, sensor gain and
    load to the ends of their [estimated] ranges. A value stopped on a bound is not measured (the
    record asks for more than the range allows, some misfit absorbed as far as it may be): those go
    back to nominal, and the leak is named instead of the valve null offset that the skewed baseline
    made look best (which it did before this rule). The coefficient within 15 %."""
    leak = _sized_leak(cli, tmp_path, "rotary")
    j, d = _diagnose(cli, tmp_path, "rotary", ("leakage", {"internal": leak}))
    rows = {r["parameter"]: r for r in d["calibration"]["changes"]}
    assert any("end of its range" in (r.get("not_identified_because") or "") for r in rows.values())
    assert [s["effect"] for s in d["selected"]] == ["leakage"], d["selected"]
    assert d["selected"][0]["params"]["internal"] == pytest.approx(leak, rel=0.15, abs=0)


def test_a_leak_the_record_cannot_split_is_given_whole_to_the_cross_port_leak(cli, tmp_path):
    """An internal (cross-port) leak on the rotary rig at seed 2. Without chamber pressures a leak
    across the vanes and one from each chamber to tank slow the motor alike; the candidate fits both,
    and the split followed the noise: the cross-port coefficient came 22 % low, with a leak to tank
    beside it. A named effect's secondary parameter must now be worth the threshold as the effect is:
    held at the effect's default (none to tank) with the rest refitted, the leak to tank costs a
    fraction of a point, so it stays there, the report says so, and the cross-port coefficient
    carries the whole leak, within 15 %."""
    leak = _sized_leak(cli, tmp_path, "rotary")
    j, d = _diagnose(cli, tmp_path, "rotary", ("leakage", {"internal": leak}), seed=2)
    assert [s["effect"] for s in d["selected"]] == ["leakage"], d["selected"]
    named = d["selected"][0]
    assert named["params"]["internal"] == pytest.approx(leak, rel=0.15, abs=0), named["params"]
    assert named["params"]["external"] == 0.0
    assert list(named["held_at_default"]) == ["external"] and named["held_at_default"]["external"]["value"] == 0.0
    assert "external held at its default 0" in (tmp_path / "stdout.txt").read_text()
    assert "<b>Held</b>: external = 0" in (tmp_path / "rep" / "report.html").read_text()


def test_a_hanging_load_on_a_valve_far_larger_than_its_spec_keeps_its_flow_gain(cli, tmp_path):
    """A cylinder holding a load that hangs below it (incline_deg=-90: lifting is retracting), its
    valve 60 % larger and its supply 25 % lower than the written spec, a 0.8 V deadband, P control,
    no pressures. The flow gain, the supply and the sensor gain explain the speed together and none
    is identified by itself; the calibration sent them all back to nominal, left the model 1.6x too
    slow and the deadband's fit 18 points under the noise ceiling (unexplained). The flow gain is
    the baseline and goes last: the deadband is named within 2 %, and the model fits to its ceiling."""
    j, d = _diagnose(cli, tmp_path, "cylinder", ("deadband", {"width": 0.8}), seed=1, rig_set=("incline_deg=-90",),
                     off_nominal={"valve.rated_flow": 1.6, "supply.pressure": 0.75})
    assert d["verdict"] == "discrepancy", d.get("unexplained")
    assert [s["effect"] for s in d["selected"]] == ["deadband"], d["selected"]
    assert d["selected"][0]["params"]["width"] == pytest.approx(0.8, rel=0.02)
    rows = {r["parameter"]: r for r in d["calibration"]["changes"]}
    assert rows[f"joints.{j}.valve.rated_flow"]["identified"]
    assert d["extended"]["fit"][j] >= 99.0


def test_every_candidate_refits_a_flow_gain_the_baseline_could_not_keep(cli, tmp_path):
    """A hanging load on a valve 40 % smaller than its spec that passes 30 % less one way (a valve
    asymmetry of 0.7), P control, no pressures. Without the asymmetry the nominal model drifts off the
    record whatever its flow gain (baseline fit far below zero); the flow gain's fit stops at the end of
    its range and goes back to nominal, 1.7x the truth. Candidates fitted at that flow gain compete at
    making the model slower, not at explaining the record (a large Coulomb friction does that best).
    The flow gain is the baseline: every candidate refits it, identified by the calibration or not,
    and the asymmetry is named within 3 % with the model at its noise ceiling."""
    j, d = _diagnose(cli, tmp_path, "cylinder", ("valve_asymmetry", {"ratio": 0.7}), seed=7,
                     rig_set=("incline_deg=-90",), off_nominal={"valve.rated_flow": 0.6, "supply.pressure": 1.1})
    rows = {r["parameter"]: r for r in d["calibration"]["changes"]}
    flow = rows[f"joints.{j}.valve.rated_flow"]
    assert not flow["identified"] and "end of its range" in flow["not_identified_because"]     # the premise
    assert d["baseline"]["fit"][j] < 0.0
    assert [s["effect"] for s in d["selected"]] == ["valve_asymmetry"], (d["verdict"], d["selected"])
    assert d["selected"][0]["params"]["ratio"] == pytest.approx(0.7, rel=0.03)
    ceiling = d["decision"]["channel_ceilings"][j]["angle"]
    assert d["extended"]["fit"][j] >= ceiling - 1.0


def test_a_deadband_under_sine_tracking_is_named_with_the_load_carrying_the_supply(cli, tmp_path):
    """The cylinder rig tracking a slow sine (the load lifted and lowered all the time, the valve never
    at rest) with a 1.2 V deadband, no pressures (found closed loop, such a record shows a deadband
    from about 1.1 V: its `detectable` row; 0.8 V gains 1.9-2.1 points, on the 2-point threshold).
    Beside the identified flow gain the supply and the load are each under 3 sigma (either trades against the other: their ratio sets the load
    pressure), but together the record needs them: reset both to nominal, the baseline's cost rose
    28-fold, every candidate gained about as much by making up for it (seven within 1.2 points) and
    the deadband was named an area ratio. Now only the weaker goes: the load carries what the two
    explained, its row says it is conditional on the supply, and the deadband is named within 15 %."""
    j, d = _diagnose(cli, tmp_path, "cylinder", ("deadband", {"width": 1.2}), seed=4, reference=sine_reference)
    assert d["closed_loop"]
    assert [s["effect"] for s in d["selected"]] == ["deadband"], d["selected"]
    assert d["selected"][0]["params"]["width"] == pytest.approx(1.2, rel=0.15)
    rows = {r["parameter"]: r for r in d["calibration"]["changes"]}
    load = rows[f"effects.payload.{j}.mass"]
    assert load["identified"] and not rows["supply.pressure"]["identified"]
    assert "supply.pressure" in load["conditional_on"]
    # `hydrohil fit` keeps them by the same rules: reset all at once it ended where it started
    # (angle fit 59.7 -> 59.7 %; 98.9 % with the load kept, the deadband's misfit left)
    proc = cli("fit", "--robot", tmp_path / "rig", tmp_path / "rec.csv", "--out", tmp_path / "fit.toml", "--json")
    assert proc.returncode == 0, proc.stderr
    fitted = json.loads(proc.stdout)
    assert fitted["parameters"][f"effects.payload.{j}.mass"]["identified"]
    angle = next(iter(fitted["fit"].values()))[j]["angle"]          # the one record (no --validation)
    assert angle["after"] > angle["before"] + 20.0, angle


@pytest.mark.parametrize("template", ["cylinder", "rotary"])
def test_coulomb_friction_is_named_once_the_supply_and_the_load_are_measured(cli, tmp_path, template):
    """Without pressures a P loop shows friction only through the speeds it reaches each way per volt:
    two figures, against a flow gain, a supply and a load that are each unknown and each trade
    against a friction (bench_rig_diagnosis.py: 0 of 9 at 6 % of the full force). A user who reads
    the supply off the pump's gauge and weighs the load writes both into robot.toml and deletes
    their [estimated] lines; the flow gain is left to calibrate. Then a Coulomb friction of 6 % of
    the full-pressure force is named alone within 15 %."""
    cli("rig", "new", template, "--out", tmp_path / "sizing", check=True)
    spec = load_robot(tmp_path / "sizing")
    j = spec.joint_names[0]
    torque = 0.06 * actuator_scales(spec, j)["torque"]
    _, d = _diagnose(cli, tmp_path, template, ("coulomb_friction", {"torque": torque}),
                     measure=("supply.pressure", f"effects.payload.{j}.mass"))
    held = load_robot(tmp_path / "rig_measured").estimated
    assert "supply.pressure" not in held and f"joints.{j}.valve.rated_flow" in held      # the premise
    assert [s["effect"] for s in d["selected"]] == ["coulomb_friction"], (d["verdict"], d["selected"])
    assert d["selected"][0]["params"]["torque"] == pytest.approx(torque, rel=0.15)
    assert d["calibration"]["blind_spots"] == []


def test_a_recalibration_sends_what_it_cannot_identify_back_to_the_spec_not_to_the_baseline(cli, tmp_path):
    """The boom rig under a 10 Hz P loop with a 0.25 V valve null offset. Without the offset in the
    model the baseline calibration explains the creep with a sensor offset of about 0.3 rad, which
    it identifies. Once the valve offset is named the calibration is redone: the sensor offset is then
    not identified (|value/sigma| < 1). Sent back to the baseline's 0.3 rad, the model stayed 11
    points under its noise ceiling and the verdict was unexplained_discrepancy. Sent back to the
    spec's value (no offset), the valve offset is named within 15 % and the model fits to its ceiling."""
    j, d = _diagnose(cli, tmp_path, "boom", ("valve_offset", {"offset": 0.25}), seed=1, rate=10.0)
    base = {c["parameter"]: c for c in d["calibration"]["changes"]}
    key = f"effects.sensor_offset.{j}.offset"
    assert base[key]["identified"] and abs(base[key]["value"]) > 0.1          # the premise: the stand-in
    again = {c["parameter"]: c for c in d["calibration"]["recalibrations"][0]["changes"]}
    assert not again[key]["identified"] and again[key]["value"] == again[key]["nominal"] == 0.0
    assert [s["effect"] for s in d["selected"]] == ["valve_offset"], (d["verdict"], d["selected"])
    assert d["selected"][0]["params"]["offset"] == pytest.approx(0.25, rel=0.15)
    assert d["extended"]["fit"][j] >= d["decision"]["channel_ceilings"][j]["angle"] - 1.0


def test_the_extended_model_carries_the_calibration_refitted_with_the_named_effect(cli, tmp_path):
    """A deadband on the cylinder rig, its valve and supply off the spec, no pressures: the baseline,
    misled by the deadband, identifies little; once the deadband is named the recalibration
    identifies more (the load, the seal friction), and the final refit fits them beside it. The
    extended model is that model: extended.toml must carry those values (``simulate --params`` runs
    what was diagnosed), diagnosis.json and the output say them with what they hang on, and each,
    corrected with its elasticity to the true supply, comes to the truth."""
    from sim_core.identification.parameters import free_parameter
    from sim_core.params_file import apply_params_file

    j, d = _diagnose(cli, tmp_path, "cylinder", ("deadband", {"width": 0.8}))
    assert [s["effect"] for s in d["selected"]] == ["deadband"]
    refitted = d["calibration"]["refitted_with_effects"]
    newly = [k for r in d["calibration"]["recalibrations"] for k in r["newly_identified"]]
    assert newly and set(newly) <= set(refitted), (newly, refitted)           # the premise
    spec = load_robot(tmp_path / "rig")
    extended = apply_params_file(spec.copy(), tmp_path / "rep" / "extended.toml")
    for k, r in refitted.items():
        assert free_parameter(extended, k).get(extended) == pytest.approx(r["value"], rel=1e-5), k
    printed = (tmp_path / "stdout.txt").read_text()
    load = f"effects.payload.{j}.mass"
    assert f"calibrated with it: {load} = " in printed and "given supply.pressure" in printed
    truth = {load: free_parameter(spec, load).get(spec),
             f"joints.{j}.valve.rated_flow": spec.get(f"joints.{j}.valve.rated_flow") * OFF["valve.rated_flow"]}
    for k, true in truth.items():
        r = refitted[k]
        corrected = r["value"] * OFF["supply.pressure"] ** r["elasticity_to_held"]["supply.pressure"]
        assert corrected == pytest.approx(true, rel=0.05), (k, r, true)

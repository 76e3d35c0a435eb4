"""What a record cannot test for: a Coulomb friction beside an estimated supply or load, without
chamber pressures (sim_core/identification/blind_spots.py). No simulation: the rule alone."""

from sim_core.identification import blind_spots

FLOW = "joints.lift.valve.rated_flow"


def test_an_estimated_supply_or_load_hides_a_friction_on_a_position_only_record():
    for free in ([FLOW, "supply.pressure"], [FLOW, "effects.payload.lift.mass"], [FLOW, "links.mass_scale"]):
        spots = blind_spots.friction(free, ["lift"], False, None, set())
        assert len(spots) == 1 and spots[0].startswith("lift: a Coulomb friction") and free[1] in spots[0]


def test_measured_supply_and_load_pressures_or_a_named_friction_leave_nothing_to_say():
    both = [FLOW, "supply.pressure", "effects.payload.lift.mass"]
    assert blind_spots.friction([FLOW], ["lift"], False, None, set()) == []                  # measured
    assert blind_spots.friction(both, ["lift"], True, None, set()) == []                     # pressures
    assert blind_spots.friction(both, ["lift"], False, ["deadband"], set()) == []            # not searched
    assert blind_spots.friction(both, ["lift"], False, None, {("coulomb_friction", "lift")}) == []


def test_each_joint_is_said_once_with_its_own_load():
    free = [FLOW, "effects.payload.boom.mass"]
    spots = blind_spots.friction(free, ["lift", "boom"], False, None, set())
    assert len(spots) == 1 and spots[0].startswith("boom:") and "effects.payload.boom.mass" in spots[0]

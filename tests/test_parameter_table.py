"""amr_common.plugins.parameter_table: defaults, overrides and the checks of each table's rules."""
from __future__ import annotations

import importlib
import math
import pickle

import numpy as np
import pytest

from amr_common.plugins.parameter_table import (
    Param,
    above,
    at_least,
    between,
    check_values,
    checked_values,
    defaults,
    finite,
    one_of,
    rule_of,
    ruled,
    table_values,
    vector,
)

TABLE = {"kp": (10.0, "gain"), "side": ("right", "side")}


def test_overrides_replace_defaults_and_the_rest_keep_theirs():
    assert table_values(TABLE, {"kp": 5}, "Thing") == {"kp": 5, "side": "right"}
    assert table_values(TABLE, None, "Thing") == {"kp": 10.0, "side": "right"}


def test_an_unknown_name_is_refused_with_the_known_ones():
    with pytest.raises(ValueError, match=r"Thing: unknown parameter\(s\) \['speed'\]; "
                                         r"known: \['kp', 'side'\]"):
        table_values(TABLE, {"speed": 1.0, "kp": 1.0}, "Thing")


@pytest.mark.parametrize("value, expected", [
    (1, True), (-2.5, True), (np.float64(0.1), True), (0, True),
    (True, False), (math.nan, False), (math.inf, False), (-math.inf, False), ("1", False),
    (None, False), ([1.0], False)])
def test_finite_means_a_finite_int_or_float_not_a_bool(value, expected):
    assert finite(value) is expected


# --- rules: the checks come from the tables -----------------------------------------------------
RULED = {"gain": Param(10.0, "a gain", at_least(0.0)),
         "count": Param(3, "a count", between(1, 10)),
         "share": Param(0.5, "a share", between(0.0, 1.0, low_open=True)),
         "side": Param("right", "a side", one_of("right", "left")),
         "on": Param(True, "a switch"),
         "pose": Param([], "a pose", vector(0, 3)),
         "sigma": Param([0.1, 0.1], "two sigmas", vector(2, low=0.0)),
         "offset": (0.0, "a plain pair: any finite number")}


def test_a_param_is_still_a_default_description_pair():
    default, description = RULED["gain"]
    assert (default, description) == (10.0, "a gain") and RULED["gain"] == (10.0, "a gain")
    assert rule_of(RULED["gain"]) == at_least(0.0) and rule_of(RULED["offset"]) is None
    assert rule_of(pickle.loads(pickle.dumps(RULED["count"]))) == between(1, 10)


def test_values_are_normalised_to_the_defaults_types():
    values = checked_values(RULED, {"gain": 5, "count": 4.0, "side": " LEFT", "on": "false",
                                    "pose": [1, 2, 3], "sigma": np.array([0.0, 2])})
    assert values == {"gain": 5.0, "count": 4, "share": 0.5, "side": "left", "on": False,
                      "pose": (1.0, 2.0, 3.0), "sigma": (0.0, 2.0), "offset": 0.0}
    assert type(values["gain"]) is float and type(values["count"]) is int


def test_every_problem_is_named_with_the_rule_it_breaks():
    with pytest.raises(ValueError) as error:
        checked_values(RULED, {"gain": -1, "count": 2.5, "share": 0.0, "side": "up", "on": 1,
                               "pose": [1, 2], "sigma": [0.1, -0.1], "offset": math.nan},
                       "Thing")
    assert str(error.value) == (
        "Thing: gain must be >= 0 (got -1.0); count must be an integer (got 2.5); "
        "share must be in (0, 1] (got 0.0); side must be one of ['right', 'left'] (got 'up'); "
        "on must be true or false (got 1); pose must be [] or 3 finite numbers (got [1, 2]); "
        "sigma must have each number >= 0 (got [0.1, -0.1]); "
        "offset must be a finite number (got nan)")


def test_ruled_gives_the_numbers_a_common_rule_and_refuses_unknown_names():
    table = ruled({"a": (1.0, "a"), "b": (-1.0, "b"), "n": (2, "n"), "s": ("x", "s")},
                  at_least(0.0), b=None)
    assert [rule_of(table[name]) for name in "abns"] == [at_least(0.0), None, at_least(0.0),
                                                          None]
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) \['typo'\]"):
        ruled({"a": (1.0, "a")}, typo=above(0.0))


TABLES = {  # owner: (module, table)
    "wall follower": ("amr_control.wall_follower_params", "PARAMETERS"),
    "pure pursuit": ("amr_control.pure_pursuit", "PARAMETERS"),
    "planner": ("amr_planning.planner", "PARAMETERS"),
    "particle filter": ("amr_localization.particle_filter_params", "PARAMETERS"),
    "mapper": ("amr_mapping.mapper_params", "PARAMETERS"),
    "simulator": ("amr_sim.simulator_params", "PARAMETERS"),
    "odometry node": ("amr_turtlebot3.odometry_node", "_PARAMETERS"),
    "wall follower node": ("amr_control.wall_follower_node", "_NODE_PARAMETERS"),
    "pure pursuit node": ("amr_control.pure_pursuit_node", "_NODE_PARAMETERS"),
    "particle filter node": ("amr_localization.particle_filter_node", "_NODE_PARAMETERS"),
    "planner node": ("amr_planning.planner_node", "_NODE_PARAMETERS"),
    "map publisher": ("amr_tools.map_publisher", "_PARAMETERS"),
    "foxglove bridge": ("amr_tools.foxglove_bridge", "PARAMETERS"),
}


@pytest.mark.parametrize("owner", TABLES)
def test_every_tables_defaults_keep_its_own_rules(owner):
    module, name = TABLES[owner]
    table = getattr(importlib.import_module(module), name)
    assert check_values(table, defaults(table))[1] == []
    assert any(rule_of(entry) for entry in table.values()), f"{owner}: no parameter with a rule"


def test_the_filters_localized_test_and_motion_noise_default_to_its_table():
    # One home for the filter's defaults: CheckSettings once had its own (reinit 0.5 / 3 updates
    # against the table's 0.75 / 10), so a decision built without the filter disagreed with it.
    from amr_localization.localization_check import CheckSettings
    from amr_localization.motion_model import MotionNoise
    from amr_localization.particle_filter_params import check_parameters
    table = check_parameters({})
    settings = CheckSettings()
    for name in CheckSettings.__dataclass_fields__:
        assert getattr(settings, name) == table[name], name
    noise = MotionNoise()
    assert (noise.v_per_v, noise.v_per_w, noise.w_per_w, noise.w_per_v) == (
        table["noise_v_per_v"], table["noise_v_per_w"], table["noise_w_per_w"],
        table["noise_w_per_v"])

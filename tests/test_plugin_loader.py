"""amr_common.plugins.loader: controller specs and parameter overrides.

"MODULE:CLASS" specs with errors that name the problem, and `name:=value` overrides typed like
ROS parameters.
"""
from __future__ import annotations

import pytest

from amr_common.plugins.loader import (
    DEFAULT_CONTROLLER,
    PluginSpecError,
    load_controller_class,
    parse_overrides,
    parse_value,
)
from tests.controllers import ConstantController


class NotCallable:
    compute_commands = 3.0


def test_a_spec_loads_the_class():
    from amr_control.wall_follower import WallFollower
    assert load_controller_class(DEFAULT_CONTROLLER) is WallFollower
    assert load_controller_class("  tests.controllers:ConstantController\n") is ConstantController


@pytest.mark.parametrize("spec, message", [
    ("amr_control.wall_follower.WallFollower", "must look like MODULE:CLASS"),
    (":WallFollower", "must look like MODULE:CLASS"),
    ("amr_control.wall_follower:", "must look like MODULE:CLASS"),
    ("amr_control.no_such_module:X", "cannot import module 'amr_control.no_such_module'"),
    ("amr_control.wall_follower:WallFolower", "module 'amr_control.wall_follower' has no "
                                               "'WallFolower'"),
    ("json:JSONDecoder", "has no compute_commands"),
    (f"{__name__}:NotCallable", "has no compute_commands"),
])
def test_a_bad_spec_names_the_problem(spec, message):
    with pytest.raises(PluginSpecError, match=message) as error:
        load_controller_class(spec)
    assert f"controller '{spec}'" in str(error.value)
    assert isinstance(error.value, ValueError)  # callers that catch ValueError see it too


def test_values_are_typed_like_ros_parameters():
    cases = {"true": True, "False": False, " TRUE ": True, "4": 4, "-2": -2, "0": 0,
             "0.25": 0.25, "-0.5": -0.5, "1e3": 1000.0, "-1e-3": -0.001, ".5": 0.5,
             "right": "right", "-": "-", "": "", "1.2.3": "1.2.3", "0.2m": "0.2m"}
    for text, expected in cases.items():
        value = parse_value(text)
        assert value == expected and type(value) is type(expected), text


@pytest.mark.parametrize("text", ["nan", "NaN", "inf", "-inf", "Infinity", "1e999", "-1e999"])
def test_non_finite_values_are_rejected(text):
    with pytest.raises(PluginSpecError, match=f"value '{text}' is not finite"):
        parse_value(text)


def test_overrides_are_typed_like_ros_parameters():
    got = parse_overrides(["kp:=4", "kd:=0.25", "follow_left:=true", "side:=right", "big:=1e3",
                           "off:=False", "neg:=-2"])
    assert got == {"kp": 4, "kd": 0.25, "follow_left": True, "side": "right", "big": 1000.0,
                   "off": False, "neg": -2}
    assert type(got["kp"]) is int and type(got["kd"]) is float and type(got["follow_left"]) is bool


def test_override_names_values_and_order():
    assert parse_overrides(None) == {} and parse_overrides([]) == {}
    assert parse_overrides([" kp :=1", "kp:=2"]) == {"kp": 2}  # trimmed name, the last wins
    assert parse_overrides(["world:=a:=b"]) == {"world": "a:=b"}  # only the first := splits
    assert parse_overrides(["offset:=-0.032"]) == {"offset": -0.032}
    assert parse_overrides(["_private:=1", "ns.kp:=2"]) == {"_private": 1, "ns.kp": 2}


def test_lists_are_typed_like_ros_parameters():
    assert parse_value("[0.0,0.0,0.0]") == [0.0, 0.0, 0.0]
    assert parse_value(" [1, -2.5, true, a] ") == [1, -2.5, True, "a"] and parse_value("[]") == []
    assert parse_overrides(["initial_pose:=[1.0, -1.0, 1.57]"]) == {
        "initial_pose": [1.0, -1.0, 1.57]}


@pytest.mark.parametrize("item, message", [
    ("__node:=evil", "'__node' is not a parameter name"),  # rcl would rename every node
    ("__ns:=/evil", "'__ns' is not a parameter name"),
    ("a/b:=1", "'a/b' is not a parameter name"),
    ("~kp:=1", "'~kp' is not a parameter name"),
    ("kp:=[1, nan]", "override 'kp:=\\[1, nan\\]': value 'nan' is not finite"),
    ("kp=4", "override 'kp=4' must look like name:=value"),
    (":=4", "must look like name:=value"),
    ("  :=4", "must look like name:=value"),
    ("kp:=nan", "not finite"),
])
def test_bad_overrides_are_rejected(item, message):
    with pytest.raises(PluginSpecError, match=message):
        parse_overrides([item])

"""amr_common.parameter_table: the defaults-plus-overrides every algorithm checks, and `finite`."""
from __future__ import annotations

import math

import numpy as np
import pytest

from amr_common.parameter_table import finite, table_values

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

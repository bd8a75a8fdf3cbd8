"""The measures of SLAM on real logs: the relation error (Kuemmerle et al. 2009), self-consistency.

Hand-made cases with answers worked out by hand, the file reader's refusals, and the measures
on the shipped slice of the Intel log.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from amr_common.world.map_raster import FREE, OCCUPIED, UNKNOWN, Raster
from amr_evaluation.relation_error import (
    RelationFileError,
    read_relations,
    relation_errors,
    self_consistency,
    stamp_indices,
)
from amr_mapping.scan_points import Scan

DATA = Path(__file__).resolve().parent / "data"


def test_a_hand_made_estimate_has_the_errors_worked_out_by_hand():
    # The estimate: at t=0 at the origin facing +y; at t=1 one metre ahead of it (0, 1), turned
    # 10 deg left; at t=2 back at the origin, turned 179 deg.
    stamps = [0.0, 1.0, 2.0]
    poses = [(0.0, 0.0, math.pi / 2), (0.0, 1.0, math.pi / 2 + math.radians(10)),
             (0.0, 0.0, math.pi / 2 + math.radians(179))]
    relations = np.array([
        # seen from t=0 the estimate puts t=1 at (1, 0) turned 10 deg; the truth: (1.03, 0.04)
        # turned 12 deg -> |dt| = 0.05 m, |dtheta| = 2 deg
        [0.0, 1.0, 1.03, 0.04, math.radians(12)],
        # t=0 -> t=2: estimate (0, 0) turned 179 deg; truth turned -179 deg: 2 deg the short way
        [0.0, 2.0, 0.0, 0.0, math.radians(-179)],
        [0.0, 3.0, 1.0, 0.0, 0.0],  # t=3 is not a stamp of the estimate: not used
    ])
    errors = relation_errors(stamps, poses, relations)
    assert errors.used.tolist() == [0, 1] and errors.total == 3
    assert errors.translation_m == pytest.approx([0.05, 0.0], abs=1e-12)
    assert errors.rotation_deg == pytest.approx([2.0, 2.0], abs=1e-9)
    assert errors.translation == pytest.approx((0.025, 0.025))
    assert errors.translation_squared == pytest.approx((0.00125, 0.00125))
    assert errors.rotation == pytest.approx((2.0, 0.0))
    assert errors.rotation_squared == pytest.approx((4.0, 0.0))
    assert errors.summary() == "0.0250 +- 0.0250 m, 2.000 +- 0.000 deg (2 of 3 relations)"
    assert errors.as_dict()["relations_used"] == 2


def test_stamps_match_within_a_millisecond_and_repeated_stamps_take_the_first():
    stamps = np.array([5.0, 3.0, 4.0, 4.0, 6.0])  # out of order, 4.0 twice (indices 2 and 3)
    queries = np.array([4.0, 4.0004, 3.0, 6.0009, 5.5, 2.0, 7.0])
    assert stamp_indices(stamps, queries).tolist() == [2, 2, 1, 4, -1, -1, -1]
    assert stamp_indices([], queries).tolist() == [-1] * 7


def test_no_relation_inside_gives_nan_not_a_crash():
    errors = relation_errors([0.0], [(0.0, 0.0, 0.0)], np.array([[1.0, 2.0, 0.0, 0.0, 0.0]]))
    assert len(errors.used) == 0 and math.isnan(errors.translation[0])


@pytest.mark.parametrize("text,message", [
    ("1 2 3 4 5 6 7\n", "line 1: 7 fields, expected 8"),
    ("# header\n1 2 0.1 0.2 0 0 0 x\n", "line 2: not all numbers"),
    ("1 2 0.1 nan 0 0 0 0.3\n", "line 1: not finite"),
])
def test_a_malformed_relations_file_names_the_line(tmp_path, text, message):
    path = tmp_path / "bad.relations"
    path.write_text(text)
    with pytest.raises(RelationFileError, match=message):
        read_relations(path)
    with pytest.raises(RelationFileError, match="cannot read relations"):
        read_relations(tmp_path / "missing.relations")


def test_the_shipped_relations_read_as_x_y_yaw():
    relations = read_relations(DATA / "intel-1000-1399.relations")
    assert relations.shape == (60, 5)
    assert np.all(relations[:, 1] > relations[:, 0])
    assert np.abs(relations[:, 2:4]).max() < 1.5  # manually verified matches: under 1.5 m


def test_self_consistency_is_the_share_of_returns_near_an_occupied_cell():
    # A 5 cm map: a wall one cell thick at x in [2.0, 2.05), y in [-2, 2), free before it.
    values = np.full((80, 81), FREE, dtype=np.int8)  # x in [-2, 2.05), y in [-2, 2)
    values[:, 80] = OCCUPIED  # the last column: x in [2.0, 2.05)
    values[:10, :10] = UNKNOWN
    raster = Raster(values, 0.05, (-2.0, -2.0))
    # A scan from the origin, facing +x: 4 returns on the wall (x = 2.0), 2 half a metre short
    # of it, 1 at 25 m (beyond 20 m: not counted), 1 with no return (NaN).
    angles = np.radians([-10.0, -5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 25.0])
    ranges = 2.0 / np.cos(angles)
    ranges[4:6] -= 0.5
    ranges[6], ranges[7] = 25.0, math.nan
    scan = Scan(ranges, float(angles[0]), math.radians(5.0), 0.05, 30.0)
    assert self_consistency(raster, [(0.0, 0.0, 0.0)], [scan]) == pytest.approx(4 / 6)
    # The same scan drawn from a pose 20 cm off: no return lands near the wall.
    assert self_consistency(raster, [(-0.2, 0.0, 0.0)], [scan]) == 0.0
    # A pose that is not finite leaves its scan out; nothing left: NaN.
    assert math.isnan(self_consistency(raster, [(math.nan, 0.0, 0.0)], [scan]))

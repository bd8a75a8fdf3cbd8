"""The Mapper on real data: 400 scans of the Intel Research Lab log, with its defaults.

tests/data/intel-1000-1399.clf.gz (80 s of a real robot's SICK scans and raw odometry; 24 scans
stamped at or before the scan before, and more at or before the latest stamp so far) with the
60 ground-truth relations inside it. Only the sensor's facts are set (5 cm cells, 50 m range),
as scripts/bench_realdata.py does on the whole log.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from amr_evaluation.relation_error import read_relations, relation_errors, self_consistency
from amr_mapping.mapper import Mapper
from amr_tools.carmen_log import read_carmen_log

DATA = Path(__file__).resolve().parent / "data"
SENSOR_FACTS = {"resolution_m": 0.05, "max_range_m": 50.0}


@pytest.fixture(scope="module")
def mapped():
    log = read_carmen_log(DATA / "intel-1000-1399.clf.gz")
    mapper = Mapper(SENSOR_FACTS)
    for scan in log.scans:
        mapper.update(scan, scan.odometry, scan.stamp)
    return log, mapper


def test_every_scan_gets_a_pose_at_its_own_stamp_out_of_order_ones_too(mapped):
    log, mapper = mapped
    stamps = np.array([scan.stamp for scan in log.scans])
    trajectory = mapper.trajectory()
    assert trajectory[:, 0].tolist() == stamps.tolist()  # every scan, in the order given
    assert np.isfinite(trajectory).all()
    stats = mapper.statistics()
    late = np.count_nonzero(stamps[1:] <= np.maximum.accumulate(stamps)[:-1])
    assert stats["out_of_order"] == late > 24 and stats["rejected"] == {}
    assert stats["odometry_only"] == 0 and stats["odometry_jumps"] == 0


def test_the_relation_error_is_below_the_targets_and_far_below_the_odometry(mapped):
    log, mapper = mapped
    relations = read_relations(DATA / "intel-1000-1399.relations")
    trajectory = mapper.trajectory()
    slam = relation_errors(trajectory[:, 0], trajectory[:, 1:], relations)
    odometry = relation_errors([s.stamp for s in log.scans], [s.odometry for s in log.scans],
                               relations)
    assert len(slam.used) == len(odometry.used) == 60
    # Measured: 0.0137 +- 0.0072 m, 0.197 +- 0.152 deg (the raw odometry: 0.0125 +- 0.0222 m,
    # 1.19 +- 0.75 deg: over 0.35 m its translation is good, its heading is not).
    assert slam.translation[0] < 0.02 and slam.translation_m.max() < 0.06
    assert slam.rotation[0] < 0.3 < odometry.rotation[0]


def test_the_map_drawn_from_the_trajectory_agrees_with_the_scans(mapped):
    log, mapper = mapped
    trajectory = mapper.trajectory()
    share = self_consistency(mapper.occupancy_raster(), trajectory[:, 1:], log.scans)
    assert share > 0.95  # measured 97.9 %

"""SLAM accuracy on real logs: the relation error of Kuemmerle et al. 2009, map self-consistency.

    relations = read_relations("intel.relations")        # t1 t2 x y z roll pitch yaw per line
    errors = relation_errors(stamps, poses, relations)    # the estimate at each scan's stamp
    errors.summary()   # "0.0229 +- 0.0239 m, 0.453 +- 1.335 deg (1030 of 1030 relations)"
    self_consistency(raster, poses, scans, lidar_offset_x_m)   # share of returns on the map

The relation error (Kuemmerle, Steder, Dornhege, Ruhnke, Grisetti, Stachniss, Kleiner: "On
measuring the accuracy of SLAM algorithms", Autonomous Robots 27(4), 2009; the measure Hess et
al. 2016, Cartographer, Table II quotes): each relation is the pose at stamp t2 seen from the
pose at t1, from manually verified scan matches. For each relation whose both stamps are
stamps of the estimate (within `tolerance_s`), the estimate's own relative pose
x(t1)^-1 (+) x(t2) is compared with the given one: the translational error is the length of
the difference of the two relative translations (m), the rotational error the difference of
the two rotations (deg, the short way round); each is reported as mean +- std of the absolute
and of the squared values. Only x, y and yaw of a relation are used (a 2D log's z, roll and
pitch are 0).

Self-consistency needs no ground truth: the share of the returns within `max_range_m` (20 m)
that, drawn from the estimated pose of their scan, end within `tolerance_m` (10 cm) of an
OCCUPIED cell of the map (cell centre; amr_evaluation.mapping_metrics.near_occupied). A map
drawn from a bent trajectory blurs its walls, and returns of the scans that disagree with the
map land off them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from amr_common.world.map_raster import Raster
from amr_evaluation.mapping_metrics import near_occupied, transform_points
from amr_mapping.scan_points import ScanError, scan_points

STAMP_TOLERANCE_S = 1e-3  # a relation's stamp matches an estimate's within this
CONSISTENCY_RANGE_M = 20.0
CONSISTENCY_TOLERANCE_M = 0.10


class RelationFileError(ValueError):
    """A relations file that cannot be read, with the line that is wrong."""


def read_relations(path: str | Path) -> np.ndarray:
    """(M, 5) rows [t1, t2, x, y, yaw] of a Kuemmerle relations file (t1 t2 x y z roll pitch yaw).

    Blank lines and `#` comments are skipped; RelationFileError names a malformed line.
    """
    rows = []
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RelationFileError(f"cannot read relations {path}: {exc}") from None
    for number, line in enumerate(text.splitlines(), start=1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        if len(fields) != 8:
            raise RelationFileError(f"{path} line {number}: {len(fields)} fields, expected 8 "
                                    "(t1 t2 x y z roll pitch yaw)")
        try:
            values = [float(v) for v in fields]
        except ValueError:
            raise RelationFileError(f"{path} line {number}: not all numbers: {line.strip()!r}"
                                    ) from None
        if not all(math.isfinite(v) for v in values):
            raise RelationFileError(f"{path} line {number}: not finite: {line.strip()!r}")
        rows.append([values[0], values[1], values[2], values[3], values[7]])
    return np.array(rows, dtype=np.float64).reshape(-1, 5)


@dataclass(frozen=True)
class RelationErrors:
    """Per-relation errors of the relations both of whose stamps the estimate has."""

    translation_m: np.ndarray  # (K,) |dt| per used relation
    rotation_deg: np.ndarray  # (K,) |dtheta| per used relation
    used: np.ndarray  # (K,) indices of the used relations
    total: int  # relations given

    @staticmethod
    def _mean_std(values: np.ndarray) -> tuple[float, float]:
        if values.size == 0:
            return math.nan, math.nan
        return float(values.mean()), float(values.std())

    @property
    def translation(self) -> tuple[float, float]:
        """Mean and std of the absolute translational error (m)."""
        return self._mean_std(self.translation_m)

    @property
    def translation_squared(self) -> tuple[float, float]:
        """Mean and std of the squared translational error (m^2)."""
        return self._mean_std(self.translation_m ** 2)

    @property
    def rotation(self) -> tuple[float, float]:
        """Mean and std of the absolute rotational error (deg)."""
        return self._mean_std(self.rotation_deg)

    @property
    def rotation_squared(self) -> tuple[float, float]:
        """Mean and std of the squared rotational error (deg^2)."""
        return self._mean_std(self.rotation_deg ** 2)

    def summary(self) -> str:
        """One line: absolute errors, mean +- std, and how many relations were used."""
        t, r = self.translation, self.rotation
        return (f"{t[0]:.4f} +- {t[1]:.4f} m, {r[0]:.3f} +- {r[1]:.3f} deg "
                f"({len(self.used)} of {self.total} relations)")

    def as_dict(self) -> dict[str, Any]:
        """The figures as plain numbers (a report's)."""
        return {"relations": self.total, "relations_used": int(len(self.used)),
                "translation_m": list(self.translation),
                "translation_squared_m2": list(self.translation_squared),
                "rotation_deg": list(self.rotation),
                "rotation_squared_deg2": list(self.rotation_squared)}


def stamp_indices(stamps: np.ndarray, queries: np.ndarray,
                  tolerance_s: float = STAMP_TOLERANCE_S) -> np.ndarray:
    """Per query stamp, the index of the nearest stamp within tolerance_s, else -1.

    Of several equally near (a log's repeated stamps), the first in `stamps`' order.
    """
    stamps = np.asarray(stamps, dtype=np.float64)
    queries = np.asarray(queries, dtype=np.float64)
    if stamps.size == 0:
        return np.full(queries.shape, -1, dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    ordered = stamps[order]
    right = np.searchsorted(ordered, queries, side="left")
    # the candidates: the last stamp below the query and the first at or above it (the first
    # of a run of equal stamps: side="left", and stable order keeps the log's order)
    below = np.searchsorted(ordered, ordered[np.clip(right - 1, 0, len(ordered) - 1)],
                            side="left")
    above = np.where(right < len(ordered), right, below)
    d_below = np.abs(queries - ordered[below])
    d_above = np.abs(ordered[above] - queries)
    pick = np.where(d_above <= d_below, above, below)
    best = np.minimum(d_below, d_above)
    return np.where(best <= tolerance_s, order[pick], -1)


def relation_errors(stamps: Sequence[float] | np.ndarray, poses: np.ndarray,
                    relations: np.ndarray,
                    tolerance_s: float = STAMP_TOLERANCE_S) -> RelationErrors:
    """The errors of the estimate (stamps (N,), poses (N, 3) [x, y, theta]) on `relations`.

    relations: read_relations' rows [t1, t2, x, y, yaw]. A relation is used when both its stamps
    match an estimate's stamp (stamp_indices); see the module docstring for the measure.
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    relations = np.asarray(relations, dtype=np.float64).reshape(-1, 5)
    first = stamp_indices(stamps, relations[:, 0], tolerance_s)
    second = stamp_indices(stamps, relations[:, 1], tolerance_s)
    used = np.flatnonzero((first >= 0) & (second >= 0))
    a, b = poses[first[used]], poses[second[used]]
    # x(t1)^-1 (+) x(t2)
    c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
    dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
    rel_x, rel_y = c * dx + s * dy, -s * dx + c * dy
    rel_th = b[:, 2] - a[:, 2]
    given = relations[used]
    translation = np.hypot(rel_x - given[:, 2], rel_y - given[:, 3])
    rotation = np.abs(np.remainder(rel_th - given[:, 4] + math.pi, 2.0 * math.pi) - math.pi)
    return RelationErrors(translation, np.degrees(rotation), used, len(relations))


def self_consistency(raster: Raster, poses: np.ndarray, scans: Sequence[Any],
                     lidar_offset_x_m: float = 0.0, max_range_m: float = CONSISTENCY_RANGE_M,
                     tolerance_m: float = CONSISTENCY_TOLERANCE_M) -> float:
    """Share of the scans' returns within max_range_m that end near an OCCUPIED cell.

    poses (N, 3): each scan's estimated pose (map frame) in the order of `scans`
    (LaserScan-like); a pose that is not finite leaves its scan out. NaN without returns.
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    ends = []
    for pose, scan in zip(poses, scans):
        if not np.all(np.isfinite(pose)):
            continue
        try:
            points, _ = scan_points(scan, lidar_offset_x_m, max_range_m)
        except ScanError:
            continue
        ends.append(transform_points(tuple(pose), points))
    if not ends or sum(len(e) for e in ends) == 0:
        return math.nan
    return float(near_occupied(raster, np.concatenate(ends), tolerance_m).mean())


__all__ = ["RelationErrors", "RelationFileError", "read_relations", "relation_errors",
           "self_consistency", "stamp_indices"]

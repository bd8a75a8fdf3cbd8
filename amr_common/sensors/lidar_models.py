"""The TurtleBot3's LiDARs as their datasheets and drivers describe them (no ROS import).

One home for the figures the simulator's reality gap draws its range errors from (amr_sim) and
the particle filter sizes its tolerances with (amr_localization): distance bands with their
accuracy and precision bounds, the sensing range, the revolution and how the driver stamps it.
Sources: docs/reality-gap.md ([1] LDS-01 and [2] LDS-02 e-manual pages, [3] hls_lfcd_lds_driver,
[4] ld08_driver).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class LidarModel:
    """What a real scanner adds to the ideal ray cast: its datasheet's bands and its driver.

    Distance bands: below band_edges[0] band 0, and so on; each band's accuracy and precision
    bound is abs_m + rel * range (datasheet figures). Rays are measured clockwise, so a ray at
    angle a (rad, counter-clockwise) is measured revolution_s * a / (2 pi) before the
    revolution's end, when the driver stamps the scan. With samples_per_s (LD08) the samples
    are binned per scan as ld08_driver does: the ray count and angle_min change every scan.
    """

    name: str
    revolution_s: float
    band_edges: tuple[float, ...]
    accuracy: tuple[tuple[float, float], ...]  # (abs_m, rel) per band
    precision: tuple[tuple[float, float], ...]
    sensing_min: float  # m: shorter true ranges return nothing
    sensing_max: float  # m: longer ones too
    samples_per_s: float | None = None  # LD08: 2300 samples/s, binned per scan
    speed_sigma: float = 0.0  # relative rotation-speed change from scan to scan
    # Relative error of the reported angle_increment (the driver takes the speed of the last
    # packet, not the revolution's mean): the binning then leaves a gap or merges two samples
    # every 1 / error rays.
    increment_sigma: float = 0.0

    def bounds(self, ranges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(accuracy, precision) bounds (m) of each range's band (NaN ranges: band 0)."""
        r = np.nan_to_num(np.asarray(ranges, dtype=np.float64), nan=0.0, posinf=0.0)
        band = np.searchsorted(np.asarray(self.band_edges), r, side="right")
        accuracy, precision = np.asarray(self.accuracy), np.asarray(self.precision)
        return (accuracy[band, 0] + accuracy[band, 1] * r,
                precision[band, 0] + precision[band, 1] * r)

    def ray_ages(self, angles: np.ndarray) -> np.ndarray:
        """How long before the scan's stamp each ray at `angles` (rad) was measured (s).

        Both drivers stamp the END of a clockwise revolution (revolution_ages).
        """
        return revolution_ages(angles, self.revolution_s)


def revolution_ages(angles: np.ndarray, revolution_s: float) -> np.ndarray:
    """How long before the stamp (s) each ray at `angles` (rad) of a revolution was measured.

    The one statement of the Burger's drivers' convention (hls_lfcd_lds_driver, ld08_driver;
    docs/reality-gap.md "Scan skew"): the scanner turns clockwise and the scan is stamped at
    the END of its revolution, so the ray at angle a (counter-clockwise, taken in [0, 2 pi))
    is revolution_s * a / (2 pi) old (ray 0 the newest). This holds for any ray count and
    angle_min (the LDS-02's change from scan to scan).
    """
    return revolution_s * np.mod(angles, 2.0 * math.pi) / (2.0 * math.pi)


# emanual.robotis.com turtlebot3 appendix_lds_01: accuracy 15 mm (120-499 mm) / 5 % (500-3,500),
# precision 10 mm / 3.5 %, 300 +- 10 rpm. hls_lfcd_lds_driver: ranges[359 - index] (clockwise).
LDS01 = LidarModel(name="LDS-01", revolution_s=0.2, band_edges=(0.5,),
                   accuracy=((0.015, 0.0), (0.0, 0.05)), precision=((0.010, 0.0), (0.0, 0.035)),
                   sensing_min=0.12, sensing_max=3.5)
# appendix_lds_02: 160-8,000 mm, 2.3 kHz fixed sampling, >= 5 Hz; accuracy 10 mm (160-300 mm),
# 3 % (300-6,000 mm), 5 % (6,000-8,000 mm; the page labels it precision). No separate precision
# figure: the same bounds are used.
LDS02 = LidarModel(name="LDS-02", revolution_s=0.2, band_edges=(0.3, 6.0),
                   accuracy=((0.010, 0.0), (0.0, 0.03), (0.0, 0.05)),
                   precision=((0.010, 0.0), (0.0, 0.03), (0.0, 0.05)),
                   sensing_min=0.16, sensing_max=8.0, samples_per_s=2300.0, speed_sigma=0.01,
                   increment_sigma=0.005)

LIDAR_MODELS: dict[str, LidarModel] = {model.name: model for model in (LDS01, LDS02)}

__all__ = ["LidarModel", "LDS01", "LDS02", "LIDAR_MODELS", "revolution_ages"]

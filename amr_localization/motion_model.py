"""The motion model: every particle moves with the odometry twist (v, w) plus its own noise.

Per particle and step, v_i = v + sigma_v * n1 and w_i = w + sigma_w * n2 (n1, n2 standard
normal), with sigma_v = a_vv * |v| + a_vw * |w| and sigma_w = a_ww * |w| + a_wv * |v|: the noise
grows with what the robot does and is zero while it stands still (the particles do not diffuse
when nothing moves). The pose advances along the arc's chord at the mid-step heading
(amr_common.robot's step, with v dt for the chord: exact for a constant twist up to the chord
factor, 1 - (w dt)^2 / 24). No rclpy import.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from amr_common.jit import jit
from amr_common.robot import arc_displacement_kernel
from amr_localization.particle_filter_params import PARAMETERS


@dataclass(frozen=True)
class MotionNoise:
    """Standard deviations of the per-step velocity noise, proportional to the motion.

    The defaults are the filter's parameter table's noise_* (particle_filter_params).
    """

    v_per_v: float = PARAMETERS["noise_v_per_v"][0]  # m/s of v noise per m/s of v
    v_per_w: float = PARAMETERS["noise_v_per_w"][0]  # m/s of v noise per rad/s of w
    w_per_w: float = PARAMETERS["noise_w_per_w"][0]  # rad/s of w noise per rad/s of w
    w_per_v: float = PARAMETERS["noise_w_per_v"][0]  # rad/s of w noise per m/s of v

    def sigmas(self, v: float, w: float) -> tuple[float, float]:
        """(sigma_v m/s, sigma_w rad/s) for the twist (v, w)."""
        return (self.v_per_v * abs(v) + self.v_per_w * abs(w),
                self.w_per_w * abs(w) + self.w_per_v * abs(v))


def move_python(particles, count, v, w, dt, sigma_v, sigma_w, normals):
    """In place: particles[:count] moved by (v + sigma_v n0, w + sigma_w n1) for dt seconds."""
    for p in range(count):
        vi = v + sigma_v * normals[p, 0]
        wi = w + sigma_w * normals[p, 1]
        theta = particles[p, 2]
        dx, dy = arc_displacement_kernel(theta, vi * dt, wi * dt)
        particles[p, 0] += dx
        particles[p, 1] += dy
        theta += wi * dt
        if theta > math.pi:  # keep headings in (-pi, pi]: a step turns far less than 2 pi
            theta -= 2.0 * math.pi
        elif theta <= -math.pi:
            theta += 2.0 * math.pi
        particles[p, 2] = theta


move = jit(move_python)


def sample_motion(particles: np.ndarray, count: int, v: float, w: float, dt: float,
                  noise: MotionNoise, rng: np.random.Generator) -> None:
    """Move particles[:count] in place by the odometry twist (v, w) over dt with noise."""
    sigma_v, sigma_w = noise.sigmas(v, w)
    if sigma_v > 0.0 or sigma_w > 0.0:
        normals = rng.standard_normal((count, 2))
    else:
        normals = np.zeros((count, 2))
    move(particles, count, float(v), float(w), float(dt), sigma_v, sigma_w, normals)

"""The reality gap: profiles and effect parameters, the drivetrain's effects, determinism per seed.

The scanner's effects (noise by band, dropouts, skew, LDS-02) are in test_lidar_effects.py.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from amr_common.robot import TRACK, WHEEL_RADIUS
from amr_common.sensors.lidar_models import LDS01
from amr_sim.drivetrain import (
    FIRMWARE_MAX_ANGULAR,
    FIRMWARE_MAX_LINEAR,
    RPM,
    Drivetrain,
    drive_step_python,
)
from amr_sim.effects import EFFECT_NAMES, EFFECTS, Effects, draw_effects
from amr_sim.profiles import get_profile, randomized_profile_name
from amr_sim.simulator import Simulator

DT = 0.05


def drive_only(**on) -> str:
    """A profile with every effect off but `on` (the real drivetrain and scanner code paths)."""
    return "turtlebot3:off" + "".join(f":{k}={v}" for k, v in on.items())


def digest(profile: str, seed: int) -> str:
    """A fingerprint of 400 steps: scans (rounded to 1 nm), twists, poses, odometry, contacts."""
    sim = Simulator("lab02", start="outer", profile=profile, seed=seed)
    h = hashlib.sha256()
    for k in range(400):
        z, v, w = sim.step(0.2 * math.cos(0.013 * k), 1.5 * math.sin(0.05 * k))
        h.update(np.round(z, 9).tobytes())
        h.update(np.round(np.array([v, w, *sim.pose, *sim.odometry_pose, *sim.wheel_angles]),
                          12).tobytes())
    h.update(np.round(np.array([sim.collisions, sim.min_clearance, sim.distance]), 12).tobytes())
    return h.hexdigest()[:16]


@pytest.mark.parametrize("profile, expected", [("ideal", "d34df50ce4018847"),
                                               ("turtlebot3_clean", "466a69c738c3c327")])
def test_clean_profiles_are_unchanged(profile, expected):
    # Fingerprints taken on main before the effects existed (3 wall contacts included); the
    # clean Burger was called `turtlebot3` then.
    assert digest(profile, 3) == expected


def test_turtlebot3_clean_is_the_old_turtlebot3_and_turtlebot3_has_every_effect():
    clean, burger = get_profile("turtlebot3_clean"), get_profile("turtlebot3")
    # The clean model's fields as `turtlebot3` had them before the reality-gap profiles (bar the
    # name).
    assert dataclasses.asdict(clean) == {
        "name": "turtlebot3_clean", "scan_rays": 360, "angle_min": 0.0,
        "angle_increment": 2.0 * math.pi / 360, "range_min": 0.12, "range_max": 3.5,
        "no_return": 0.0, "range_noise_sigma": 0.01, "scan_period": 0.2, "odom_period": 0.05,
        "odom_topic": "/odom", "command_resolution": 0.01, "max_linear": 0.22,
        "max_angular": 2.84, "clamp_commands": True, "lidar_offset_x": -0.032, "effects": None,
        "lidar_model": None, "randomize": False, "effect_overrides": ()}
    assert burger == dataclasses.replace(clean, name="turtlebot3", range_noise_sigma=0.0,
                                         effects=Effects(), lidar_model=LDS01)


@pytest.mark.parametrize("spec", ["turtlebot3_real", "turtlebot3_real:randomized"])
def test_the_retired_turtlebot3_real_says_what_it_is_called_now(spec):
    with pytest.raises(ValueError, match=r"\A[^\n]*\Z") as error:  # one line
        get_profile(spec)
    assert str(error.value) == ("profile 'turtlebot3_real' is now 'turtlebot3' (every "
                                "reality-gap effect at its typical value); the clean model is "
                                "'turtlebot3_clean'")


# --- profiles, parameters and bad input --------------------------------------------------------
def test_profile_options_set_draw_and_turn_off_effects():
    typical = get_profile("turtlebot3")
    assert typical.effects == Effects() and not typical.randomize
    assert get_profile("turtlebot3:command_latency_s=0.1").effects.command_latency_s == 0.1
    off = get_profile("turtlebot3:off:scan_skew=on").effects
    assert off.scan_skew == 1.0 and off.command_latency_s == 0.0 and off.firmware_clamp == 0.0
    randomized = get_profile("turtlebot3_lds02:randomized:dropout_share=0.2")
    assert randomized.randomize and dict(randomized.effect_overrides) == {"dropout_share": 0.2}
    assert randomized_profile_name("turtlebot3:track_error=0.01") == \
        "turtlebot3:randomized:track_error=0.01"
    assert get_profile("ideal").effects is None
    assert get_profile("turtlebot3_clean").effects is None


@pytest.mark.parametrize("spec, words", [
    ("turtlebot3:command_latency_s=-0.1", "command_latency_s must be a number in [0, 2] s"),
    ("turtlebot3:dropout_share=1.5", "dropout_share must be a number in [0, 1]"),
    ("turtlebot3:wheel_slip_sigma=nan", "wheel_slip_sigma must be a number"),
    ("turtlebot3:scan_jitter_s=fast", "scan_jitter_s must be a number"),
    ("turtlebot3:scan_skew=0.5", "scan_skew must be 0 (off) or 1 (on)"),
    ("turtlebot3:latency=0.1", "unknown effect 'latency'"),
    ("turtlebot3:noisy", "profile option 'noisy'"),
    ("turtlebot3:off:randomized", "exclude each other"),
    ("ideal:randomized", "profile 'ideal' has no reality-gap effects"),
    ("turtlebot3_clean:command_latency_s=0.1",
     "profile 'turtlebot3_clean' has no reality-gap effects"),
])
def test_bad_profile_options_are_clear_value_errors(spec, words):
    with pytest.raises(ValueError, match=r"\A[^\n]*\Z") as error:  # one line
        get_profile(spec)
    assert words in str(error.value)
    with pytest.raises(ValueError):
        Simulator("lab02", profile=spec)


def test_effects_reject_out_of_range_values_in_python():
    with pytest.raises(ValueError, match="command_latency_s.*-1"):
        Effects(command_latency_s=-1.0)
    with pytest.raises(ValueError, match="dropout_share.*1.2.*wheel_acceleration.*inf"):
        Effects(dropout_share=1.2, wheel_acceleration=math.inf)
    with pytest.raises(ValueError, match="range_noise_share"):
        Effects().with_values({"range_noise_share": math.nan})
    with pytest.raises(ValueError, match="track_error"):
        Effects(track_error=True)  # a bool is not a number here


def test_drawn_effects_stay_in_their_documented_ranges():
    for seed in range(200):
        drawn = draw_effects(np.random.default_rng(seed))
        for name in EFFECT_NAMES:
            low, high = EFFECTS[name].drawn
            assert low <= getattr(drawn, name) <= high, name
    spreads = [draw_effects(np.random.default_rng(s)).command_latency_s for s in range(50)]
    assert max(spreads) - min(spreads) > 0.05  # really drawn, across the range


def test_a_seed_fully_determines_a_randomized_run():
    def run(seed):
        sim = Simulator("maze_deadends", profile="turtlebot3:randomized", seed=seed)
        scans = []
        for k in range(200):
            z, v, w = sim.step(0.2, 1.2 * math.sin(0.07 * k))
            scans.append(z.copy())
        return sim.effects, np.array(scans), sim.pose, sim.odometry_pose
    a, b, c = run(5), run(5), run(6)
    assert a[0] == b[0] and a[0] != c[0]
    np.testing.assert_array_equal(a[1], b[1])
    assert a[2:] == b[2:] and a[2] != c[2]


# --- the drivetrain ---------------------------------------------------------------------------
def forward_speeds(profile: str, commands) -> list[float]:
    sim = Simulator("lab02", start="outer", profile=profile)
    return [sim.step(v, w)[1] for v, w in commands]


def test_command_latency_in_steps_and_fractions():
    commands = [(0.1, 0.0)] * 5
    assert forward_speeds(drive_only(command_latency_s=0.1), commands) == \
        pytest.approx([0.0, 0.0, 0.1, 0.1, 0.1], abs=1e-12)  # two steps late
    # 25 ms: the first step runs half on the old command (0) and half on the new one
    assert forward_speeds(drive_only(command_latency_s=0.025), commands) == \
        pytest.approx([0.05, 0.1, 0.1, 0.1, 0.1], abs=1e-12)
    assert forward_speeds(drive_only(), commands) == pytest.approx([0.1] * 5, abs=1e-12)


def test_wheel_acceleration_limits_the_speed_change():
    commands = [(0.2, 0.0)] * 6 + [(0.0, 0.0)] * 2
    speeds = forward_speeds(drive_only(wheel_acceleration=1.0), commands)
    # 1 m/s^2 from rest: 0.05 m/s more each step; the step's mean speed is reported.
    assert speeds == pytest.approx([0.025, 0.075, 0.125, 0.175, 0.2, 0.2, 0.175, 0.125],
                                   abs=1e-12)


def test_firmware_clamp_and_per_wheel_top_speed():
    sim = Simulator("lab02", start="outer", profile=drive_only(firmware_clamp=1))
    sim.step(0.5, 0.0)
    assert sim.executed_command == pytest.approx((FIRMWARE_MAX_LINEAR, 0.0))
    assert FIRMWARE_MAX_LINEAR == pytest.approx(0.2108, abs=1e-4)
    sim.step(0.0, 9.0)
    assert sim.executed_command == pytest.approx((0.0, FIRMWARE_MAX_ANGULAR))
    assert FIRMWARE_MAX_ANGULAR == pytest.approx(2.635, abs=1e-3)
    # Both at once: the outer wheel is clipped at 61 rpm alone, so the curvature changes.
    sim = Simulator("lab02", start="outer", profile=drive_only(firmware_clamp=1,
                                                               wheel_speed_limit_rpm=61))
    sim.step(0.2, 1.5)  # within the firmware's v and w limits
    top = 61 * RPM * WHEEL_RADIUS
    left, right = 0.2 - 1.5 * TRACK / 2, top  # rim speeds: the right wheel is clipped
    v, w = sim.executed_command
    assert (v, w) == pytest.approx(((left + right) / 2, (right - left) / TRACK), rel=1e-9)
    assert w / v == pytest.approx(5.62, abs=0.01)  # commanded: 7.5 /m


def test_wheel_radius_and_track_errors_make_odometry_drift():
    sim = Simulator("lab02", start="outer", profile=drive_only(wheel_radius_error=0.02))
    for _ in range(40):
        sim.step(0.1, 0.0)
    x0, y0, _ = sim.start
    travelled = math.hypot(sim.pose[0] - x0, sim.pose[1] - y0)
    assert travelled == pytest.approx(1.02 * 0.2, rel=1e-9)  # wheels 2 % larger
    assert sim.odometry_pose[0] == pytest.approx(0.2, rel=1e-9)  # encoders x nominal radius
    # A larger right wheel curves a straight command to the left; the IMU heading sees it.
    sim = Simulator("lab02", start="outer", profile=drive_only(wheel_radius_difference=0.01))
    for _ in range(40):
        sim.step(0.1, 0.0)
    turned = sim.pose[2] - sim.start[2]
    assert turned == pytest.approx(0.01 * 0.2 / TRACK, rel=1e-6)
    assert sim.odometry_pose[2] == pytest.approx(turned, abs=1e-12)
    # A wider track turns slower than commanded.
    sim = Simulator("lab02", start="outer", profile=drive_only(track_error=0.05))
    for _ in range(20):
        sim.step(0.0, 1.0)
    assert sim.pose[2] - sim.start[2] == pytest.approx(1.0 / 1.05, rel=1e-9)


def test_slip_is_random_and_the_imu_heading_drifts():
    sim = Simulator("lab02", start="outer", profile=drive_only(wheel_slip_sigma=0.05))
    path = [sim.pose[:2]]
    for _ in range(100):
        assert sim.step(0.1, 0.0)[1] == pytest.approx(0.1)  # the encoders: the wheels' turns
        path.append(sim.pose[:2])
    speeds = np.hypot(*np.diff(path, axis=0).T) / DT  # true: each wheel slips by its own share
    assert np.std(speeds) == pytest.approx(0.1 * 0.05 / math.sqrt(2), rel=0.25)
    assert math.hypot(*sim.odometry_pose[:2]) == pytest.approx(0.5, abs=1e-3)
    assert sim.distance != pytest.approx(0.5, abs=1e-4)
    sim = Simulator("lab02", start="outer", profile=drive_only(imu_yaw_drift_deg_per_min=6.0))
    for _ in range(200):  # 10 s at rest
        sim.step(0.0, 0.0)
    assert sim.pose[2] == pytest.approx(sim.start[2], abs=1e-12)
    assert sim.odometry_pose[2] == pytest.approx(math.radians(1.0), rel=1e-9)


def test_compiled_drive_step_equals_its_python_twin():
    effects = Effects(command_latency_s=0.037, wheel_slip_sigma=0.05)
    drives = [Drivetrain(effects, np.random.default_rng(1), DT, use_numba=numba)
              for numba in (True, False)]
    assert drives[1]._step is drive_step_python
    rng = np.random.default_rng(2)
    for k in range(300):
        v, w = rng.uniform(-0.4, 0.4), rng.uniform(-4.0, 4.0)
        a, b = (d.step(v, w, k * DT, DT) for d in drives)
        assert a == pytest.approx(b, abs=1e-15)


# --- the scripts ------------------------------------------------------------------------------
SCRIPTS = Path(__file__).resolve().parent.parent / "scripts"


@pytest.mark.parametrize("argv, words", [
    (["--profile", "turtlebot3:command_latency_s=-1"], "command_latency_s must be"),
    (["--profile", "turtlebot3:dropout_share=1.5"], "dropout_share must be"),
    (["--profile", "turtlebot3_lds02:scan_jitter_s=nan"], "scan_jitter_s must be"),
    (["--profile", "turtlebot3_real"], "profile 'turtlebot3_real' is now 'turtlebot3'"),
    (["--randomize"], "--randomize: profile 'ideal' has no reality-gap effects"),
])
def test_bad_effects_are_one_line_errors_with_exit_code_2(capsys, argv, words):
    sys.path.insert(0, str(SCRIPTS))
    import evaluate
    import run_sim
    with pytest.raises(SystemExit) as exit_:
        run_sim.parse_args(argv)
    assert exit_.value.code == 2 and words in capsys.readouterr().err
    evaluate_argv = [a.replace("--profile", "--profiles") for a in argv]
    assert evaluate.main(["--worlds", "lab02", *evaluate_argv]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and words in err


def test_evaluate_randomize_lists_the_drawn_effects(capsys, tmp_path):
    sys.path.insert(0, str(SCRIPTS))
    import evaluate
    code = evaluate.main(["--worlds", "lab02", "--starts", "outer", "--profiles",
                          "turtlebot3", "--randomize", "--seeds", "3,4", "--duration", "5",
                          "--jobs", "1", "--no-sheet", "--out", str(tmp_path / "out")])
    out = capsys.readouterr().out
    assert code == 0
    rows = json.loads((tmp_path / "out" / "results.json").read_text())["episodes"]
    drawn = [draw_effects_of(seed) for seed in (3, 4)]
    assert [row["effects"] for row in rows] == drawn
    assert [row["profile"] for row in rows] == ["turtlebot3:randomized"] * 2
    assert f"seed 3: {Effects(**drawn[0]).summary()}" in out
    assert "latency_s=" in (tmp_path / "out" / "results.csv").read_text()


def draw_effects_of(seed: int) -> dict:
    return Simulator("lab02", profile="turtlebot3:randomized", seed=seed).effects.as_dict()


def test_episodes_retell_the_changing_lds02_geometry_and_record_the_effects():
    from amr_evaluation.episode import run_episode
    from amr_evaluation.localization_episode import run_localization_episode

    class Spy:
        def __init__(self) -> None:
            self.geometries = []

        def set_scan_geometry(self, *geometry) -> None:
            self.geometries.append(geometry)

        def compute_commands(self, z_scan, z_v, z_w):
            return 0.1, 0.3

    spy = Spy()
    result = run_episode("lab02", "outer", profile="turtlebot3_lds02", duration=5.0,
                         controller=spy)
    assert len(spy.geometries) == 1 + 25  # the first scan, then a new one every 0.2 s
    assert len(set(spy.geometries)) > 10 and all(g[2:] == (0.0, 100.0) for g in spy.geometries)
    assert result.effects == Effects().as_dict()
    result = run_localization_episode("lab02", "outer", profile="turtlebot3_lds02:randomized",
                                      seed=2, duration=5.0, record=False)
    assert result.steps == 100 and result.effects == draw_effects_of_lds02(2)


def draw_effects_of_lds02(seed: int) -> dict:
    return Simulator("lab02", profile="turtlebot3_lds02:randomized", seed=seed).effects.as_dict()

"""The kinematic position target of `copter-4.6` (ArduCopter 4.1+'s AC_PosControl shaping, AP_Math/control.cpp)."""

import math

import pytest

from preland_app.sim.control import sqrt_controller
from preland_app.sim.shaping import AltitudeShaper, PositionShaper

ACCEL_M_S2 = 2.5  # WPNAV_ACCEL
JERK_M_S3 = 5.0  # PSC_JERK_XY
DT_S = 0.0025  # ArduCopter's 400 Hz loop


def _path_to(target_ne_m, *, seconds, speed_max_m_s=10.0):
    shaper = PositionShaper(position_ne_m=(0.0, 0.0))
    path = []
    for _ in range(round(seconds / DT_S)):
        shaper.to_position(target_ne_m, dt_s=DT_S, speed_max_m_s=speed_max_m_s, accel_max_m_s2=ACCEL_M_S2,
                           jerk_max_m_s3=JERK_M_S3)
        path.append((tuple(shaper.position_ne_m), tuple(shaper.velocity_ne_m_s), tuple(shaper.accel_ne_m_s2)))
    return path


def test_sqrt_controller_is_linear_near_zero_and_a_square_root_beyond():
    # linear up to second_order_limit / p^2 = 1.25 m, then sqrt(2 * limit * (error - linear / 2))
    assert sqrt_controller(0.5, 1.0, 1.25, 0.0) == pytest.approx(0.5)
    assert sqrt_controller(-0.5, 1.0, 1.25, 0.0) == pytest.approx(-0.5)
    assert sqrt_controller(3.0, 1.0, 1.25, 0.0) == pytest.approx(math.sqrt(2 * 1.25 * (3.0 - 0.625)))
    # never past zero in one step
    assert sqrt_controller(0.001, 0.0, 1.25, 0.1) == pytest.approx(0.01)


def test_a_2_m_leg_keeps_the_jerk_and_acceleration_limits_and_arrives():
    path = _path_to((2.0, 0.0), seconds=10.0)
    accelerations = [a for _, _, a in path]
    assert max(math.hypot(*a) for a in accelerations) <= ACCEL_M_S2 + 1e-9
    steps = [math.dist(a, b) / DT_S for a, b in zip(accelerations, accelerations[1:])]
    assert max(steps) <= JERK_M_S3 + 1e-6
    (north, east), velocity, _ = path[-1]
    assert north == pytest.approx(2.0, abs=0.005) and east == 0.0
    assert math.hypot(*velocity) < 0.01
    # ArduCopter 4.6.3 SITL's target (PSCN.TPN) on the thesis mission's 2 m legs peaks 7 to 8 cm past the corner
    peak_m = max(p[0] for p, _, _ in path)
    assert 2.05 < peak_m < 2.10, peak_m
    # and passes 1 m (half way) after about 1.3 s
    halfway_s = next(k for k, (p, _, _) in enumerate(path) if p[0] >= 1.0) * DT_S
    assert 1.1 < halfway_s < 1.5, halfway_s


def test_the_speed_limit_holds_on_a_long_leg():
    path = _path_to((0.0, 30.0), seconds=20.0, speed_max_m_s=3.0)
    assert max(math.hypot(*v) for _, v, _ in path) <= 3.0 + 1e-6
    assert path[-1][0][1] == pytest.approx(30.0, abs=0.01)


def test_a_stop_comes_to_rest_along_the_path_within_the_limits():
    shaper = PositionShaper(position_ne_m=(0.0, 0.0), velocity_ne_m_s=(1.0, 1.0))
    for _ in range(round(5.0 / DT_S)):
        shaper.to_stop(dt_s=DT_S, accel_max_m_s2=ACCEL_M_S2, jerk_max_m_s3=JERK_M_S3)
        assert math.hypot(*shaper.accel_ne_m_s2) <= ACCEL_M_S2 + 1e-9
    north, east = shaper.position_ne_m
    assert math.hypot(*shaper.velocity_ne_m_s) < 0.01
    # along the velocity's line, beyond the distance of a braking at the full acceleration (v^2 / 2a)
    assert north == pytest.approx(east, abs=1e-9)
    assert math.hypot(north, east) > 2.0 / (2 * ACCEL_M_S2)


def test_a_climb_keeps_its_limits_and_arrives_as_arducopter_4_6_s_take_off_does():
    # WPNAV_ACCEL_Z 1 m/s/s, PSC_JERK_Z 5 m/s/s/s, WPNAV_SPEED_UP 2.5 m/s; started as at lift-off
    shaper = AltitudeShaper(altitude_m=0.0, accel_up_m_s2=0.5)
    rates, accels = [], [0.5]
    for _ in range(round(10.0 / DT_S)):
        shaper.to_altitude(6.0, dt_s=DT_S, speed_up_m_s=2.5, speed_down_m_s=1.5, accel_max_m_s2=1.0,
                           jerk_max_m_s3=5.0)
        rates.append(shaper.climb_rate_m_s)
        accels.append(shaper.accel_up_m_s2)
    assert max(abs(a) for a in accels) <= 1.0 + 1e-9
    assert max(abs(b - a) for a, b in zip(accels, accels[1:])) <= 5.0 * DT_S + 1e-9
    assert shaper.altitude_m == pytest.approx(6.0, abs=0.01)
    # ArduCopter 4.6.3 SITL's desired climb rate (CTUN.DCRt) on the thesis mission's 6 m take-off peaks at
    # 1.92 m/s, 2.2 s after lift-off
    peak = max(range(len(rates)), key=rates.__getitem__)
    assert 1.8 < rates[peak] < 2.1, rates[peak]
    assert 1.9 < peak * DT_S < 2.6, peak * DT_S

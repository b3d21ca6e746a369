"""The simulator's error sources and the ArduPilot parameters that shape them, each checked by its outcome:
independent random streams, PLND_LAG, PLND_OPTIONS, PLND_CAM_POS_*, LOIT_ACC_MAX, PSC_VELZ_P, RTL_ALT_FINAL."""

import math
from dataclasses import replace

import pytest

from preland_app.errors import SpecValueError
from preland_app.sim.navigation import NavigationModel
from preland_app.sim.params import ParameterTable
from preland_app.sim.precland import PrecisionLandingEstimator
from preland_app.sim.spec import NavigationSpec
from preland_app.vehicle.types import FlightMode, LandingTarget

from .test_sim_autopilot import CALM, airborne, fly


def _nav_errors(spec: NavigationSpec, *, seed: int = 11, steps: int = 3000):
    model = NavigationModel(spec=spec, rangefinder_min_m=0.2, rangefinder_max_m=10.0, seed=seed)
    rows = []
    for i in range(steps):
        est = model.step(dt_s=0.01, north_m=0.0, east_m=0.0, down_m=-5.0, velocity_ned_m_s=(0.0, 0.0, 0.0),
                         tilt_cos=1.0, yaw_rad=0.3)
        rows.append((est.gps_error_north_m, est.gps_error_east_m, est.down_m, est.rangefinder_m,
                     est.velocity_north_m_s, est.roll_error_rad, est.heading_error_rad))
    return rows


@pytest.mark.parametrize("change", [
    {"attitude_noise_sigma_deg": 0.0},
    {"imu_accel_noise_m_s2": 0.0},
    {"heading_error_sigma_deg": 0.0},
    {"rangefinder_noise_sigma_m": 0.0, "baro_noise_sigma_m": 0.0},
])
def test_switching_one_error_source_leaves_the_others_draws_unchanged(change):
    base = NavigationSpec()
    before = _nav_errors(base)
    after = _nav_errors(replace(base, **change))
    # GPS error, draw by draw, is the same whatever happens to the other sources.
    assert [r[:2] for r in before] == [r[:2] for r in after]
    if "attitude_noise_sigma_deg" in change:
        assert any(r[5] != 0 for r in before) and all(r[5] == 0 for r in after)
        assert [r[2:5] for r in before] == [r[2:5] for r in after]  # baro, rangefinder, velocity untouched
    if "heading_error_sigma_deg" in change:
        assert [r[5] for r in before] == [r[5] for r in after]  # attitude untouched
    # And the GPS error itself is not zero (the comparison means something).
    assert max(abs(r[0]) for r in before) > 0.05


def test_a_different_seed_draws_a_different_gps_error():
    assert _nav_errors(NavigationSpec(), seed=1, steps=50) != _nav_errors(NavigationSpec(), seed=2, steps=50)


# ---------------------------------------------------------------- PLND_LAG


def _estimate_after_delay(plnd_lag_s: float, *, true_delay_s: float) -> tuple[float, float]:
    """The vehicle hovers 10 m above the target and rolls 0.2 rad at t = 1 s. A sensor sees the target
    straight below (angles 0) just before the roll, and the reading arrives `true_delay_s` later."""
    params = ParameterTable({"PLND_EST_TYPE": 0, "PLND_LAG": plnd_lag_s})
    estimator = PrecisionLandingEstimator(params)
    t = 0.0
    while t < 1.4:
        estimator.record_pose(t, north_m=0.0, east_m=0.0, height_m=10.0,
                              roll_rad=0.2 if t >= 1.0 else 0.0, pitch_rad=0.0, yaw_rad=0.0)
        t = round(t + 0.0025, 6)
    capture_s = 0.99
    received_s = capture_s + true_delay_s
    estimator._history = type(estimator._history)(s for s in estimator._history if s.time_s <= received_s)
    assert estimator.handle(received_s, LandingTarget(timestamp_s=capture_s, angle_x_rad=0.0, angle_y_rad=0.0))
    return estimator.relative_position_m(received_s)


def test_plnd_lag_matching_the_sensor_delay_puts_the_target_where_it_is():
    north, east = _estimate_after_delay(0.1, true_delay_s=0.1)
    assert math.hypot(north, east) < 0.01


def test_plnd_lag_shorter_than_the_sensor_delay_fuses_the_wrong_attitude():
    # ArduPilot's default 20 ms against a 100 ms companion: the roll after capture is taken as the
    # attitude of the measurement, and the target appears 10 m * tan(0.2) to the side (a roll to the
    # right tilts the body's down axis to the left: west at yaw 0).
    north, east = _estimate_after_delay(0.02, true_delay_s=0.1)
    assert east == pytest.approx(-10.0 * math.tan(0.2), rel=0.02)
    assert abs(north) < 0.01


# ---------------------------------------------------------------- flights with a companion target


def _land_on_reported_target(params, *, target_ne_m=(1.5, -1.0), target_velocity_ne_m_s=(0.0, 0.0),
                             record=None):
    """Fly up 8 m, then LAND while a companion reports a target at `target_ne_m` (moving at
    `target_velocity_ne_m_s`). Returns (touchdown, target position then, time of LAND, samples)."""
    samples = []

    async def scenario(vehicle, simulator, clock):
        for name, value in {"PLND_ENABLED": 1, "PLND_TYPE": 1, "PLND_STRICT": 0, **params}.items():
            await vehicle.set_param(name, value)
        await airborne(vehicle, clock, altitude_m=8.0)
        await vehicle.set_mode(FlightMode.LAND)
        land_s = clock.now_s()
        target = (target_ne_m[0], target_ne_m[1])
        while (await vehicle.telemetry()).armed:
            elapsed = clock.now_s() - land_s
            target = (target_ne_m[0] + target_velocity_ne_m_s[0] * elapsed,
                      target_ne_m[1] + target_velocity_ne_m_s[1] * elapsed)
            truth = simulator.true_pose()
            samples.append((clock.now_s() - land_s, truth.north_m, truth.east_m, -truth.down_m))
            height = max(-truth.down_m, 0.1)
            dn, de = target[0] - truth.north_m, target[1] - truth.east_m
            c, s = math.cos(truth.yaw_rad), math.sin(truth.yaw_rad)
            forward, right = dn * c + de * s, -dn * s + de * c
            await vehicle.send_landing_target(LandingTarget(
                timestamp_s=clock.now_s(), angle_x_rad=math.atan2(right, height),
                angle_y_rad=math.atan2(-forward, height)))
            await clock.sleep(0.05)
        return simulator.touchdowns()[-1], target, land_s, samples

    return fly(scenario, environment=CALM)


def _time_below(samples, height_m):
    return next(t for t, _, _, h in samples if h < height_m)


def test_plnd_options_fast_descend_skips_the_slow_final_descent():
    slow, _, _, slow_samples = _land_on_reported_target({})
    fast, _, _, fast_samples = _land_on_reported_target({"PLND_OPTIONS": 4})
    # From 2 m down: LAND_SPEED (0.5 m/s) instead of at most half of it.
    slow_s = slow_samples[-1][0] - _time_below(slow_samples, 2.0)
    fast_s = fast_samples[-1][0] - _time_below(fast_samples, 2.0)
    assert fast_s < 0.75 * slow_s
    assert 3.0 < fast_s < 6.0 and slow_s > 6.0


def test_plnd_options_moving_target_follows_the_target():
    moving = (0.0, 0.15)
    still, target_still, _, _ = _land_on_reported_target({}, target_velocity_ne_m_s=moving)
    followed, target_followed, _, _ = _land_on_reported_target({"PLND_OPTIONS": 1}, target_velocity_ne_m_s=moving)
    lag_still = math.hypot(still.north_m - target_still[0], still.east_m - target_still[1])
    lag_followed = math.hypot(followed.north_m - target_followed[0], followed.east_m - target_followed[1])
    # Without the feed-forward the position loop trails a moving target; with it, it keeps up.
    assert lag_followed < 0.6 * lag_still
    assert lag_still > 0.05


def test_plnd_options_bit_1_is_refused_at_load(thesis_mission):
    with pytest.raises(SpecValueError, match="PLND_OPTIONS.*bit 1"):
        replace(thesis_mission, params={"PLND_OPTIONS": 3})
    assert replace(thesis_mission, params={"PLND_OPTIONS": 5}).params["PLND_OPTIONS"] == 5


def _sensor_offset_estimate(cam_pos_frd_m):
    """A sensor 0.3 m right of and 0.2 m below the centre, the vehicle 10 m up and rolled 0.3 rad; the
    target straight below the centre. Returns what the estimator steers to and the sensor's NED offset."""
    params = ParameterTable({"PLND_EST_TYPE": 0, "PLND_CAM_POS_X": cam_pos_frd_m[0],
                             "PLND_CAM_POS_Y": cam_pos_frd_m[1], "PLND_CAM_POS_Z": cam_pos_frd_m[2]})
    estimator = PrecisionLandingEstimator(params)
    roll = 0.3
    for i in range(200):
        estimator.record_pose(i * 0.0025, north_m=0.0, east_m=0.0, height_m=10.0, roll_rad=roll, pitch_rad=0.0,
                              yaw_rad=0.0)
    now_s = 199 * 0.0025
    # The sensor's NED position (yaw 0, roll only) and its body-frame line of sight to the target.
    offset = (0.0, 0.3, 0.2)
    sensor_e = math.cos(roll) * offset[1] - math.sin(roll) * offset[2]
    sensor_d = math.sin(roll) * offset[1] + math.cos(roll) * offset[2]
    to_target_ned = (0.0, -sensor_e, 10.0 - sensor_d)
    # NED -> body for a pure roll.
    body_y = math.cos(roll) * to_target_ned[1] + math.sin(roll) * to_target_ned[2]
    body_z = -math.sin(roll) * to_target_ned[1] + math.cos(roll) * to_target_ned[2]
    target = LandingTarget(timestamp_s=now_s, angle_x_rad=math.atan2(body_y, body_z), angle_y_rad=0.0)
    assert estimator.handle(now_s, target)
    return estimator.relative_position_m(now_s), sensor_e


def test_plnd_cam_pos_corrects_a_tilted_offset_sensor_and_lands_the_sensor_on_the_target():
    (north, east), sensor_e = _sensor_offset_estimate((0.0, 0.3, 0.2))
    # With PLND_CAM_POS the target is located exactly; the output then keeps the sensor's horizontal
    # offset (AC_PrecLand lands lens-to-target): steer to the target minus the offset.
    horizontal_offset_e = math.cos(0.3) * 0.3
    assert north == pytest.approx(0.0, abs=1e-6)
    assert east == pytest.approx(-horizontal_offset_e, abs=0.005)
    (north0, east0), _ = _sensor_offset_estimate((0.0, 0.0, 0.0))
    # Without it the tilted offset turns into an error of several cm on top of the lens-to-target offset.
    assert abs(east0 - east) > 0.04


# ---------------------------------------------------------------- LOIT_ACC_MAX, PSC_VELZ_P, RTL_ALT_FINAL


def test_loit_acc_max_sets_how_hard_land_corrects_towards_the_target():
    def time_to_close(accel_cm_s2):
        _, _, _, samples = _land_on_reported_target({"LOIT_ACC_MAX": accel_cm_s2}, target_ne_m=(2.0, 0.0))
        return next(t for t, n, e, _ in samples if math.hypot(n - 2.0, e) < 0.5)

    gentle, brisk = time_to_close(100), time_to_close(981)
    assert gentle > brisk + 0.3
    assert brisk > 0.5


def test_psc_velz_p_sets_how_closely_the_climb_rate_follows_its_demand():
    def takeoff_time(gain):
        async def scenario(vehicle, simulator, clock):
            start = clock.now_s()
            await airborne(vehicle, clock, altitude_m=5.0)
            return clock.now_s() - start, simulator.dynamics.state

        return fly(scenario, params={"PSC_VELZ_P": gain})

    slow_s, _ = takeoff_time(1.0)
    fast_s, _ = takeoff_time(8.0)
    assert slow_s > fast_s + 0.3


def test_rtl_alt_final_holds_above_home_instead_of_landing():
    def rtl(alt_final_cm):
        async def scenario(vehicle, simulator, clock):
            await airborne(vehicle, clock, altitude_m=10.0)
            await vehicle.set_mode(FlightMode.RTL)
            await clock.sleep(60.0)
            telemetry = await vehicle.telemetry()
            return telemetry.armed, -simulator.true_pose().down_m

        return fly(scenario, params={"RTL_ALT_FINAL": alt_final_cm, "RTL_LOIT_TIME": 1000})

    armed, height = rtl(300)
    assert armed and height == pytest.approx(3.0, abs=0.6)
    armed, height = rtl(0)
    assert not armed and height == pytest.approx(0.0, abs=0.01)


# ---------------------------------------------------------------- IR-LOCK pixel grid, frame age and mounting


def _irlock_reading(spec, *, north_off_m=-1.0, east_off_m=0.3, height_m=10.0):
    import numpy as np

    from preland_app.sensing.irlock import IrLockModel
    from preland_app.sensing.virtual_camera import CameraPose

    model = IrLockModel(spec=spec, beacon_ned_m=(0.0, 0.0), rng=np.random.default_rng(0))
    return model.read(CameraPose(north_off_m, east_off_m, -height_m, 0.0, 0.0, 0.0), capture_time_s=1.0)


def test_irlock_angles_fall_on_the_pixy_grid_within_half_a_pixel():
    from preland_app.sensing.irlock import IrLockSpec

    base = IrLockSpec(noise_sigma_deg=0.0, mount_offset_frd_m=(0.0, 0.0, 0.0))
    step_x = 2 * math.tan(math.radians(30.0)) / 320
    step_y = 2 * math.tan(math.radians(17.5)) / 200
    for north, east in ((-1.0, 0.3), (-0.37, -0.81), (0.52, 0.02)):
        exact = _irlock_reading(replace(base, quantize=False), north_off_m=north, east_off_m=east)
        grid = _irlock_reading(base, north_off_m=north, east_off_m=east)
        for angle_exact, angle_grid, step in ((exact.angle_x_rad, grid.angle_x_rad, step_x),
                                              (exact.angle_y_rad, grid.angle_y_rad, step_y)):
            pixels = math.tan(angle_grid) / step
            assert pixels - math.floor(pixels) == pytest.approx(0.5, abs=1e-6)  # a pixel centre
            assert abs(math.tan(angle_grid) - math.tan(angle_exact)) <= step / 2 + 1e-12
        assert (grid.angle_x_rad, grid.angle_y_rad) != (exact.angle_x_rad, exact.angle_y_rad)


def test_irlock_mount_offset_shifts_the_seen_beacon_by_the_offset():
    from preland_app.sensing.irlock import IrLockSpec

    centred = _irlock_reading(IrLockSpec(noise_sigma_deg=0.0, quantize=False, mount_offset_frd_m=(0.0, 0.0, 0.0)),
                              north_off_m=0.0, east_off_m=0.0)
    offset = _irlock_reading(IrLockSpec(noise_sigma_deg=0.0, quantize=False, mount_offset_frd_m=(0.0, -0.0125, 0.0)),
                             north_off_m=0.0, east_off_m=0.0)
    assert centred.angle_x_rad == pytest.approx(0.0, abs=1e-12)
    # The sensor 12.5 mm left sees the beacon below the centre 12.5 mm to its right, from 10 m.
    assert math.tan(offset.angle_x_rad) * 10.0 == pytest.approx(0.0125, rel=1e-6)


def test_irlock_frame_age_makes_a_reading_describe_the_earlier_pose():
    import asyncio

    import numpy as np

    from preland_app.clock import LoopClock, run_virtual
    from preland_app.sensing.irlock import IrLockModel, IrLockSpec
    from preland_app.sensing.sources import IrLockSource
    from preland_app.sensing.virtual_camera import CameraPose

    async def readings(latency_s):
        clock = LoopClock()
        spec = IrLockSpec(noise_sigma_deg=0.0, quantize=False, mount_offset_frd_m=(0.0, 0.0, 0.0),
                          latency_s=latency_s)
        # The vehicle slides east at 1 m/s, 10 m above the beacon.
        source = IrLockSource(model=IrLockModel(spec=spec, beacon_ned_m=(0.0, 0.0), rng=np.random.default_rng(0)),
                              pose=lambda: CameraPose(0.0, clock.now_s(), -10.0, 0.0, 0.0, 0.0), clock=clock)
        out = [await source.next_reading() for _ in range(10)]
        await asyncio.sleep(0)
        return out[-1], clock.now_s()

    fresh, now_s = run_virtual(readings(0.0))
    aged, _ = run_virtual(readings(0.02))
    assert fresh.capture_time_s == pytest.approx(now_s)
    assert aged.capture_time_s == pytest.approx(now_s - 0.02)
    # The aged reading sees the beacon from where the vehicle was 20 ms before: 2 cm less far west.
    assert -10.0 * math.tan(fresh.angle_x_rad) == pytest.approx(now_s, abs=1e-6)
    assert -10.0 * math.tan(aged.angle_x_rad) == pytest.approx(now_s - 0.02, abs=1e-6)


# ---------------------------------------------------------------- firmware (sim.spec.Firmware)


def _hovering_estimator(firmware, *, velocity_ne_m_s=(0.0, 0.0)):
    estimator = PrecisionLandingEstimator(ParameterTable(), firmware=firmware)
    estimator.record_pose(0.0, north_m=0.0, east_m=0.0, height_m=5.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0,
                          velocity_ne_m_s=velocity_ne_m_s)
    return estimator


def _readings(estimator, times_s, *, until_s):
    """Readings (the target 0.1 rad to the right) at `times_s`; one control cycle every 10 ms to `until_s`.
    Returns the first time (s) the target was used, or None."""
    pending = sorted(times_s)
    t = 0.0
    while t <= until_s:
        estimator.record_pose(t, north_m=0.0, east_m=0.0, height_m=5.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0)
        while pending and pending[0] <= t + 1e-9:
            estimator.handle(t, LandingTarget(timestamp_s=t, angle_x_rad=0.1, angle_y_rad=0.0))
            pending.pop(0)
        estimator.update(t)
        if estimator.target_acquired(t):
            return t
        t = round(t + 0.01, 6)
    return None


def test_copter_4_6_uses_a_target_after_two_seconds_of_readings_and_4_0_from_the_first():
    from preland_app.sim.spec import Firmware

    every_100_ms = [round(0.1 * i, 6) for i in range(60)]
    assert _readings(_hovering_estimator(Firmware.COPTER_4_0), every_100_ms, until_s=5.0) == 0.0
    acquired_s = _readings(_hovering_estimator(Firmware.COPTER_4_6), every_100_ms, until_s=5.0)
    assert acquired_s is not None and 2.0 < acquired_s <= 2.02
    # A 0.6 s gap during the wait fails it; the wait starts again at the next reading (1.6 s).
    gap = [t for t in every_100_ms if not 1.0 < t < 1.6]
    acquired_s = _readings(_hovering_estimator(Firmware.COPTER_4_6), gap, until_s=5.0)
    assert acquired_s is not None and 3.6 < acquired_s <= 3.62


def test_copter_4_6_starts_its_filter_at_minus_the_vehicles_velocity():
    from preland_app.sim.spec import Firmware

    estimator = _hovering_estimator(Firmware.COPTER_4_6, velocity_ne_m_s=(1.0, -0.5))
    assert estimator.handle(0.0, LandingTarget(timestamp_s=0.0, angle_x_rad=0.1, angle_y_rad=0.0))
    assert [f.velocity for f in estimator._filters] == [-1.0, 0.5]
    estimator = _hovering_estimator(Firmware.COPTER_4_0, velocity_ne_m_s=(1.0, -0.5))
    assert estimator.handle(0.0, LandingTarget(timestamp_s=0.0, angle_x_rad=0.1, angle_y_rad=0.0))
    assert [f.velocity for f in estimator._filters] == [0.0, 0.0]


def test_late_readings_carry_copter_4_0_off_the_beacon_and_not_copter_4_6(thesis_mission):
    # 4.0 feeds the estimator's velocity, which carries the readings' 350 ms delay, into the velocity loop;
    # 4.1 and later keep the EKF's there (docs: explanation, departures).
    from preland_app.runtime.embedded import TrialRequest, run_trial
    from preland_app.sim.spec import AutopilotSpec, Firmware

    calm = replace(thesis_mission.environment.wind, speed_m_s=0.5, turbulence_w20_m_s=0.5)
    errors = {}
    for firmware in Firmware:
        environment = replace(thesis_mission.environment, wind=calm, autopilot=AutopilotSpec(firmware=firmware))
        mission = replace(thesis_mission, environment=environment)
        errors[firmware] = [run_trial(TrialRequest(mission=mission, seed=seed, land_mode="irlock",
                                                   faults={"irlock": "delay:350"})).landing_error_cm
                            for seed in range(3)]
    assert max(errors[Firmware.COPTER_4_6]) < 5.0, errors
    assert max(errors[Firmware.COPTER_4_0]) > 15.0, errors


def test_copter_4_6_uses_a_raw_estimate_from_its_first_reading():
    # AC_PrecLand's RAW_SENSOR estimator (PLND_EST_TYPE=0) has no initialisation wait, in 4.6 as in 4.0.
    from preland_app.sim.spec import Firmware

    estimator = PrecisionLandingEstimator(ParameterTable({"PLND_EST_TYPE": 0}), firmware=Firmware.COPTER_4_6)
    assert _readings(estimator, [round(0.1 * i, 6) for i in range(60)], until_s=5.0) == 0.0

"""Precision land modes end to end, and the onboard precision landing fed through the Vehicle protocol."""

import functools
import math
from dataclasses import replace

import numpy as np
import pytest

from preland_app.sensing.spec import MarkerSensorSpec
from preland_app.sensing.virtual_camera import rotation_ned_from_body

from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.vehicle.types import FlightMode, LandingTarget

from .conftest import ROOT
from .test_sim_autopilot import CALM, airborne, fly


@pytest.fixture(scope="module")
def thesis_landing(thesis_mission):
    """The thesis mission flown in a land mode from a seed, each flown once in this module: a trial is
    deterministic, and the marker landing from seed 1 is one two tests read."""
    return functools.cache(lambda mode, seed: run_trial(
        TrialRequest(mission=thesis_mission, seed=seed, land_mode=mode, record_trajectory=False)))


@pytest.mark.parametrize("mode", ["irlock", "marker", "fused"])
def test_precision_modes_land_on_the_pad(thesis_landing, mode):
    for seed in (0, 1):
        outcome = thesis_landing(mode, seed)
        assert outcome.outcome is Outcome.LANDED, outcome.message
        assert outcome.scoring_reference == "pad"
        assert outcome.landing_error_cm < 15.0
        assert outcome.details["landing_targets_sent"] > 100
    expected_altitude = 6.0 if mode == "marker" else 10.0
    assert outcome.takeoff_altitude_rel_m == expected_altitude


def test_the_missions_detector_parameters_reach_the_companions_detector(thesis_mission, thesis_landing):
    # OpenCV's maxMarkerPerimeterRate 0.3: nothing over 192 px round (the 60 cm marker below about 6 m) is a
    # candidate, so the marker is lost over the middle of the descent until the 9 cm one comes into view.
    limited = replace(thesis_mission, sensors=replace(
        thesis_mission.sensors, marker=MarkerSensorSpec(detector={"maxMarkerPerimeterRate": 0.3})))
    default = thesis_landing("marker", 1)
    narrowed = run_trial(TrialRequest(mission=limited, seed=1, land_mode="marker", record_trajectory=False))
    assert default.details["landing_targets_sent"] > 250
    assert narrowed.details["landing_targets_sent"] < 0.8 * default.details["landing_targets_sent"]
    assert narrowed.landing_error_cm > 3 * default.landing_error_cm


def test_fused_mode_uses_both_sensors_and_averages_when_both_are_new(thesis_mission):
    outcome = run_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode="fused", record_trajectory=False))
    assert outcome.details["fused_both"] > 50
    assert outcome.details["fused_irlock"] > 50
    assert outcome.details["irlock_produced"] > outcome.details["marker_produced"] > 50
    assert outcome.details["irlock_dropped"] == outcome.details["marker_dropped"] == 0


def _companion_pointing(offset_north_m, offset_east_m, *, enable, stop_below_m=None):
    """Fly up, then LAND while a companion reports the target at a fixed NED spot near the start."""

    async def scenario(vehicle, simulator, clock):
        if enable:
            for name, value in {"PLND_ENABLED": 1, "PLND_TYPE": 1, "PLND_STRICT": 0}.items():
                await vehicle.set_param(name, value)
        await airborne(vehicle, clock, altitude_m=8.0)
        await vehicle.set_mode(FlightMode.LAND)
        while (await vehicle.telemetry()).armed:
            truth = simulator.true_pose()
            height = -truth.down_m
            if stop_below_m is None or height > stop_below_m:
                # Line of sight from the true pose, in the body frame (a tilt of 10 degrees at 8 m moves the
                # target 1.4 m: the autopilot's outlier gate refuses a line of sight that leaves the tilt out).
                line_ned = np.array([offset_north_m - truth.north_m, offset_east_m - truth.east_m, height])
                forward, right, down = rotation_ned_from_body(truth.roll_rad, truth.pitch_rad,
                                                              truth.yaw_rad).T @ line_ned
                await vehicle.send_landing_target(LandingTarget(
                    timestamp_s=clock.now_s(), angle_x_rad=math.atan2(right, max(down, 0.1)),
                    angle_y_rad=math.atan2(-forward, max(down, 0.1))))
            await clock.sleep(0.05)
        return simulator.touchdowns()[-1], simulator.autopilot.messages

    return fly(scenario, environment=CALM)


def test_landing_target_steers_land_when_precision_landing_is_enabled():
    touchdown, messages = _companion_pointing(1.5, -1.0, enable=True)
    assert math.hypot(touchdown.north_m - 1.5, touchdown.east_m + 1.0) < 0.1
    assert any("target acquired" in m.text for m in messages)


def test_landing_target_is_ignored_without_plnd():
    touchdown, _ = _companion_pointing(1.5, -1.0, enable=False)
    # Plain LAND where it stood (within the GPS error), not steered to the reported spot 1.8 m away.
    from_start = math.hypot(touchdown.north_m, touchdown.east_m)
    assert from_start < 1.0
    assert math.hypot(touchdown.north_m - 1.5, touchdown.east_m + 1.0) > from_start + 0.5


def test_target_lost_low_down_the_descent_continues():
    touchdown, messages = _companion_pointing(1.5, -1.0, enable=True, stop_below_m=2.0)
    texts = [m.text for m in messages]
    assert "PrecLand: target lost" in texts and texts[-1].startswith("Disarming")
    # It lands near the target, not where it started (1.8 m away): after the loss the estimator
    # coasts on the IMU for 2 s, and the attitude error's gravity leak makes that drift.
    assert math.hypot(touchdown.north_m - 1.5, touchdown.east_m + 1.0) < 1.0


def test_raw_estimator_option_also_lands_on_the_pad(thesis_mission):
    from dataclasses import replace

    mission = replace(thesis_mission, params={"PLND_EST_TYPE": 0})
    outcome = run_trial(TrialRequest(mission=mission, seed=4, land_mode="irlock", record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED and outcome.landing_error_cm < 15.0


def test_a_measurement_that_is_not_a_number_is_dropped_not_fused():
    # One NaN fused into the estimator's filter made the LAND position target NaN for good.
    import math as _math

    from preland_app.sim.params import ParameterTable
    from preland_app.sim.precland import PrecisionLandingEstimator
    from preland_app.vehicle.types import LandingTarget

    estimator = PrecisionLandingEstimator(ParameterTable())
    estimator.record_pose(0.0, north_m=0.0, east_m=0.0, height_m=5.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0)
    estimator.record_pose(0.05, north_m=0.0, east_m=0.0, height_m=5.0, roll_rad=0.0, pitch_rad=0.0, yaw_rad=0.0)
    bad = LandingTarget(timestamp_s=0.05, angle_x_rad=_math.nan, angle_y_rad=0.0, distance_m=None)
    assert estimator.handle(0.05, bad) is False and estimator.measurements_dropped == 1
    good = LandingTarget(timestamp_s=0.05, angle_x_rad=0.1, angle_y_rad=0.0, distance_m=None)
    assert estimator.handle(0.05, good) is True
    north, east = estimator.relative_position_m(0.05)
    assert _math.isfinite(north) and east > 0.4  # 5 m * tan(0.1 rad) to the right


def test_the_marker_trial_whose_pose_fit_came_back_nan_now_lands():
    # thesis_fidelity.yaml's "Marker / none" trial 77 (seed 151972701): solvePnP returned "ok" with NaNs at
    # 2 m, the NaN reading reached the estimator, and the trial ended as an error.
    from preland_app.campaign.spec import load_campaign, resolve_scenarios

    campaign = load_campaign(ROOT / "campaigns" / "thesis_fidelity.yaml")
    (scenario,) = [s for s in resolve_scenarios(campaign) if s.spec.label == "Marker / none"]
    outcome = run_trial(TrialRequest(mission=scenario.mission, seed=151972701,
                                     takeoff_altitude_rel_m=scenario.takeoff_altitude_rel_m, record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED and outcome.landing_error_cm < 15.0


def test_an_outlier_is_refused_until_three_in_a_row_were_refused():
    """AC_PrecLand's gate: a measurement whose NIS is 3 or more on an axis is not fused, and the fourth such
    measurement in a row is (a target that really moved is followed); the raw estimator has no gate."""
    from preland_app.sim.params import ParameterTable
    from preland_app.sim.precland import PrecisionLandingEstimator
    from preland_app.vehicle.types import LandingTarget

    def estimator_at_rest(params: ParameterTable) -> PrecisionLandingEstimator:
        estimator = PrecisionLandingEstimator(params)
        for k in range(40):
            estimator.record_pose(0.02 * k, north_m=0.0, east_m=0.0, height_m=5.0, roll_rad=0.0, pitch_rad=0.0,
                                  yaw_rad=0.0)
        return estimator

    def target(time_s: float, east_m: float) -> LandingTarget:
        return LandingTarget(timestamp_s=time_s, angle_x_rad=math.atan2(east_m, 5.0), angle_y_rad=0.0,
                             distance_m=None)

    estimator = estimator_at_rest(ParameterTable())
    for k in range(10):
        assert estimator.handle(0.4 + 0.02 * k, target(0.4 + 0.02 * k, 0.5)) is True
    _, east_before = estimator.relative_position_m(0.6)
    # 2 m off, four times in a row: three refused, the fourth fused.
    results = [estimator.handle(0.62 + 0.02 * k, target(0.62 + 0.02 * k, 2.5)) for k in range(4)]
    assert results == [False, False, False, True] and estimator.measurements_rejected == 3
    _, east_after = estimator.relative_position_m(0.7)
    assert east_before == pytest.approx(0.5, abs=0.01) and 0.6 < east_after < 2.5  # fused: moved towards it
    # One outlier between good measurements is refused and leaves the estimate where it was.
    estimator = estimator_at_rest(ParameterTable())
    for k in range(10):
        estimator.handle(0.4 + 0.02 * k, target(0.4 + 0.02 * k, 0.5))
    assert estimator.handle(0.62, target(0.62, 2.5)) is False
    assert estimator.handle(0.64, target(0.64, 0.5)) is True
    assert estimator.relative_position_m(0.64)[1] == pytest.approx(0.5, abs=0.01)
    # PLND_EST_TYPE=0: no gate.
    raw = estimator_at_rest(ParameterTable({"PLND_EST_TYPE": 0}))
    for k in range(10):
        raw.handle(0.4 + 0.02 * k, target(0.4 + 0.02 * k, 0.5))
    assert raw.handle(0.62, target(0.62, 2.5)) is True and raw.measurements_rejected == 0
    assert raw.relative_position_m(0.62)[1] == pytest.approx(2.5, abs=0.01)

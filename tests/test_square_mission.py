"""The thesis mission on the embedded simulator: path shape, landing, determinism."""

import json
import math

import numpy as np
import pytest

from preland_app.outcome import TRAJECTORY_COLUMNS, Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial

COL = {name: i for i, name in enumerate(TRAJECTORY_COLUMNS)}


def _corner_targets(outcome):
    recorded = next(e for e in outcome.events if e.kind == "recorded")
    return [(e.data["target_north_m"], e.data["target_east_m"]) for e in outcome.events if e.kind == "waypoint"], recorded


def test_estimate_passes_each_corner_within_half_a_metre(square_trial, thesis_mission):
    corners, recorded = _corner_targets(square_trial)
    assert len(corners) == 4
    expected = [(recorded.data["north_m"] + n, recorded.data["east_m"] + e)
                for n, e in thesis_mission.path.waypoints_rel_ned_m]
    assert np.allclose(corners, expected)
    track = square_trial.trajectory
    for north, east in corners:
        distances = np.hypot(track[:, COL["est_north_m"]] - north, track[:, COL["est_east_m"]] - east)
        assert distances.min() <= 0.5


def test_true_path_is_a_square_of_two_metre_legs(square_trial):
    track = square_trial.trajectory
    times = [e.time_s for e in square_trial.events if e.kind in ("recorded", "waypoint")]
    assert len(times) == 5
    true_points = []
    for t in times:
        row = np.argmin(np.abs(track[:, COL["time_s"]] - t))
        true_points.append((track[row, COL["true_north_m"]], track[row, COL["true_east_m"]]))
    legs = [math.dist(a, b) for a, b in zip(true_points, true_points[1:])]
    # A waypoint counts as reached within 0.2 m of it (estimate), so each end of a leg may fall up to
    # 0.2 m short, and the GPS error drifts a little during the leg.
    assert legs == pytest.approx([2.0] * 4, abs=0.45)
    # Directions: south, east, north, west (the square turns away from the pad, which is north).
    headings = [math.degrees(math.atan2(b[1] - a[1], b[0] - a[0])) % 360 for a, b in zip(true_points, true_points[1:])]
    assert headings == pytest.approx([180, 90, 0, 270], abs=15)


def test_vehicle_lands_and_disarms(square_trial):
    assert square_trial.outcome is Outcome.LANDED
    kinds = [e.kind for e in square_trial.events]
    assert kinds.index("land_command") < kinds.index("disarmed")
    track = square_trial.trajectory
    assert track[-1, COL["true_altitude_m"]] == pytest.approx(0.0, abs=1e-9)
    assert square_trial.touchdown_speed_m_s < 1.0
    # LAND from 10 m at ArduCopter's LAND_SPEED (0.5 m/s) takes about 20 s.
    assert 18.0 < square_trial.landing_time_s < 26.0


def test_same_seed_gives_identical_json(thesis_mission):
    a = run_trial(TrialRequest(mission=thesis_mission, seed=42, record_trajectory=False))
    b = run_trial(TrialRequest(mission=thesis_mission, seed=42, record_trajectory=False))
    assert json.dumps(a.to_dict(include_events=True), sort_keys=True) == json.dumps(
        b.to_dict(include_events=True), sort_keys=True)


def test_different_seeds_give_different_gps_errors(thesis_mission):
    offsets = set()
    for seed in (1, 2, 3):
        o = run_trial(TrialRequest(mission=thesis_mission, seed=seed, record_trajectory=False))
        offsets.add((round(o.offset_north_cm, 1), round(o.offset_east_cm, 1)))
    assert len(offsets) == 3


def test_normal_landing_error_is_gps_sized(thesis_mission):
    errors = [run_trial(TrialRequest(mission=thesis_mission, seed=seed, record_trajectory=False)).landing_error_cm
              for seed in range(10)]
    mean = sum(errors) / len(errors)
    assert 40.0 <= mean <= 120.0, errors
    assert max(errors) < 300.0

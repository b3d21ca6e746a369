"""Fault injection in flight and the cautious (retrying) landing."""

from dataclasses import replace

import pytest

from preland_app.landing.cautious import CautiousSpec
from preland_app.landing.attempts import AttemptTracker
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial


def test_attempt_tracker_counts_a_climb_once():
    tracker = AttemptTracker()
    altitudes = [6, 5, 4, 3, 2.5, 2.4, 2.6, 3.0, 3.5, 4.0, 4.4, 4.0, 3.5, 2.0, 1.0, 1.5, 1.2]
    starts = [a for a in altitudes if tracker.update(a)]
    assert tracker.attempt == 2 and starts == [3.0]


def test_marker_below_three_metres_in_the_first_attempt(thesis_mission):
    fault = {"marker": "below:3:first-attempt"}
    default = run_trial(TrialRequest(mission=thesis_mission, seed=2, land_mode="marker", faults=fault,
                                     record_trajectory=False))
    cautious = run_trial(TrialRequest(mission=thesis_mission, seed=2, land_mode="cautious", sensor="marker",
                                      faults=fault, record_trajectory=False))
    assert default.outcome is cautious.outcome is Outcome.LANDED
    assert default.details["marker_dropped"] > 20 and default.details["attempts"] == 1
    assert cautious.details["attempts"] == 2
    assert cautious.landing_error_cm < 10.0 < default.landing_error_cm
    assert cautious.landing_time_s > default.landing_time_s + 5.0
    kinds = [e.kind for e in cautious.events]
    assert kinds.count("attempt") == 1


def test_cautious_gives_up_after_plnd_ret_max_and_lands_blind(thesis_mission):
    land = replace(thesis_mission.land, cautious=CautiousSpec(PLND_RET_MAX=2, PLND_TIMEOUT=2.0))
    mission = replace(thesis_mission, land=land)
    outcome = run_trial(TrialRequest(mission=mission, seed=5, land_mode="cautious", sensor="marker",
                                     faults={"marker": "below:3"}, record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED
    assert outcome.details["attempts"] == 3  # the first one and two retries
    assert outcome.details["marker_dropped"] > 0
    attempts = [e for e in outcome.events if e.kind == "attempt"]
    assert [e.data["attempt"] for e in attempts] == [2, 3]
    # It lands blind, so it misses by more than a tracked landing would.
    assert outcome.landing_error_cm > 5.0


def test_hover_strictness_never_lands_and_times_out(thesis_mission):
    land = replace(thesis_mission.land, cautious=CautiousSpec(PLND_STRICT=2, PLND_RET_MAX=1, PLND_TIMEOUT=1.0))
    timeouts = replace(thesis_mission.timeouts, land_s=60.0)
    mission = replace(thesis_mission, land=land, timeouts=timeouts)
    outcome = run_trial(TrialRequest(mission=mission, seed=5, land_mode="cautious", sensor="marker",
                                     faults={"marker": "below:3"}, record_trajectory=False))
    assert outcome.outcome is Outcome.TIMED_OUT
    assert "land" in outcome.message and outcome.landing_error_cm is None


@pytest.mark.parametrize("mode, faults", [
    ("irlock", {"irlock": "permanent"}),
    ("fused", {"irlock": "permanent", "marker": "permanent"}),
])
def test_permanent_failure_falls_back_to_a_gps_landing(thesis_mission, mode, faults):
    outcome = run_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode=mode, faults=faults,
                                     record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED
    for sensor in faults:
        assert outcome.details[f"{sensor}_dropped"] == outcome.details[f"{sensor}_produced"] > 0
    assert outcome.details.get("landing_targets_sent", 0) == 0
    assert outcome.landing_error_cm > 20.0  # nothing guided it onto the pad


def test_fused_survives_complementary_failures(thesis_mission):
    both = {"irlock": "below:3", "marker": "above:3"}
    outcome = run_trial(TrialRequest(mission=thesis_mission, seed=6, land_mode="fused", faults=both,
                                     record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED and outcome.landing_error_cm < 15.0
    assert outcome.details["irlock_dropped"] > 0 and outcome.details["marker_dropped"] > 0

"""A land mode that returns before the vehicle has disarmed: the trial lands only once it has."""

from dataclasses import replace

from preland_app.landing import LandingReport, ScoringReference
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.vehicle.types import FlightMode


class HandOverToLand:
    """Switches to LAND and returns at once, leaving the touchdown to the autopilot."""

    name = "hand_over_to_land"
    scoring_reference = ScoringReference.TAKEOFF
    uses_irlock = uses_marker = False

    async def land(self, context):
        await context.vehicle.set_mode(FlightMode.LAND)
        return LandingReport(details={"handed_over": True})


class HoverAndReturn:
    """Returns at once, leaving the vehicle hovering in GUIDED."""

    name = "hover_and_return"
    scoring_reference = ScoringReference.TAKEOFF
    uses_irlock = uses_marker = False

    async def land(self, context):
        await context.vehicle.hold()
        return LandingReport(details={})


def _fly(mission, strategy_class, **request):
    import preland_app.landing.registry as registry

    name = f"{__name__}:{strategy_class.__name__}"
    assert registry.create_land_strategy(name).name == strategy_class.name
    return run_trial(TrialRequest(mission=mission, seed=3, land_mode=name, **request))


def test_a_land_mode_that_hands_over_to_land_is_scored_at_its_touchdown(thesis_mission):
    handed = _fly(thesis_mission, HandOverToLand)
    normal = run_trial(TrialRequest(mission=thesis_mission, seed=3, land_mode="normal"))
    assert handed.outcome is Outcome.LANDED
    assert handed.details["handed_over"] is True
    # The same LAND from the same point and seed as the built-in GPS landing: the same touchdown.
    assert handed.landing_error_cm is not None
    assert abs(handed.landing_error_cm - normal.landing_error_cm) < 1.0
    assert handed.landing_time_s > 10.0  # a 10 m descent, not the instant the mode returned
    assert handed.flight_time_s > handed.landing_time_s


def test_a_land_mode_that_returns_in_the_air_times_out_instead_of_landing(thesis_mission):
    timeouts = replace(thesis_mission.timeouts, land_s=20.0)
    outcome = _fly(replace(thesis_mission, timeouts=timeouts), HoverAndReturn)
    assert outcome.outcome is Outcome.TIMED_OUT
    assert "land" in outcome.message
    assert outcome.landing_error_cm is None

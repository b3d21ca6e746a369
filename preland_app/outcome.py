"""A trial's outcome: where it touched down, how far from the reference, how long it took.

Scoring uses ground truth (simulator state, SITL's SIMSTATE, or the operator's
tape measure); nothing here feeds back into landing decisions.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .events import MissionEvent


class Outcome(enum.Enum):
    """How a trial ended."""

    LANDED = "landed"
    ABORTED = "aborted"
    TIMED_OUT = "timed_out"
    CRASHED = "crashed"
    LINK_LOST = "link_lost"
    PILOT_TAKEOVER = "pilot_takeover"
    ERROR = "error"

    @property
    def description(self) -> str:
        return {
            Outcome.LANDED: "landed and disarmed",
            Outcome.ABORTED: "the mission stopped before landing",
            Outcome.TIMED_OUT: "a step did not finish within its timeout",
            Outcome.CRASHED: "the vehicle hit the ground too hard or tilted over",
            Outcome.LINK_LOST: "the link to the vehicle was lost",
            Outcome.PILOT_TAKEOVER: "the pilot took over (a mode change preland did not make)",
            Outcome.ERROR: "the trial failed with an error",
        }[self]


TRAJECTORY_COLUMNS = (
    "time_s",
    "est_north_m",
    "est_east_m",
    "est_altitude_rel_m",
    "true_north_m",
    "true_east_m",
    "true_altitude_m",
)
"""Trajectory columns. `est_*`: the autopilot's estimate, NED from home. `true_*`: ground truth,
NED from the start position (the take-off spot), where the runtime has it (NaN otherwise)."""


@dataclass(frozen=True)
class LandingScore:
    """Touchdown relative to the scoring reference, in cm (north, east, and horizontal distance)."""

    landing_error_cm: float
    offset_north_cm: float
    offset_east_cm: float


def score_touchdown(*, touchdown_ned_m: tuple[float, float], reference_ned_m: tuple[float, float]) -> LandingScore:
    """Horizontal offset of a touchdown from a reference point (both NED, same origin, m)."""
    north_cm = (touchdown_ned_m[0] - reference_ned_m[0]) * 100.0
    east_cm = (touchdown_ned_m[1] - reference_ned_m[1]) * 100.0
    return LandingScore(math.hypot(north_cm, east_cm), north_cm, east_cm)


@dataclass(frozen=True, kw_only=True)
class TrialScore:
    """A trial's figures from ground truth: the touchdown's offset from the reference (None when it was not
    scored), landing time (hand-over to touchdown, s) and flight time (arming to disarming, s)."""

    score: LandingScore | None
    landing_time_s: float | None
    flight_time_s: float | None


def reference_ned_m(*, pad_offset_ned_m: tuple[float, float], scored_from_pad: bool) -> tuple[float, float]:
    """The point a landing's error is measured from, NED from the start position (m): the pad's centre,
    or the take-off point (the thesis scores its GPS-only landings from there, Section 8.2.3)."""
    return tuple(pad_offset_ned_m) if scored_from_pad else (0.0, 0.0)


def score_trial(*, touchdown_ned_m: tuple[float, float] | None, touchdown_s: float | None, scored: bool,
                reference_ned_m: tuple[float, float], handover_s: float | None, armed_s: float | None,
                disarmed_s: float | None) -> TrialScore:
    """Every runtime's scoring: the final touchdown (NED from the start, m) against the reference when the
    trial is `scored` (it landed, or crashed), and its times (vehicle s) where each is known."""
    score = None
    if scored and touchdown_ned_m is not None:
        score = score_touchdown(touchdown_ned_m=touchdown_ned_m, reference_ned_m=reference_ned_m)
    landing_time_s = touchdown_s - handover_s if touchdown_s is not None and handover_s is not None else None
    flight_time_s = disarmed_s - armed_s if armed_s is not None and disarmed_s is not None else None
    return TrialScore(score=score, landing_time_s=landing_time_s, flight_time_s=flight_time_s)


@dataclass(frozen=True, kw_only=True)
class TrialOutcome:
    """Everything one trial produced. Times in vehicle seconds; offsets in cm."""

    outcome: Outcome
    message: str
    seed: int
    mission: str
    land_mode: str
    takeoff_altitude_rel_m: float
    scoring_reference: str
    landing_error_cm: float | None = None
    offset_north_cm: float | None = None
    offset_east_cm: float | None = None
    landing_time_s: float | None = None
    flight_time_s: float | None = None
    touchdown_speed_m_s: float | None = None
    details: dict[str, Any] = field(default_factory=dict)
    events: tuple[MissionEvent, ...] = ()
    trajectory: np.ndarray | None = field(default=None, compare=False, repr=False)

    def to_dict(self, *, include_events: bool = False) -> dict[str, Any]:
        """A JSON-ready dict (rounded to what the measurement supports)."""

        def rounded(value: float | None, digits: int) -> float | None:
            return None if value is None else round(float(value), digits)

        data: dict[str, Any] = {
            "outcome": self.outcome.value,
            "message": self.message,
            "seed": self.seed,
            "mission": self.mission,
            "land_mode": self.land_mode,
            "takeoff_altitude_rel_m": self.takeoff_altitude_rel_m,
            "scoring_reference": self.scoring_reference,
            "landing_error_cm": rounded(self.landing_error_cm, 2),
            "offset_north_cm": rounded(self.offset_north_cm, 2),
            "offset_east_cm": rounded(self.offset_east_cm, 2),
            "landing_time_s": rounded(self.landing_time_s, 2),
            "flight_time_s": rounded(self.flight_time_s, 2),
            "touchdown_speed_m_s": rounded(self.touchdown_speed_m_s, 3),
            "details": self.details,
        }
        if include_events:
            data["events"] = [event.to_dict() for event in self.events]
        return data


def outcome_for_error(error: Exception) -> tuple[Outcome, str]:
    """How a trial that ended with `error` is recorded: its outcome and a readable message."""
    from .errors import LandModeFailed, LinkLost, MissionAborted, PrelandError, VehicleCrashed, WaitTimeout
    from .field.takeover import PilotTakeover

    for kind, outcome in ((WaitTimeout, Outcome.TIMED_OUT), (MissionAborted, Outcome.ABORTED),
                          (VehicleCrashed, Outcome.CRASHED), (LinkLost, Outcome.LINK_LOST),
                          (PilotTakeover, Outcome.PILOT_TAKEOVER)):
        if isinstance(error, kind):
            return outcome, str(error)
    if isinstance(error, LandModeFailed):  # already names the land mode and the exception
        return Outcome.ERROR, str(error)
    if isinstance(error, PrelandError):
        return Outcome.ERROR, f"{type(error).__name__}: {error}"
    # A bug must still end as this trial's outcome, not kill a campaign.
    return Outcome.ERROR, f"unexpected {type(error).__name__}: {error}"

"""What every land mode implements (`LandStrategy`), and the context it runs in (`LandingContext`).

The contract, for built-in modes and plugins alike:

* A land mode starts when the mission hands over to it: the vehicle is
  armed, in GUIDED, hovering at the take-off altitude over the position recorded
  after take-off. The mission runner records the hand-over (event
  `land_handover`); landing time runs from there to touchdown on every runtime.
* `land(context)` returns a `LandingReport` once the vehicle is on the ground
  and disarmed (switching to LAND near the ground and waiting for the disarm is
  the usual way). It must not block the event loop (no `time.sleep`, no long
  computation without an `await`) and must let itself be cancelled.
* Time: only `context.clock` (vehicle seconds; the embedded simulator runs
  faster than wall time, SITL at its speed-up). Never `time.time()` or
  `asyncio.sleep` for waiting: those are wall time.
* Randomness: only `context.rng` (seeded from the trial), so a seed gives the
  same landing on every run.
* Units and frames are in the names: metres, seconds, m/s, radians or degrees
  as named; positions NED from home (`position_ned_m`), body velocities FRD
  (`set_velocity_body(forward_m_s=, right_m_s=, down_m_s=)`, yaw-rotated),
  LANDING_TARGET angles in body FRD; camera detections in the OpenCV camera
  frame (x right, y down in the image = body backward, z down).
* Truth: a land mode sees what a companion computer sees, never the
  simulator's ground truth. The context holds views only (see
  `landing/boundary.py`): the Vehicle protocol and nothing more, readings from
  the sensors. It must not import preland's simulator or runtime.
* Outcome: the runtime scores the touchdown from its own truth against
  `scoring_reference` (the pad's centre or the take-off position), and stores
  `LandingReport.details` (JSON-ready values) with the trial; the runtime adds
  its own keys (wind, runtime, fault counters).
* Failures: an exception in `land()` ends the trial with outcome `error`
  naming its type and message; a `land()` still running after the mission's
  `timeouts.land_s` is cancelled and the trial ends `timed_out`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..clock import Clock
from .boundary import (
    ClockView,
    EventView,
    SensorView,
    VehicleView,
    as_clock_view,
    as_event_view,
    as_sensor_view,
    as_vehicle_view,
)


class ScoringReference(enum.Enum):
    """What a landing's error is measured against (thesis Section 8.2.3)."""

    PAD = "pad"  # precision modes: the pad's centre
    TAKEOFF = "takeoff"  # normal mode: the take-off position


@dataclass(frozen=True, kw_only=True)
class LandingContext:
    """What a land mode may use; no ground truth in here, by construction: whatever vehicle, clock, event
    log and sensor suite it is made with, it holds views of them (`landing/boundary.py`).

    `vehicle`: the Vehicle protocol; `clock`: vehicle seconds; `events`: the trial's event log;
    `rng`: a generator seeded from the trial; `timeout_s`: the mission's `timeouts.land_s`;
    `poll_period_s`: the mission's telemetry polling period; `sensors`: the sensor suite (None when the
    vehicle has no sensors)."""

    vehicle: VehicleView
    clock: ClockView
    events: EventView
    rng: np.random.Generator
    timeout_s: float
    poll_period_s: float = 0.1
    sensors: SensorView | None = None

    def __post_init__(self) -> None:
        clock: Clock = self.clock
        object.__setattr__(self, "vehicle", as_vehicle_view(self.vehicle))
        object.__setattr__(self, "clock", as_clock_view(clock))
        object.__setattr__(self, "events", as_event_view(self.events))
        if self.sensors is not None:
            object.__setattr__(self, "sensors", as_sensor_view(self.sensors, clock=clock))


@dataclass
class LandingReport:
    """What a land mode reports about its landing (counters, switches, attempts...): JSON-ready values,
    stored with the trial (the `details` column of the results store, `details` in `--json`)."""

    details: dict[str, Any] = field(default_factory=dict)


class LandStrategy(Protocol):
    """A land mode. `name`: a word for reports; `scoring_reference`: what its error is measured against;
    `uses_irlock` / `uses_marker`: which sensors the runtime must give it (`context.sensors`)."""

    name: str
    scoring_reference: ScoringReference
    uses_irlock: bool
    uses_marker: bool

    async def land(self, context: LandingContext) -> LandingReport:
        """Land and return once disarmed on the ground; raises on timeout or refusal."""
        ...


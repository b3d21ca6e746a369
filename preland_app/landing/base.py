"""What every land mode implements, and the context it runs in.

A land mode starts once the mission has flown its path. It decides from what a
companion computer knows (telemetry, camera, sensor readings), never from
simulator truth, and commands the vehicle only through the Vehicle protocol.
`land()` returns when the vehicle is on the ground and disarmed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from ..clock import Clock
from ..events import EventLog
from ..sensing.suite import SensorSuite
from ..vehicle.protocol import Vehicle


class ScoringReference(enum.Enum):
    """What a landing's error is measured against (thesis Section 8.2.3)."""

    PAD = "pad"  # precision modes: the pad's centre
    TAKEOFF = "takeoff"  # normal mode: the take-off position


@dataclass(frozen=True, kw_only=True)
class LandingContext:
    """What a land mode may use. No ground truth in here, on purpose."""

    vehicle: Vehicle
    clock: Clock
    events: EventLog
    rng: np.random.Generator
    timeout_s: float
    poll_period_s: float = 0.1
    sensors: SensorSuite | None = None


@dataclass
class LandingReport:
    """What a land mode reports about its landing (counters, switches, attempts...)."""

    details: dict[str, Any] = field(default_factory=dict)


class LandStrategy(Protocol):
    name: str
    scoring_reference: ScoringReference
    uses_irlock: bool
    uses_marker: bool

    async def land(self, context: LandingContext) -> LandingReport:
        """Land and return once disarmed on the ground; raises on timeout or refusal."""
        ...

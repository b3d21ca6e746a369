"""A trial's event log: what happened when, on the vehicle clock."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .clock import Clock


@dataclass(frozen=True, slots=True)
class MissionEvent:
    """One event. `time_s` is vehicle-clock seconds; `data` holds numbers in named units."""

    time_s: float
    kind: str
    message: str
    data: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"time_s": round(self.time_s, 3), "kind": self.kind, "message": self.message, **self.data}


class EventLog:
    """Append-only list of `MissionEvent`s stamped with the clock's time."""

    def __init__(self, clock: Clock) -> None:
        self._clock = clock
        self.events: list[MissionEvent] = []

    def add(self, kind: str, message: str, **data: Any) -> MissionEvent:
        event = MissionEvent(self._clock.now_s(), kind, message, data)
        self.events.append(event)
        return event

    def first(self, kind: str) -> MissionEvent | None:
        return next((e for e in self.events if e.kind == kind), None)

    def all(self, kind: str) -> list[MissionEvent]:
        return [e for e in self.events if e.kind == kind]

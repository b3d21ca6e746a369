"""Pilot takeover: a flight-mode change preland did not make stops every preland command at once.

`GuardedVehicle` wraps a Vehicle. It remembers the modes preland commanded;
`check(telemetry)` (called by the mission's watcher) notices any other mode,
and from then on every command raises PilotTakeover, so nothing preland sends
can fight the pilot.
"""

from __future__ import annotations

from typing import Any

from ..errors import PrelandError
from ..vehicle.protocol import Vehicle
from ..vehicle.types import FlightMode, Telemetry

_COMMANDS = {"arm", "disarm", "takeoff", "goto_ned", "goto_global", "set_velocity_ned", "set_velocity_body", "hold",
             "set_mode", "set_param", "send_landing_target"}
# The Vehicle protocol's other members; nothing else of the backend passes through the guard.
_QUERIES = {"connect", "close", "get_param", "telemetry"}


class PilotTakeover(PrelandError):
    """The pilot changed the flight mode: preland has stopped commanding the vehicle."""


class GuardedVehicle:
    """A Vehicle that stops obeying preland once the pilot takes over."""

    # A mode report can trail a commanded change by a message or two; a real takeover persists.
    CONFIRM_S = 0.25

    def __init__(self, vehicle: Vehicle) -> None:
        self._vehicle = vehicle
        self.commanded_modes: list[FlightMode] = []
        self.taken_over: str | None = None
        self._mismatch_since_s: float | None = None
        self._changing_to: FlightMode | None = None  # a mode change sent and not yet acknowledged

    @property
    def clock(self):
        return self._vehicle.clock

    async def set_mode(self, mode: FlightMode) -> None:
        """The mode counts as preland's once the vehicle accepts it; until then, the one before it and this one
        both do (the change can take longer than CONFIRM_S to acknowledge at a high speed-up)."""
        self._raise_if_taken_over("set_mode")
        self._changing_to = mode
        self._mismatch_since_s = None
        try:
            await self._vehicle.set_mode(mode)
        finally:
            self._changing_to = None
        self._raise_if_taken_over("set_mode")  # the pilot took over while the change was on its way
        self.commanded_modes.append(mode)
        self._mismatch_since_s = None

    def check(self, telemetry: Telemetry) -> None:
        """Raise PilotTakeover (once, and on every command after) when the vehicle has been in a mode
        preland did not set for CONFIRM_S vehicle seconds."""
        if self.taken_over is None and self.commanded_modes:
            if telemetry.mode is self.commanded_modes[-1] or telemetry.mode is self._changing_to:
                self._mismatch_since_s = None
            elif self._mismatch_since_s is None:
                self._mismatch_since_s = telemetry.time_s
            elif telemetry.time_s - self._mismatch_since_s >= self.CONFIRM_S:
                self.taken_over = (f"pilot takeover: mode {telemetry.mode.name}, preland had set "
                                   f"{self.commanded_modes[-1].name}")
        self._raise_if_taken_over("watch")

    def _raise_if_taken_over(self, operation: str) -> None:
        if self.taken_over is not None:
            raise PilotTakeover(self.taken_over)

    def __getattr__(self, name: str) -> Any:
        if name not in _COMMANDS and name not in _QUERIES:
            raise AttributeError(f"{type(self).__name__} has no {name!r}: it passes on the Vehicle protocol only")
        attribute = getattr(self._vehicle, name)
        if name in _COMMANDS and callable(attribute):
            async def guarded(*args, **kwargs):
                self._raise_if_taken_over(name)
                return await attribute(*args, **kwargs)

            return guarded
        return attribute

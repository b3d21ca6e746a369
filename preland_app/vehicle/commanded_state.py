"""A commanded state (armed or not, a flight mode) that the vehicle has accepted and its HEARTBEATs have not
shown yet: what the vehicle is taken to be in meanwhile (`vehicle.mavlink_backend`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .types import FlightMode

# HEARTBEAT arrives on MAVSDK's message stream, COMMAND_ACK on the command call's own: a HEARTBEAT sent
# before an accepted mode change or arm/disarm can reach preland after that command's ACK (a backlog of the
# message stream on a loaded machine holds seconds of vehicle time at 20x). The message stream carries the
# COMMAND_ACK too, in the order the vehicle sent it: a HEARTBEAT read after it there was sent after the change.
# So the commanded state stands until a HEARTBEAT reports it or one is read after its ACK on the stream. Where
# the stream shows no COMMAND_ACK at all, it stands for COMMANDED_STATE_GRACE_S vehicle seconds after the ACK
# (heartbeats come at 1 to 10 Hz, so any later one was sent after the change); and an ACK the stream never
# shows is waited for COMMANDED_STATE_LIMIT_S at most.
COMMANDED_STATE_GRACE_S = 5.0
COMMANDED_STATE_LIMIT_S = 30.0


def heartbeat_mode(fields: dict[str, Any]) -> FlightMode:
    try:
        return FlightMode(int(fields.get("custom_mode", 0)))
    except ValueError:
        return FlightMode.STABILIZE


def heartbeat_armed(fields: dict[str, Any]) -> bool:
    return bool(int(fields.get("base_mode", 0)) & 128)  # MAV_MODE_FLAG_SAFETY_ARMED


@dataclass(slots=True)
class Commanded:
    """An accepted arm/disarm or mode change, until a HEARTBEAT confirms it."""

    value: Any
    acked_at_s: float  # vehicle time of the COMMAND_ACK
    ack: tuple[int, int] | None = None  # (MAV_CMD, its n-th ACK on this link), to find it on the message stream
    confirmed: bool = False

    def confirm(self, heartbeat_value: Any) -> None:
        """Note a HEARTBEAT's value: once one reports the commanded value, HEARTBEATs alone tell."""
        self.confirmed = self.confirmed or heartbeat_value == self.value

    def reported(self, heartbeat_value: Any, heard_s: float, heartbeats_after_ack: int | None) -> Any:
        """What the vehicle is taken to be in, given the newest HEARTBEAT's `heartbeat_value`, sent at vehicle
        time `heard_s`; `heartbeats_after_ack`: HEARTBEATs read after this command's ACK on the message
        stream, or None where the stream shows no ACKs."""
        if self.confirmed:
            return heartbeat_value
        elapsed_s = heard_s - self.acked_at_s
        if heartbeats_after_ack is None:
            after = elapsed_s >= COMMANDED_STATE_GRACE_S
        else:
            after = heartbeats_after_ack > 0 or elapsed_s >= COMMANDED_STATE_LIMIT_S
        return heartbeat_value if after else self.value

"""The Vehicle protocol: everything mission and landing logic may ask of a drone.

It is deliberately small, and every backend implements all of it: the embedded
simulator (`vehicle.sim_backend`), the MAVLink backend (ArduPilot SITL and real
drones), and the in-package fake for unit tests (`vehicle.fake`).

Commands return once the autopilot has accepted them (like a MAVLink
COMMAND_ACK) and raise `CommandDenied` when it refuses; they do not wait for the
manoeuvre to finish. Waiting is the caller's job, through the vehicle clock and
a timeout (see `clock.wait_until`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from ..clock import Clock
from ..errors import CommandDenied
from .types import FlightMode, LandingTarget, PositionNed, Telemetry, VelocityNed


@runtime_checkable
class Vehicle(Protocol):
    """An ArduCopter-like multirotor, as seen from a companion computer."""

    @property
    def clock(self) -> Clock:
        """The vehicle's clock: mission timers run on it."""
        ...

    async def connect(self) -> None:
        """Open the link (or start the simulated vehicle)."""
        ...

    async def close(self) -> None:
        """Close the link; further commands fail."""
        ...

    async def arm(self) -> None:
        """Arm the motors. Refused without a position estimate."""
        ...

    async def disarm(self) -> None:
        """Disarm the motors (refused in flight: use LAND)."""
        ...

    async def takeoff(self, *, altitude_rel_m: float) -> None:
        """Start a GUIDED take-off to `altitude_rel_m` above home."""
        ...

    async def goto_ned(self, *, position_ned_m: PositionNed, yaw_deg: float | None = None) -> None:
        """GUIDED: fly to a position in metres NED relative to home."""
        ...

    async def goto_global(
        self, *, latitude_deg: float, longitude_deg: float, altitude_rel_m: float
    ) -> None:
        """GUIDED: fly to a WGS-84 position, altitude relative to home in m."""
        ...

    async def set_velocity_ned(
        self, *, velocity_ned_m_s: VelocityNed, yaw_deg: float | None = None
    ) -> None:
        """GUIDED: hold a velocity in m/s, NED (stops after ArduCopter's 3 s guided timeout)."""
        ...

    async def set_velocity_body(
        self,
        *,
        forward_m_s: float,
        right_m_s: float,
        down_m_s: float,
        yaw_rate_deg_s: float = 0.0,
    ) -> None:
        """GUIDED: hold a velocity in m/s in the body frame (FRD, yaw-rotated)."""
        ...

    async def hold(self) -> None:
        """GUIDED: stop and hold the current position."""
        ...

    async def set_mode(self, mode: FlightMode) -> None:
        """Change flight mode (GUIDED, LOITER, LAND, RTL)."""
        ...

    async def get_param(self, name: str) -> float:
        """Read an autopilot parameter by its ArduPilot name (ArduPilot units)."""
        ...

    async def set_param(self, name: str, value: float) -> None:
        """Write an autopilot parameter by its ArduPilot name (ArduPilot units)."""
        ...

    async def telemetry(self) -> Telemetry:
        """The latest telemetry snapshot."""
        ...

    async def send_landing_target(self, target: LandingTarget) -> None:
        """Send one landing-target measurement (the content of LANDING_TARGET)."""
        ...


ARM_RETRY_PERIOD_S = 1.0  # vehicle seconds between tries while the autopilot refuses to arm


async def arm_when_allowed(vehicle: Vehicle, *, timeout_s: float) -> None:
    """Arm, trying again every ARM_RETRY_PERIOD_S while the autopilot refuses (its checks may pass a moment
    later); the last CommandDenied after `timeout_s` vehicle seconds."""
    deadline_s = vehicle.clock.now_s() + timeout_s
    while True:
        try:
            await vehicle.arm()
            return
        except CommandDenied:
            if vehicle.clock.now_s() >= deadline_s:
                raise
            await vehicle.clock.sleep(ARM_RETRY_PERIOD_S)

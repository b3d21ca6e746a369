"""An in-package fake vehicle for unit tests: kinematic, scriptable, and it records every call.

It moves in straight lines at fixed speeds (no wind, no estimate error), so a
test can check mission logic (steps, timeouts, retries, refusals) in
milliseconds. Make it refuse commands with `deny`, or cut it off with
`fail_after_s`. Like any backend, it runs on the clock it is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..clock import Clock
from ..errors import CommandDenied, LinkLost
from .types import (
    Attitude,
    Battery,
    FlightMode,
    GlobalPosition,
    LandedState,
    LandingTarget,
    PositionNed,
    Telemetry,
    VelocityNed,
)


@dataclass
class FakeCall:
    time_s: float
    operation: str
    arguments: dict = field(default_factory=dict)


class FakeVehicle:
    """A kinematic stand-in for a drone. Positions NED in m from home."""

    def __init__(
        self,
        *,
        clock: Clock,
        speed_m_s: float = 3.0,
        climb_rate_m_s: float = 2.0,
        descent_rate_m_s: float = 1.0,
        position_ok_after_s: float = 0.0,
        deny: dict[str, str] | None = None,
        deny_count: dict[str, int] | None = None,
        fail_after_s: float | None = None,
    ) -> None:
        self._clock = clock
        self.speed_m_s = speed_m_s
        self.climb_rate_m_s = climb_rate_m_s
        self.descent_rate_m_s = descent_rate_m_s
        self.position_ok_after_s = position_ok_after_s
        self.deny = dict(deny or {})
        self.deny_count = dict(deny_count or {})
        self.fail_after_s = fail_after_s
        self.calls: list[FakeCall] = []
        self.landing_targets: list[LandingTarget] = []
        self.params: dict[str, float] = {"LAND_SPEED": 50.0, "PLND_ENABLED": 0.0}
        self.connected = False
        self.armed = False
        self.mode = FlightMode.STABILIZE
        self.north_m = self.east_m = self.down_m = 0.0
        self._target: tuple[float, float, float] | None = None
        self._velocity: tuple[float, float, float] | None = None
        self._last_s = 0.0

    @property
    def clock(self) -> Clock:
        return self._clock

    # ------------------------------------------------------------------ internals

    def _record(self, operation: str, **arguments) -> None:
        now = self._clock.now_s()
        if self.fail_after_s is not None and now >= self.fail_after_s:
            raise LinkLost(operation=operation, reason="fake link cut")
        self.calls.append(FakeCall(now, operation, arguments))
        remaining = self.deny_count.get(operation)
        if remaining:
            self.deny_count[operation] = remaining - 1
            raise CommandDenied(operation=operation, reason=self.deny.get(operation, "denied by the fake"))
        if operation in self.deny and remaining is None:
            raise CommandDenied(operation=operation, reason=self.deny[operation])

    def _advance(self) -> None:
        now = self._clock.now_s()
        dt = now - self._last_s
        self._last_s = now
        if not self.armed or dt <= 0:
            return
        if self.mode is FlightMode.LAND:
            self.down_m = min(0.0, self.down_m + self.descent_rate_m_s * dt)
            if self.down_m >= 0.0:
                self.armed = False
            return
        if self._velocity is not None:
            self.north_m += self._velocity[0] * dt
            self.east_m += self._velocity[1] * dt
            self.down_m = min(0.0, self.down_m + self._velocity[2] * dt)
            return
        if self._target is None:
            return
        tn, te, td = self._target
        dn, de = tn - self.north_m, te - self.east_m
        distance = math.hypot(dn, de)
        step = min(distance, self.speed_m_s * dt)
        if distance > 0:
            self.north_m += dn / distance * step
            self.east_m += de / distance * step
        dz = td - self.down_m
        rate = self.descent_rate_m_s if dz > 0 else self.climb_rate_m_s
        self.down_m += math.copysign(min(abs(dz), rate * dt), dz)

    # ------------------------------------------------------------------ the protocol

    async def connect(self) -> None:
        self._record("connect")
        self.connected = True
        self._last_s = self._clock.now_s()

    async def close(self) -> None:
        self.calls.append(FakeCall(self._clock.now_s(), "close"))
        self.connected = False

    async def arm(self) -> None:
        self._advance()
        self._record("arm")
        if self._clock.now_s() < self.position_ok_after_s:
            raise CommandDenied(operation="arm", reason="PreArm: Need Position Estimate")
        self.armed = True

    async def disarm(self) -> None:
        self._advance()
        self._record("disarm")
        if self.down_m < -0.05:
            raise CommandDenied(operation="disarm", reason="vehicle is flying (use LAND)")
        self.armed = False

    async def takeoff(self, *, altitude_rel_m: float) -> None:
        self._advance()
        self._record("takeoff", altitude_rel_m=altitude_rel_m)
        if not self.armed:
            raise CommandDenied(operation="takeoff", reason="vehicle is not armed")
        self._velocity = None
        self._target = (self.north_m, self.east_m, -altitude_rel_m)

    async def goto_ned(self, *, position_ned_m: PositionNed, yaw_deg: float | None = None) -> None:
        self._advance()
        self._record("goto_ned", north_m=position_ned_m.north_m, east_m=position_ned_m.east_m,
                     down_m=position_ned_m.down_m)
        self._velocity = None
        self._target = (position_ned_m.north_m, position_ned_m.east_m, position_ned_m.down_m)

    async def goto_global(self, *, latitude_deg: float, longitude_deg: float, altitude_rel_m: float) -> None:
        self._advance()
        self._record("goto_global", latitude_deg=latitude_deg, longitude_deg=longitude_deg,
                     altitude_rel_m=altitude_rel_m)

    async def set_velocity_ned(self, *, velocity_ned_m_s: VelocityNed, yaw_deg: float | None = None) -> None:
        self._advance()
        self._record("set_velocity_ned", north_m_s=velocity_ned_m_s.north_m_s, east_m_s=velocity_ned_m_s.east_m_s,
                     down_m_s=velocity_ned_m_s.down_m_s)
        self._velocity = (velocity_ned_m_s.north_m_s, velocity_ned_m_s.east_m_s, velocity_ned_m_s.down_m_s)

    async def set_velocity_body(self, *, forward_m_s: float, right_m_s: float, down_m_s: float,
                                yaw_rate_deg_s: float = 0.0) -> None:
        self._advance()
        self._record("set_velocity_body", forward_m_s=forward_m_s, right_m_s=right_m_s, down_m_s=down_m_s)
        # The fake always faces north, so body forward/right are north/east.
        self._velocity = (forward_m_s, right_m_s, down_m_s)

    async def hold(self) -> None:
        self._advance()
        self._record("hold")
        self._velocity = None
        self._target = (self.north_m, self.east_m, self.down_m)

    async def set_mode(self, mode: FlightMode) -> None:
        self._advance()
        self._record("set_mode", mode=mode.name)
        self.mode = mode

    async def get_param(self, name: str) -> float:
        self._record("get_param", name=name)
        if name not in self.params:
            raise CommandDenied(operation="get_param", reason=f"unknown parameter {name!r}")
        return self.params[name]

    async def set_param(self, name: str, value: float) -> None:
        self._record("set_param", name=name, value=value)
        self.params[name] = float(value)

    async def telemetry(self) -> Telemetry:
        self._advance()
        now = self._clock.now_s()
        if self.fail_after_s is not None and now >= self.fail_after_s:
            raise LinkLost(operation="telemetry", reason="fake link cut")
        on_ground = self.down_m >= -0.05
        if not self.armed or on_ground and self._target is None:
            landed = LandedState.ON_GROUND
        elif self.mode is FlightMode.LAND:
            landed = LandedState.LANDING
        else:
            landed = LandedState.IN_AIR
        return Telemetry(
            time_s=now,
            armed=self.armed,
            mode=self.mode,
            landed_state=landed,
            position_ok=now >= self.position_ok_after_s,
            position_ned_m=PositionNed(self.north_m, self.east_m, self.down_m),
            velocity_ned_m_s=VelocityNed(0.0, 0.0, 0.0),
            global_position=GlobalPosition(0.0, 0.0, -self.down_m, -self.down_m),
            home=GlobalPosition(0.0, 0.0, 0.0, 0.0),
            attitude=Attitude(0.0, 0.0, 0.0),
            height_above_ground_m=-self.down_m,
            rangefinder_valid=-self.down_m < 10.0,
            battery=Battery(16.0, 90.0),
        )

    async def send_landing_target(self, target: LandingTarget) -> None:
        self._record("send_landing_target")
        self.landing_targets.append(target)

    def operations(self) -> list[str]:
        """The names of the calls made so far, in order."""
        return [call.operation for call in self.calls]

"""The Vehicle protocol for the embedded simulator (in-process, no link)."""

from __future__ import annotations

import asyncio
import math

from ..clock import Clock
from ..errors import CommandDenied, VehicleError
from ..geo import GeoPoint, LocalTangentPlane
from ..sim.simulator import Simulator
from .types import (
    Attitude,
    Battery,
    FlightMode,
    GlobalPosition,
    LandingTarget,
    PositionNed,
    Telemetry,
    VelocityNed,
)


class SimVehicle:
    """Drives a `Simulator` through the Vehicle protocol. `connect()` powers it on."""

    def __init__(self, *, simulator: Simulator, clock: Clock) -> None:
        self.simulator = simulator
        self._clock = clock
        self._task: asyncio.Task[None] | None = None
        self._closed = False
        self._plane = LocalTangentPlane(simulator.origin)

    @property
    def clock(self) -> Clock:
        return self._clock

    def _check(self, operation: str) -> None:
        if self._task is None or self._closed:
            raise VehicleError(operation=operation, reason="not connected")
        if self._task.done():
            error = self._task.exception() if not self._task.cancelled() else None
            raise VehicleError(operation=operation, reason=f"simulator stopped: {error!r}")

    async def connect(self) -> None:
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self.simulator.run(self._clock), name="simulator")
        self._closed = False

    async def close(self) -> None:
        self._closed = True
        if self._task is not None:
            self._task.cancel()
            try:
                await self._task
            except asyncio.CancelledError:
                pass
            self._task = None

    async def arm(self) -> None:
        self._check("arm")
        self.simulator.autopilot.arm()

    async def disarm(self) -> None:
        self._check("disarm")
        self.simulator.autopilot.disarm()

    async def takeoff(self, *, altitude_rel_m: float) -> None:
        self._check("takeoff")
        self.simulator.autopilot.takeoff(altitude_rel_m=altitude_rel_m)

    async def goto_ned(self, *, position_ned_m: PositionNed, yaw_deg: float | None = None) -> None:
        self._check("goto_ned")
        self.simulator.autopilot.goto(
            north_m=position_ned_m.north_m,
            east_m=position_ned_m.east_m,
            down_m=position_ned_m.down_m,
            yaw_rad=math.radians(yaw_deg) if yaw_deg is not None else None,
        )

    async def goto_global(self, *, latitude_deg: float, longitude_deg: float, altitude_rel_m: float) -> None:
        self._check("goto_global")
        autopilot = self.simulator.autopilot
        north, east, _ = self._plane.to_ned(GeoPoint(latitude_deg, longitude_deg, self.simulator.origin.altitude_amsl_m))
        autopilot.goto(north_m=north - autopilot.home_north_m, east_m=east - autopilot.home_east_m,
                       down_m=-altitude_rel_m, yaw_rad=None)

    async def set_velocity_ned(self, *, velocity_ned_m_s: VelocityNed, yaw_deg: float | None = None) -> None:
        self._check("set_velocity_ned")
        self.simulator.autopilot.set_velocity(
            north_m_s=velocity_ned_m_s.north_m_s,
            east_m_s=velocity_ned_m_s.east_m_s,
            down_m_s=velocity_ned_m_s.down_m_s,
            yaw_rad=math.radians(yaw_deg) if yaw_deg is not None else None,
        )

    async def set_velocity_body(self, *, forward_m_s: float, right_m_s: float, down_m_s: float,
                                yaw_rate_deg_s: float = 0.0) -> None:
        self._check("set_velocity_body")
        yaw = self.simulator.autopilot.yaw_rad
        north = forward_m_s * math.cos(yaw) - right_m_s * math.sin(yaw)
        east = forward_m_s * math.sin(yaw) + right_m_s * math.cos(yaw)
        self.simulator.autopilot.set_velocity(north_m_s=north, east_m_s=east, down_m_s=down_m_s, yaw_rad=None,
                                              yaw_rate_rad_s=math.radians(yaw_rate_deg_s))

    async def hold(self) -> None:
        self._check("hold")
        self.simulator.autopilot.hold()

    async def set_mode(self, mode: FlightMode) -> None:
        self._check("set_mode")
        self.simulator.autopilot.set_mode(mode)

    async def get_param(self, name: str) -> float:
        self._check("get_param")
        try:
            return self.simulator.params.get(name)
        except KeyError as error:
            raise CommandDenied(operation="get_param", reason=str(error.args[0])) from None

    async def set_param(self, name: str, value: float) -> None:
        self._check("set_param")
        try:
            self.simulator.params.set(name, value)
        except (KeyError, ValueError) as error:
            raise CommandDenied(operation="set_param", reason=str(error.args[0])) from None

    async def telemetry(self) -> Telemetry:
        self._check("telemetry")
        sim = self.simulator
        autopilot = sim.autopilot
        nav = sim.nav
        body = sim.dynamics.state
        here = self._plane.to_geodetic(north_m=nav.north_m, east_m=nav.east_m, down_m=nav.down_m)
        home = self._plane.to_geodetic(north_m=autopilot.home_north_m, east_m=autopilot.home_east_m,
                                       down_m=autopilot.home_down_m)
        altitude_rel_m = -(nav.down_m - autopilot.home_down_m)
        return Telemetry(
            time_s=sim.time_s,
            armed=autopilot.armed,
            mode=autopilot.mode,
            landed_state=autopilot.landed_state(),
            position_ok=nav.position_ok,
            position_ned_m=PositionNed(nav.north_m - autopilot.home_north_m, nav.east_m - autopilot.home_east_m,
                                       nav.down_m - autopilot.home_down_m),
            velocity_ned_m_s=VelocityNed(nav.velocity_north_m_s, nav.velocity_east_m_s, nav.velocity_down_m_s),
            global_position=GlobalPosition(here.latitude_deg, here.longitude_deg, here.altitude_amsl_m,
                                           altitude_rel_m),
            home=GlobalPosition(home.latitude_deg, home.longitude_deg, home.altitude_amsl_m, 0.0),
            attitude=Attitude(math.degrees(body.roll_rad), math.degrees(body.pitch_rad),
                              math.degrees(body.yaw_rad) % 360.0),
            height_above_ground_m=autopilot.height_above_ground_m(),
            rangefinder_valid=autopilot.rangefinder_alt_ok(),
            battery=Battery(sim.battery_voltage_v(), 100.0 * sim.battery_remaining_fraction()),
        )

    async def send_landing_target(self, target: LandingTarget) -> None:
        self._check("send_landing_target")
        self.simulator.autopilot.receive_landing_target(target)

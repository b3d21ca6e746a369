"""Between two field trials: bring the vehicle back to where the campaign started.

`reposition` hops: GUIDED, arm, take off to a low height, fly to the start by
GPS (SET_POSITION_TARGET_GLOBAL_INT), LAND, wait for the disarm. Each step
has the mission's timeout; a start farther than the mission's geofence allows
is refused before take-off. It lands with the autopilot's LAND, so it is as
accurate as the vehicle's position (1 to 2 m with GPS, centimetres with RTK;
with PLND_ENABLED and the beacon in view, ArduPilot's LAND lands on it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..clock import wait_until
from ..config.mission import MissionSpec
from ..errors import MissionAborted
from ..geo import GeoPoint, LocalTangentPlane
from ..vehicle.protocol import Vehicle, arm_when_allowed
from ..vehicle.types import FlightMode, Telemetry

POLL_PERIOD_S = 0.1
ARRIVED_SPEED_M_S = 0.3  # settled over the start before LAND: a landing that starts drifting ends off it


@dataclass(frozen=True, kw_only=True)
class Hop:
    """What a reposition did: the distances from the start (m, horizontal, by the vehicle's GPS) before it
    and after it landed; `flown` False when the vehicle was already within the tolerance."""

    before_m: float
    after_m: float
    flown: bool


def distance_from_m(telemetry: Telemetry, start: GeoPoint) -> float:
    """Horizontal distance (m) of the vehicle's reported position from `start`."""
    position = telemetry.global_position
    north_m, east_m, _ = LocalTangentPlane(start).to_ned(
        GeoPoint(position.latitude_deg, position.longitude_deg, start.altitude_amsl_m))
    return math.hypot(north_m, east_m)


def _located(telemetry: Telemetry) -> bool:
    # Until GLOBAL_POSITION_INT arrives the position reads 0, 0: a point in the Gulf of Guinea, not the field.
    position = telemetry.global_position
    return telemetry.position_ok and (position.latitude_deg != 0.0 or position.longitude_deg != 0.0)


async def located(vehicle: Vehicle, *, timeout_s: float) -> Telemetry:
    """The vehicle's telemetry once it reports a 3D fix and a position (WaitTimeout after `timeout_s`
    vehicle seconds)."""
    found: list[Telemetry] = []

    async def known() -> bool:
        found.append(await vehicle.telemetry())
        return _located(found[-1])

    await wait_until(known, clock=vehicle.clock, timeout_s=timeout_s, operation="wait for a position",
                     poll_period_s=POLL_PERIOD_S)
    return found[-1]


async def reposition(*, vehicle: Vehicle, start: GeoPoint, mission: MissionSpec, altitude_m: float,
                     tolerance_m: float) -> Hop:
    """Fly the landed, disarmed vehicle back to `start` (its horizontal position) at `altitude_m` above its
    home and land there; nothing when it is within `tolerance_m` already. Raises WaitTimeout naming the
    step that ran out of time, MissionAborted for a start outside the mission's geofence."""
    clock, timeouts = vehicle.clock, mission.timeouts
    telemetry = await located(vehicle, timeout_s=timeouts.position_fix_s)
    before_m = distance_from_m(telemetry, start)
    if before_m <= tolerance_m:
        return Hop(before_m=before_m, after_m=before_m, flown=False)
    fence = mission.geofence
    if fence is not None and (before_m > fence.max_distance_m or altitude_m > fence.max_height_m):
        raise MissionAborted(f"reposition: the start is {before_m:.1f} m away at {altitude_m:g} m, outside the "
                             f"mission's geofence ({fence.max_distance_m:g} m, {fence.max_height_m:g} m)")

    async def describe() -> str:
        t = await vehicle.telemetry()
        return (f"mode {t.mode.name}, {t.landed_state.name}, {distance_from_m(t, start):.2f} m from the start, "
                f"altitude {t.altitude_rel_m:.2f} m")

    await vehicle.set_mode(FlightMode.GUIDED)
    await arm_when_allowed(vehicle, timeout_s=timeouts.arm_s)
    await vehicle.takeoff(altitude_rel_m=altitude_m)

    async def at_altitude() -> bool:
        return (await vehicle.telemetry()).altitude_rel_m >= 0.9 * altitude_m

    await wait_until(at_altitude, clock=clock, timeout_s=timeouts.takeoff_s, operation="reposition: take-off",
                     poll_period_s=POLL_PERIOD_S, describe=describe)
    await vehicle.goto_global(latitude_deg=start.latitude_deg, longitude_deg=start.longitude_deg,
                              altitude_rel_m=altitude_m)

    async def over_start() -> bool:
        t = await vehicle.telemetry()
        return distance_from_m(t, start) <= tolerance_m and t.velocity_ned_m_s.horizontal_m_s <= ARRIVED_SPEED_M_S

    await wait_until(over_start, clock=clock, timeout_s=timeouts.waypoint_s, operation="reposition: fly to the start",
                     poll_period_s=POLL_PERIOD_S, describe=describe)
    await vehicle.set_mode(FlightMode.LAND)

    async def disarmed() -> bool:
        return not (await vehicle.telemetry()).armed

    await wait_until(disarmed, clock=clock, timeout_s=timeouts.land_s, operation="reposition: land",
                     poll_period_s=POLL_PERIOD_S, describe=describe)
    return Hop(before_m=before_m, after_m=distance_from_m(await vehicle.telemetry(), start), flown=True)

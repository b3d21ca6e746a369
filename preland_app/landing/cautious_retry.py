"""The thesis' cautious landing (Section 6.2, Figure 11), run by the companion computer.

The autopilot lands in LAND with its precision landing; ArduPilot's own retry
(PLND_STRICT, PLND_RET_MAX, ...) stays configured. Where the thesis differs, the
companion steps in through the Vehicle protocol, so it behaves the same on
ArduPilot, SITL and the embedded simulator:

1. the target is lost (no new sensor value for `lost_after_s`) while the
   rangefinder height is within PLND_ALT_MIN..PLND_ALT_MAX: switch to GUIDED and
   hold (ArduPilot would keep descending) for PLND_TIMEOUT, watching the sensor;
   the target back: LAND again;
2. still nothing: a new attempt starts (at most PLND_RET_MAX of them): go back to
   where the vehicle was when it last saw the target, 1.5 m higher as ArduPilot's
   retry does (RETRY_OFFSET_ALT_M), and wait PLND_TIMEOUT there;
3. still nothing: climb to `retry_height_m` above home over that point and wait
   PLND_TIMEOUT; the target seen at any point: LAND again;
4. retries spent: hover `failsafe_hold_s`, then LAND without the target
   (PLND_STRICT 2: hover until the target comes back, or the land timeout).

Positions are NED in m relative to home, from telemetry (the autopilot's estimate).
"""

from __future__ import annotations

import enum
import math

from ..clock import Clock
from ..events import EventLog
from ..vehicle.protocol import Vehicle
from ..vehicle.types import FlightMode, PositionNed, Telemetry
from .cautious import CautiousSpec

ARRIVED_M = 0.75  # as ArduPilot's retry (AC_PrecLand_StateMachine MAX_POS_ERROR_M)
RETRY_OFFSET_ALT_M = 1.5  # as ArduPilot's retry: added to the height where the target was last seen
MOVE_TIMEOUT_S = 30.0  # a leg of the retry that has not arrived by then is given up


class RetryPhase(enum.Enum):
    TRACKING = "tracking"  # LAND, target in sight (or never seen in this attempt)
    PAUSED = "paused"  # target lost: holding (GUIDED) and watching
    RETURNING = "returning"  # new attempt: flying back to where the target was last seen
    AT_LAST_SEEN = "at_last_seen"
    CLIMBING = "climbing"  # to the default height
    AT_DEFAULT = "at_default"
    FAILSAFE = "failsafe"  # retries spent: hovering before the blind descent (or for good, PLND_STRICT 2)
    BLIND = "blind"  # LAND without the target; the companion no longer steps in


class CompanionRetry:
    """The cautious sequence; `note_target()` on every value sent to the autopilot, `step()` each cycle."""

    def __init__(self, *, spec: CautiousSpec, vehicle: Vehicle, clock: Clock, events: EventLog) -> None:
        self.spec = spec
        self.vehicle = vehicle
        self.clock = clock
        self.events = events
        self.phase = RetryPhase.TRACKING
        self.attempt = 1
        self.retries = 0
        self.pauses = 0
        self._phase_since_s = 0.0
        self._last_target_s: float | None = None
        self._seen_in_land = False
        self._last_seen_ned_m: PositionNed | None = None
        self._position_ned_m: PositionNed | None = None
        self._goal_ned_m: PositionNed | None = None

    # ------------------------------------------------------------------ inputs

    def note_target(self) -> None:
        """A new target value reached the autopilot now."""
        self._last_target_s = self.clock.now_s()
        if self.phase is RetryPhase.TRACKING:
            self._seen_in_land = True
            self._last_seen_ned_m = self._position_ned_m

    def _seen_since(self, since_s: float) -> bool:
        return self._last_target_s is not None and self._last_target_s >= since_s

    # ------------------------------------------------------------------ the sequence

    async def step(self, telemetry: Telemetry) -> None:
        """One control cycle; commands the vehicle when the phase changes."""
        now_s = self.clock.now_s()
        self._position_ned_m = telemetry.position_ned_m
        phase, spec = self.phase, self.spec
        if phase is RetryPhase.TRACKING:
            lost = (self._seen_in_land and self._last_target_s is not None
                    and now_s - self._last_target_s > spec.lost_after_s)
            if spec.PLND_STRICT != 0 and telemetry.mode is FlightMode.LAND and lost and self._in_range(telemetry):
                self.pauses += 1
                self._enter(RetryPhase.PAUSED, now_s, "target lost: holding and watching the sensor",
                            altitude_rel_m=round(telemetry.altitude_rel_m, 2))
                await self.vehicle.set_mode(FlightMode.GUIDED)
                if spec.hold_while_waiting:
                    await self.vehicle.goto_ned(position_ned_m=telemetry.position_ned_m)
            return
        if phase is RetryPhase.BLIND:
            return
        if self._seen_since(self._phase_since_s) and phase is not RetryPhase.RETURNING \
                and phase is not RetryPhase.CLIMBING:
            await self._land(now_s, "target in sight: landing")
            return
        waited_s = now_s - self._phase_since_s
        if phase is RetryPhase.PAUSED:
            if waited_s >= spec.PLND_TIMEOUT:
                await self._retry_or_give_up(now_s, telemetry)
        elif phase in (RetryPhase.RETURNING, RetryPhase.CLIMBING):
            if _distance_m(telemetry.position_ned_m, self._goal_ned_m) < ARRIVED_M or waited_s > MOVE_TIMEOUT_S:
                arrived = RetryPhase.AT_LAST_SEEN if phase is RetryPhase.RETURNING else RetryPhase.AT_DEFAULT
                self._enter(arrived, now_s, None)
        elif phase is RetryPhase.AT_LAST_SEEN:
            if waited_s >= spec.PLND_TIMEOUT:
                if spec.retry_height_m > 0 and -self._goal_ned_m.down_m < spec.retry_height_m - ARRIVED_M:
                    goal = self._goal_ned_m
                    await self._go(PositionNed(goal.north_m, goal.east_m, -spec.retry_height_m), now_s,
                                   RetryPhase.CLIMBING, f"going up to the default height {spec.retry_height_m:g} m")
                else:
                    await self._retry_or_give_up(now_s, telemetry)
        elif phase is RetryPhase.AT_DEFAULT:
            if waited_s >= spec.PLND_TIMEOUT:
                await self._retry_or_give_up(now_s, telemetry)
        elif phase is RetryPhase.FAILSAFE:
            if spec.PLND_STRICT != 2 and waited_s >= spec.failsafe_hold_s:
                self._enter(RetryPhase.BLIND, now_s, "descending without the target")
                await self.vehicle.set_mode(FlightMode.LAND)

    async def _retry_or_give_up(self, now_s: float, telemetry: Telemetry) -> None:
        if self.retries >= self.spec.PLND_RET_MAX:
            self._enter(RetryPhase.FAILSAFE, now_s, f"retries spent ({self.retries})")
            await self.vehicle.goto_ned(position_ned_m=telemetry.position_ned_m)
            return
        self.retries += 1
        self.attempt += 1
        seen = self._last_seen_ned_m or telemetry.position_ned_m
        goal = PositionNed(seen.north_m, seen.east_m, seen.down_m - RETRY_OFFSET_ALT_M)
        self.events.add("attempt", f"landing attempt {self.attempt} started",
                        attempt=self.attempt, altitude_rel_m=round(telemetry.altitude_rel_m, 2))
        await self._go(goal, now_s, RetryPhase.RETURNING, "going back to where the target was last seen")

    async def _go(self, goal: PositionNed, now_s: float, phase: RetryPhase, message: str) -> None:
        self._goal_ned_m = goal
        self._enter(phase, now_s, message, north_m=round(goal.north_m, 2), east_m=round(goal.east_m, 2),
                    altitude_rel_m=round(-goal.down_m, 2))
        await self.vehicle.goto_ned(position_ned_m=goal)

    async def _land(self, now_s: float, message: str) -> None:
        self._seen_in_land = True
        self._enter(RetryPhase.TRACKING, now_s, message)
        await self.vehicle.set_mode(FlightMode.LAND)

    def _enter(self, phase: RetryPhase, now_s: float, message: str | None, **data) -> None:
        self.phase = phase
        self._phase_since_s = now_s
        if message:
            self.events.add("cautious", message, phase=phase.value, attempt=self.attempt, **data)

    def _in_range(self, telemetry: Telemetry) -> bool:
        """As AC_PrecLand::check_if_sensor_in_range: no bounds (both 0) always; else a valid rangefinder
        height within them."""
        alt_min, alt_max = self.spec.PLND_ALT_MIN, self.spec.PLND_ALT_MAX
        if alt_min == 0 and alt_max == 0:
            return True
        if not telemetry.rangefinder_valid:
            return False
        height_m = telemetry.height_above_ground_m
        return not (alt_max > 0 and height_m > alt_max) and not (alt_min > 0 and height_m < alt_min)


def _distance_m(a: PositionNed, b: PositionNed) -> float:
    return math.dist((a.north_m, a.east_m, a.down_m), (b.north_m, b.east_m, b.down_m))

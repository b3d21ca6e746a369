"""What LAND does when the precision-landing target is lost: ArduPilot's retry state machine
(AC_PrecLand_StateMachine) and the thesis' cautious landing (Section 6.2), in one.

Parameters (ArduPilot names): PLND_STRICT (0 land vertically, 1 retry, 2 hover),
PLND_RET_MAX (retries), PLND_TIMEOUT (s to wait for the target before retrying),
PLND_RET_BEHAVE (0: go back to where the vehicle was when it last saw the target,
1: go above the target's last estimated position), PLND_ALT_MIN / PLND_ALT_MAX
(no retries below / above these rangefinder heights). The retry position is
1.5 m above the last detection (ArduPilot's RETRY_OFFSET_ALT_M).

The thesis' cautious variant (hold while waiting, a default retry height) is
not the autopilot's: the cautious land mode does it from the companion
(`landing/cautious_retry.py`), as it must on a real ArduPilot.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

from .params import ParameterTable

RETRY_OFFSET_ALT_M = 1.5  # AC_PrecLand_StateMachine
MAX_POS_ERROR_M = 0.75  # AC_PrecLand_StateMachine
FAILSAFE_INIT_TIMEOUT_S = 7.0  # AC_PrecLand_StateMachine: hover before the failsafe's blind descent


class RetryState(enum.Enum):
    TRACKING = "tracking"  # target in sight (or never lost): normal precision descent
    WAITING = "waiting"  # target lost: hold or descend for PLND_TIMEOUT
    RETRY_CLIMB = "retry_climb"  # going back to where the target was last seen
    RETRY_SETTLE = "retry_settle"  # ArduPilot: descending back to the detection height
    FAILSAFE_HOLD = "failsafe_hold"
    BLIND = "blind"  # retries spent: descend vertically


class Action(enum.Enum):
    DESCEND = "descend"  # LAND as usual (with the target when there is one)
    HOLD = "hold"  # stop and hold position and altitude
    GOTO = "goto"  # fly to `target`


@dataclass(frozen=True, slots=True)
class Directive:
    action: Action
    north_m: float = 0.0
    east_m: float = 0.0
    down_m: float = 0.0


class LandingRetry:
    """Decides, each control cycle in LAND with precision landing, whether to descend, hold or retry.

    Positions are NED in m in the autopilot's (estimated) frame.
    """

    def __init__(self, params: ParameterTable) -> None:
        self.params = params
        self.messages: list[str] = []
        self.reset()

    def reset(self) -> None:
        """A new LAND: no retries yet (ArduPilot resets its counter on each mode change)."""
        self.state = RetryState.TRACKING
        self.retries = 0
        self._seen_once = False
        self._last_seen_vehicle: tuple[float, float, float] | None = None
        self._last_seen_target: tuple[float, float] | None = None
        self._lost_since_s = 0.0
        self._state_since_s = 0.0
        self._hold_at: tuple[float, float, float] | None = None

    def _enter(self, state: RetryState, now_s: float, message: str | None = None) -> None:
        self.state = state
        self._state_since_s = now_s
        if message:
            self.messages.append(message)

    def note_target(self, *, vehicle_ned_m: tuple[float, float, float], target_ne_m: tuple[float, float]) -> None:
        """The target is in sight: remember where it and the vehicle were."""
        self._seen_once = True
        self._last_seen_vehicle = vehicle_ned_m
        self._last_seen_target = target_ne_m

    def update(self, *, now_s: float, target_found: bool, vehicle_ned_m: tuple[float, float, float],
               height_m: float, rangefinder_valid: bool, home_down_m: float) -> Directive:
        p = self.params
        strict = int(p.value("PLND_STRICT"))
        state = self.state
        if target_found:
            if state is not RetryState.TRACKING and state is not RetryState.BLIND:
                self._enter(RetryState.TRACKING, now_s, "PrecLand: target back in sight")
            self._hold_at = None
            return Directive(Action.DESCEND)
        if strict == 0 or not self._seen_once:
            return Directive(Action.DESCEND)
        if state is RetryState.BLIND:
            return Directive(Action.DESCEND)
        if state is RetryState.TRACKING:
            if not self._in_range(height_m, rangefinder_valid):
                return Directive(Action.DESCEND)  # too high or too low for retries: keep descending
            self._lost_since_s = now_s
            self._hold_at = vehicle_ned_m
            self._enter(RetryState.WAITING, now_s, "PrecLand: target lost, waiting")
            state = self.state
        if state is RetryState.WAITING:
            if now_s - self._lost_since_s < p.value("PLND_TIMEOUT"):
                return Directive(Action.DESCEND)
            return self._start_retry(now_s, strict)
        if state is RetryState.RETRY_CLIMB:
            goal = self._retry_position()
            if _distance(vehicle_ned_m, goal) < MAX_POS_ERROR_M:
                self._enter(RetryState.RETRY_SETTLE, now_s)
            else:
                return Directive(Action.GOTO, *goal)
        if self.state is RetryState.RETRY_SETTLE:
            goal = self._retry_position()
            settle = (vehicle_ned_m[0], vehicle_ned_m[1], goal[2] + RETRY_OFFSET_ALT_M)
            if abs(vehicle_ned_m[2] - settle[2]) < MAX_POS_ERROR_M:
                self._enter(RetryState.FAILSAFE_HOLD, now_s, "PrecLand: retry completed, failsafe")
            else:
                return Directive(Action.GOTO, *settle)
        if self.state is RetryState.FAILSAFE_HOLD:
            if strict == 2:
                return Directive(Action.HOLD)
            if now_s - self._state_since_s >= FAILSAFE_INIT_TIMEOUT_S:
                self._enter(RetryState.BLIND, now_s, "PrecLand: descending without the target")
                return Directive(Action.DESCEND)
            return Directive(Action.HOLD)
        return Directive(Action.DESCEND)

    def _start_retry(self, now_s: float, strict: int) -> Directive:
        if self.retries >= self.params.value("PLND_RET_MAX"):
            self._enter(RetryState.FAILSAFE_HOLD, now_s, "PrecLand: retries spent, failsafe")
            return Directive(Action.HOLD)
        self.retries += 1
        self._enter(RetryState.RETRY_CLIMB, now_s, f"PrecLand: Retrying ({self.retries})")
        return Directive(Action.GOTO, *self._retry_position())

    def _retry_position(self) -> tuple[float, float, float]:
        vehicle = self._last_seen_vehicle or (0.0, 0.0, 0.0)
        if self.params.value("PLND_RET_BEHAVE") == 1 and self._last_seen_target is not None:
            north, east = self._last_seen_target
        else:
            north, east = vehicle[0], vehicle[1]
        return north, east, vehicle[2] - RETRY_OFFSET_ALT_M

    def _in_range(self, height_m: float, rangefinder_valid: bool) -> bool:
        """AC_PrecLand::check_if_sensor_in_range."""
        alt_min, alt_max = self.params.value("PLND_ALT_MIN"), self.params.value("PLND_ALT_MAX")
        if alt_min == 0 and alt_max == 0:
            return True
        if not rangefinder_valid:
            return False
        if alt_max > 0 and height_m > alt_max:
            return False
        return not (alt_min > 0 and height_m < alt_min)


def _distance(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    return math.sqrt((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2 + (a[2] - b[2]) ** 2)

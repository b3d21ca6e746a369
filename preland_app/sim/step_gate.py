"""Where a physics that owns time may step to, and who is told when its time passes a deadline.

A lock-step physics (the JSON bridge SITL flies on) steps whenever SITL asks. Another thread (the
companion's `LockstepClock`) can hold it at a vehicle time, so a camera frame or IR-LOCK reading is made
at that time and its LANDING_TARGET sent before the vehicle moves on, and can ask to be told when the
physics' time reaches a deadline. The physics calls `wait_to_step` before each step and `stepped` after.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

# A deadline is reached only at or after its time, never just before: a sleeper woken a rounding error
# early would compute the same tick again and sleep to it for ever (vehicle s). The price is at most one
# physics step past the deadline (the steps' float sum may fall just short of it).
REACHED_S = 0.0
_POLL_WALL_S = 0.05  # how often a held physics looks at its stop flag (wall s)


class StepGate:
    """The hold and the wake-up between a physics thread and a clock on another thread.

    `hold_at(t)`: the physics takes no step that starts at or after `t` (vehicle s; None: no hold).
    `wake_at(t, callback)`: `callback(time_s)` is called once, from the physics thread (or at once from
    the caller's, when `t` is already reached), when the physics' time reaches `t`.
    """

    def __init__(self) -> None:
        self._condition = threading.Condition()
        self._time_s = 0.0
        self._hold_at_s: float | None = None
        self._wake_at_s = math.inf
        self._on_wake: Callable[[float], None] | None = None
        self.holds = 0  # steps that had to wait for a hold to move
        self.held_wall_s = 0.0  # wall seconds the physics spent held
        self.waiting = False  # the physics thread stands at the hold now
        self.on_waiting: Callable[[], None] | None = None  # called from the physics thread as it starts to wait

    @property
    def time_s(self) -> float:
        """The physics' time (vehicle s) after its last step."""
        return self._time_s

    @property
    def hold_at_s(self) -> float | None:
        return self._hold_at_s

    # ---------------------------------------------------------------- the clock's side

    def hold_at(self, time_s: float | None) -> None:
        with self._condition:
            if time_s != self._hold_at_s:
                self._hold_at_s = time_s
                self._condition.notify_all()

    def wake_at(self, time_s: float, callback: Callable[[float], None]) -> None:
        with self._condition:
            now_s = self._time_s
            due = now_s >= time_s - REACHED_S
            self._wake_at_s, self._on_wake = (math.inf, None) if due else (time_s, callback)
        if due:
            callback(now_s)

    # ---------------------------------------------------------------- the physics' side

    def held(self) -> bool:
        hold = self._hold_at_s
        return hold is not None and self._time_s >= hold - REACHED_S

    def wait_to_step(self, *, stop: threading.Event) -> bool:
        """Return when the physics may take its next step, or when `stop` is set: True if it was held."""
        if not self.held():
            return False
        started_wall_s = time.monotonic()
        self.holds += 1
        with self._condition:
            self.waiting = True
            if self.on_waiting is not None:
                self.on_waiting()
            while self.held() and not stop.is_set():
                self._condition.wait(_POLL_WALL_S)
            self.waiting = False
        self.held_wall_s += time.monotonic() - started_wall_s
        return True

    def stepped(self, time_s: float) -> None:
        """The physics is now at `time_s` (vehicle s): tell whoever waits for a deadline it reached."""
        callback = None
        with self._condition:
            self._time_s = time_s
            if time_s >= self._wake_at_s - REACHED_S:
                callback, self._on_wake, self._wake_at_s = self._on_wake, None, math.inf
        if callback is not None:
            callback(time_s)

    def reset(self) -> None:
        """The physics started again from time 0 (SITL restarted)."""
        with self._condition:
            self._time_s = 0.0

"""Landing attempts counted from telemetry alone, for the modes (and plugins' fault gates) that do not run
the retries themselves."""

from __future__ import annotations

ATTEMPT_CLIMB_M = 0.5  # a climb this large during LAND means the autopilot started another attempt


class AttemptTracker:
    """Counts landing attempts from telemetry alone: a climb of ATTEMPT_CLIMB_M during LAND starts a new
    attempt; the next one can start only after the vehicle has descended again."""

    def __init__(self) -> None:
        self.attempt = 1
        self._lowest_m: float | None = None
        self._highest_m: float | None = None

    def update(self, altitude_rel_m: float) -> bool:
        """Feed the current altitude; True when a new attempt has just started."""
        if self._highest_m is not None:  # climbing back up: wait for the descent to resume
            if altitude_rel_m > self._highest_m:
                self._highest_m = altitude_rel_m
            elif altitude_rel_m < self._highest_m - ATTEMPT_CLIMB_M / 2:
                self._highest_m = None
                self._lowest_m = altitude_rel_m
            return False
        if self._lowest_m is None or altitude_rel_m < self._lowest_m:
            self._lowest_m = altitude_rel_m
            return False
        if altitude_rel_m > self._lowest_m + ATTEMPT_CLIMB_M:
            self.attempt += 1
            self._highest_m = altitude_rel_m
            return True
        return False

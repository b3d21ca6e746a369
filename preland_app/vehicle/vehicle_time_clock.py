"""The autopilot's own clock as a companion follows it over MAVLink: the vehicle time its messages carry,
interpolated between them at the rate measured in wall time."""

from __future__ import annotations

import asyncio
import time


class VehicleTimeClock:
    """The autopilot's clock (time_boot_ms), interpolated between messages at the measured rate.

    The rate is vehicle seconds per wall second (1 for a real drone, the
    speed-up for SITL), estimated over the last seconds of messages, so a 30 s
    timer is 30 vehicle seconds on every runtime. Messages read after nothing
    was read for RATE_GAP_WALL_S (either process stalled, or the link) may have
    waited in a queue and are read at once, so for BACKLOG_WALL_S after such a
    gap the rate stands as it was measured before it.
    """

    RATE_GAP_WALL_S = 0.5
    BACKLOG_WALL_S = 0.25

    def __init__(self) -> None:
        self._samples: list[tuple[float, float]] = []  # (wall s, vehicle s)
        self._fresh_from_wall = 0.0
        self.rate = 1.0

    def observe(self, vehicle_s: float) -> None:
        wall = time.monotonic()
        if self._samples and vehicle_s < self._samples[-1][1] - 1.0:
            self._samples.clear()  # the autopilot rebooted
        elif self._samples and wall - self._samples[-1][0] > self.RATE_GAP_WALL_S:
            # A 3 s stall of the companion's loop, measured across its backlog, read as 0.02x: a quiet link
            # was then lost only after 250 wall s, and every sleep lasted 50 times too long.
            self._fresh_from_wall = wall + self.BACKLOG_WALL_S
        if wall < self._fresh_from_wall:
            self._samples = [(wall, vehicle_s)]  # the newest time, for now_s; not the rate
            return
        self._samples.append((wall, vehicle_s))
        while len(self._samples) > 2 and wall - self._samples[0][0] > 3.0:
            self._samples.pop(0)
        (w0, v0), (w1, v1) = self._samples[0], self._samples[-1]
        if w1 - w0 > 0.5 and v1 > v0:
            self.rate = (v1 - v0) / (w1 - w0)

    @property
    def ready(self) -> bool:
        return bool(self._samples)

    @property
    def newest_s(self) -> float | None:
        """The newest vehicle time read (s), or None before the first."""
        return self._samples[-1][1] if self._samples else None

    @property
    def settled(self) -> bool:
        """True once the rate has been measured over at least a second of messages."""
        return len(self._samples) > 2 and self._samples[-1][0] - self._samples[0][0] >= 1.0

    def now_s(self) -> float:
        if not self._samples:
            return 0.0
        wall, vehicle = self._samples[-1]
        return vehicle + (time.monotonic() - wall) * self.rate

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s) / max(self.rate, 1e-3))

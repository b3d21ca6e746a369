"""A wall clock running `speedup` times faster: for the embedded simulator served over MAVLink."""

from __future__ import annotations

import asyncio
import time


class ScaledWallClock:
    """Seconds since creation times `speedup`; sleeping `d` seconds takes d / speedup of wall time."""

    def __init__(self, *, speedup: float = 1.0) -> None:
        if speedup <= 0:
            raise ValueError(f"speedup must be > 0, got {speedup:g}")
        self.speedup = speedup
        self._start = time.monotonic()

    def now_s(self) -> float:
        return (time.monotonic() - self._start) * self.speedup

    async def sleep(self, duration_s: float) -> None:
        await asyncio.sleep(max(0.0, duration_s) / self.speedup)

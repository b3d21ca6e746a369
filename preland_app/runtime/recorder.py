"""Samples a trajectory during a trial: the vehicle's estimate and, where available, ground truth."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ..clock import Clock
from ..vehicle.protocol import Vehicle

TruthSample = Callable[[], tuple[float, float, float]]
"""Returns the true (north_m, east_m, altitude_m) from the start position."""


class TrajectoryRecorder:
    """Appends one row per `period_s` (see `outcome.TRAJECTORY_COLUMNS`)."""

    def __init__(self, *, vehicle: Vehicle, clock: Clock, period_s: float = 0.1,
                 truth: TruthSample | None = None) -> None:
        self._vehicle = vehicle
        self._clock = clock
        self._period_s = period_s
        self._truth = truth
        self._rows: list[tuple[float, ...]] = []

    async def run(self) -> None:
        while True:
            t = await self._vehicle.telemetry()
            true_n, true_e, true_alt = self._truth() if self._truth else (math.nan, math.nan, math.nan)
            p = t.position_ned_m
            self._rows.append((self._clock.now_s(), p.north_m, p.east_m, -p.down_m, true_n, true_e, true_alt))
            await self._clock.sleep(self._period_s)

    def array(self) -> np.ndarray:
        return np.asarray(self._rows, dtype=float).reshape(-1, 7)

"""Sensor sources on the vehicle clock: the virtual camera's frames and the IR-LOCK's samples.

Both take the true pose from a callable the runtime provides (the embedded
simulator's state, or SITL's SIMSTATE); what comes out is only images and
readings, exactly what a real camera or IR-LOCK would give.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

from ..clock import Clock
from .camera import CameraModel
from .irlock import IrLockModel
from .readings import TargetReading
from .virtual_camera import CameraPose, RenderedFrame, VirtualCamera

PoseSource = Callable[[], CameraPose]


async def _sleep_to_next_tick(clock: Clock, period_s: float) -> int:
    """Sleep until the next multiple of `period_s` on the clock; returns its index."""
    now_s = clock.now_s()
    tick = math.floor(now_s / period_s + 1e-9) + 1
    await clock.sleep(tick * period_s - now_s)
    return tick


class VirtualFrameSource:
    """Frames of the true pose at the camera's frame rate. A frame is captured on its tick (pose, sensor
    noise) and drawn only when a land mode or logger reads it, and then only the part it reads."""

    def __init__(self, *, renderer: VirtualCamera, pose: PoseSource, clock: Clock) -> None:
        self.renderer = renderer
        self.camera: CameraModel = renderer.camera
        self._pose = pose
        self._clock = clock
        self.frames = 0

    async def next_frame(self) -> RenderedFrame | None:
        tick = await _sleep_to_next_tick(self._clock, self.camera.frame_period_s)
        self.frames += 1
        return RenderedFrame(renderer=self.renderer, shot=self.renderer.capture(self._pose()),
                             capture_time_s=self._clock.now_s(), index=tick)


class IrLockSource:
    """IR-LOCK samples at the sensor's rate: a reading, or None when the beacon is not seen. A reading
    describes the pose `spec.latency_s` before it is read (the frame the Pixy last finished)."""

    def __init__(self, *, model: IrLockModel, pose: PoseSource, clock: Clock) -> None:
        self.model = model
        self._pose = pose
        self._clock = clock
        self._period_s = 1.0 / model.spec.rate_hz
        self._poses: deque[tuple[float, CameraPose]] = deque()

    async def next_reading(self) -> TargetReading | None:
        await _sleep_to_next_tick(self._clock, self._period_s)
        now_s = self._clock.now_s()
        self._poses.append((now_s, self._pose()))
        wanted_s = now_s - self.model.spec.latency_s
        while len(self._poses) > 1 and self._poses[1][0] <= wanted_s + 1e-9:
            self._poses.popleft()
        time_s, pose = self._poses[0]
        return self.model.read(pose, capture_time_s=time_s)

"""Sensor sources on the vehicle clock: the virtual camera's frames and the IR-LOCK's samples.

Both take the true pose from a callable the runtime provides (the embedded
simulator's state, or SITL's SIMSTATE); what comes out is only images and
readings, exactly what a real camera or IR-LOCK would give.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable

from ..clock import Clock, join
from .camera import CameraModel
from .irlock import IrLockModel
from .readings import TargetReading
from .virtual_camera import CameraPose, RenderedFrame, VirtualCamera

PoseSource = Callable[[], CameraPose]
# The vehicle time (s) of the pose the pose source gives; None: the clock's reading (the embedded simulator's
# pose is always the present). Over MAVLink the pose is the newest SIM_STATE, which a stalled link or process
# leaves behind the clock. Each reading is made of a pose newer than the last reading's, and stamped with that
# pose's time: readings made again of one pose show the target where it lay from the old position, and the
# autopilot, taking them as current, learns that the target moves with the vehicle and chases it (25 m off
# after a 2.5 s stall of SIM_STATE; several metres off after 0.2 s of such readings).
PoseTimeSource = Callable[[], float] | None


class _NewTruth:
    """Admits each pose time once; counts the ticks that found no newer pose."""

    __slots__ = ("_last_s", "waits")

    def __init__(self) -> None:
        self._last_s: float | None = None
        self.waits = 0

    def admit(self, pose_time_s: float) -> bool:
        if pose_time_s == self._last_s:
            self.waits += 1
            return False
        self._last_s = pose_time_s
        return True


async def _sleep_to_next_tick(clock: Clock, period_s: float) -> int:
    """Sleep until the next multiple of `period_s` on the clock; returns its index."""
    now_s = clock.now_s()
    tick = math.floor(now_s / period_s + 1e-9) + 1
    await clock.sleep(tick * period_s - now_s)
    return tick


class VirtualFrameSource:
    """Frames of the true pose at the camera's frame rate. A frame is captured on its tick (pose, sensor
    noise) and drawn only when a land mode or logger reads it, and then only the part it reads. A tick whose
    pose is no newer than the last frame's gives no frame; the next tick is awaited."""

    def __init__(self, *, renderer: VirtualCamera, pose: PoseSource, clock: Clock,
                 pose_time_s: PoseTimeSource = None) -> None:
        self.renderer = renderer
        self.camera: CameraModel = renderer.camera
        self._pose = pose
        self._pose_time_s = pose_time_s or clock.now_s
        self._clock = clock
        self._truth = _NewTruth()
        self.frames = 0

    @property
    def ticks_without_new_truth(self) -> int:
        return self._truth.waits

    async def next_frame(self) -> RenderedFrame | None:
        join(self._clock)
        while True:
            tick = await _sleep_to_next_tick(self._clock, self.camera.frame_period_s)
            # Stamped with the time of the pose it shows, as a real camera stamps its exposure.
            capture_time_s = self._pose_time_s()
            if self._truth.admit(capture_time_s):
                break
        self.frames += 1
        return RenderedFrame(renderer=self.renderer, shot=self.renderer.capture(self._pose()),
                             capture_time_s=capture_time_s, index=tick)


class IrLockSource:
    """IR-LOCK samples at the sensor's rate: a reading, or None when the beacon is not seen or no pose
    newer than the last reading's has come. A reading describes the pose `spec.latency_s` before it is read
    (the frame the Pixy last finished)."""

    def __init__(self, *, model: IrLockModel, pose: PoseSource, clock: Clock,
                 pose_time_s: PoseTimeSource = None) -> None:
        self.model = model
        self._pose = pose
        self._pose_time_s = pose_time_s or clock.now_s
        self._clock = clock
        self._period_s = 1.0 / model.spec.rate_hz
        self._poses: deque[tuple[float, CameraPose]] = deque()
        # Only for a truth stream: on the embedded simulator every tick's pose is new, and the pose `latency_s`
        # old is picked from the history, which at a float's edge picks one pose twice (2 of 1,359 ticks in a
        # thesis trial); refusing those would move every published IR-LOCK figure for nothing.
        self._truth = _NewTruth() if pose_time_s is not None else None

    @property
    def ticks_without_new_truth(self) -> int:
        return self._truth.waits if self._truth is not None else 0

    async def next_reading(self) -> TargetReading | None:
        join(self._clock)
        await _sleep_to_next_tick(self._clock, self._period_s)
        now_s = self._clock.now_s()
        pose_time_s = self._pose_time_s()
        if not self._poses or pose_time_s != self._poses[-1][0]:
            self._poses.append((pose_time_s, self._pose()))
        wanted_s = now_s - self.model.spec.latency_s
        while len(self._poses) > 1 and self._poses[1][0] <= wanted_s + 1e-9:
            self._poses.popleft()
        time_s, pose = self._poses[0]
        if self._truth is not None and not self._truth.admit(time_s):
            return None
        return self.model.read(pose, capture_time_s=time_s)

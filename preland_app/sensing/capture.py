"""Real frame sources behind the same FrameSource interface as the virtual camera: an OpenCV capture
device (index, device path or GStreamer pipeline) and a video file (a recorded flight, replayed).

Reading runs in a worker thread so the event loop is never blocked by the
camera. Frames keep the capture time on the vehicle clock (live devices) or
the time the video file gives (its frame index over its frame rate, from the
moment the replay started).
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import cv2
import numpy as np

from ..clock import Clock
from ..errors import PrelandError
from .camera import RPI_CAMERA_V2_640X480, CameraModel, Frame

LOSSLESS_FOURCC = "FFV1"


class CaptureError(PrelandError):
    """A camera or video cannot be opened or read."""


def _open(source: str | int) -> cv2.VideoCapture:
    if isinstance(source, str) and source.isdigit():
        source = int(source)
    capture = cv2.VideoCapture(source, cv2.CAP_GSTREAMER) if isinstance(source, str) and "!" in source \
        else cv2.VideoCapture(source)
    if not capture.isOpened():
        raise CaptureError(f"cannot open camera or video {source!r}")
    return capture


class VideoFileSource:
    """Frames of a video file, at the file's frame rate on the given clock (or as fast as read with
    `realtime=False`, for replays in tests and benchmarks)."""

    def __init__(self, *, path: str | Path, clock: Clock, camera: CameraModel = RPI_CAMERA_V2_640X480,
                 realtime: bool = False, grayscale: bool = True) -> None:
        if not Path(path).is_file():
            raise CaptureError(f"video {path} not found")
        self.capture = _open(str(path))
        self.camera = camera
        self.clock = clock
        self.realtime = realtime
        self.grayscale = grayscale
        fps = self.capture.get(cv2.CAP_PROP_FPS)
        self.frame_rate_hz = fps if fps and fps > 0 else camera.frame_rate_hz
        self.frames = 0
        self._start_s = clock.now_s()

    async def next_frame(self) -> Frame | None:
        ok, image = await asyncio.get_running_loop().run_in_executor(None, self.capture.read)
        if not ok:
            self.capture.release()
            return None
        if self.grayscale and image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        stamp_s = self._start_s + self.frames / self.frame_rate_hz
        self.frames += 1
        if self.realtime and stamp_s > self.clock.now_s():
            await self.clock.sleep(stamp_s - self.clock.now_s())
        return Frame(image, capture_time_s=stamp_s, index=self.frames - 1)


class CaptureDeviceSource:
    """Live frames from an OpenCV capture device: an index ("0"), a device path (/dev/video0) or a
    GStreamer pipeline (any string with "!")."""

    def __init__(self, *, source: str | int, clock: Clock, camera: CameraModel = RPI_CAMERA_V2_640X480) -> None:
        self.capture = _open(source)
        self.capture.set(cv2.CAP_PROP_FRAME_WIDTH, camera.width_px)
        self.capture.set(cv2.CAP_PROP_FRAME_HEIGHT, camera.height_px)
        self.capture.set(cv2.CAP_PROP_FPS, camera.frame_rate_hz)
        self.camera = camera
        self.clock = clock
        self.frames = 0

    async def next_frame(self) -> Frame | None:
        ok, image = await asyncio.get_running_loop().run_in_executor(None, self.capture.read)
        stamp_s = self.clock.now_s()
        if not ok:
            raise CaptureError("the camera stopped delivering frames")
        self.frames += 1
        return Frame(image, capture_time_s=stamp_s, index=self.frames - 1)

    def close(self) -> None:
        self.capture.release()


class VideoRecorder:
    """Writes frames to a video file (FFV1, lossless, for .mkv/.avi; mp4v for .mp4)."""

    def __init__(self, *, path: str | Path, frame_rate_hz: float, size: tuple[int, int], color: bool = False) -> None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        fourcc = "mp4v" if path.suffix.lower() == ".mp4" else LOSSLESS_FOURCC
        self.writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), frame_rate_hz, size, color)
        if not self.writer.isOpened():
            raise CaptureError(f"cannot write video {path}")
        self.path = path

    def write(self, image: np.ndarray) -> None:
        self.writer.write(image)

    def close(self) -> None:
        self.writer.release()

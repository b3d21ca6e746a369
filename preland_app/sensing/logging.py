"""What the companion keeps of a flight: every detection (CSV) and, optionally, the camera's video."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..clock import Clock
from .camera import Frame, FrameSource
from .capture import VideoRecorder
from .marker import MarkerDetection, MarkerDetector, choose_smallest

DETECTION_COLUMNS = ("time_s", "markers", "chosen_id", "angle_x_deg", "angle_y_deg", "distance_m")


class LoggingDetector:
    """A MarkerDetector that writes one CSV row per frame it processes (vehicle time, ids, chosen marker)."""

    def __init__(self, *, detector: MarkerDetector, path: str | Path, clock: Clock) -> None:
        self.detector = detector
        self.pad = detector.pad
        self.camera = detector.camera
        self.clock = clock
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("w", newline="", encoding="utf-8")
        self._writer = csv.writer(self._file)
        self._writer.writerow(DETECTION_COLUMNS)
        self.rows = 0

    def detect(self, image: np.ndarray) -> list[MarkerDetection]:
        return self._log(self.detector.detect(image))

    def detect_frame(self, frame) -> list[MarkerDetection]:
        return self._log(self.detector.detect_frame(frame))

    def _log(self, detections: list[MarkerDetection]) -> list[MarkerDetection]:
        chosen = choose_smallest(detections)
        angles = [math.degrees(a) for a in chosen.angles_rad()] if chosen else [None, None]
        self._writer.writerow([round(self.clock.now_s(), 3), " ".join(str(d.marker_id) for d in detections),
                               chosen.marker_id if chosen else "",
                               *(round(a, 3) if a is not None else "" for a in angles),
                               round(chosen.distance_m, 3) if chosen else ""])
        self.rows += 1
        return detections

    def close(self) -> None:
        self._file.close()


class RecordingFrameSource:
    """Passes frames through and writes each one to a video file."""

    def __init__(self, *, source: FrameSource, path: str | Path) -> None:
        self.source = source
        self.camera = source.camera
        self.path = Path(path)
        self._recorder: VideoRecorder | None = None

    async def next_frame(self) -> Frame | None:
        frame = await self.source.next_frame()
        if frame is not None:
            if self._recorder is None:
                self._recorder = VideoRecorder(path=self.path, frame_rate_hz=self.camera.frame_rate_hz,
                                               size=(frame.image.shape[1], frame.image.shape[0]),
                                               color=frame.image.ndim == 3)
            self._recorder.write(frame.image)
        return frame

    def close(self) -> None:
        if self._recorder is not None:
            self._recorder.close()

"""The `sensors:` section of a mission: camera, marker sensor, IR-LOCK and fusion settings."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from ..errors import require
from .camera import RPI_CAMERA_V2_640X480, CameraModel, load_calibration
from .fusion import FusionSpec
from .irlock import IrLockSpec
from .marker import DETECTOR_PARAMETER_KINDS, detector_parameter_problem, opencv_refusal
from .virtual_camera import ImageEffects


@dataclass(frozen=True)
class CameraSpec:
    """The companion's camera. `calibration`: an OpenCV calibration file (relative to the mission
    file), default the nominal Raspberry Pi camera v2 at 640x480. `noise_sigma` (grey levels),
    `blur_px` and `exposure_gain` degrade the virtual camera's frames."""

    calibration: str | None = None
    frame_rate_hz: float = 30.0
    # Thesis Fig. 14b: the camera right of the IR-LOCK, the pair at the frame's centre (boards 25 mm
    # and 53 mm wide): the camera's lens 27 mm right of the centre.
    mount_offset_frd_m: tuple[float, float, float] = (0.0, 0.027, 0.0)
    noise_sigma: float = 2.0
    blur_px: float = 0.0
    exposure_gain: float = 1.0

    def __post_init__(self) -> None:
        require(0 < self.frame_rate_hz <= 240, "frame_rate_hz", "must be within 0..240 Hz")
        require(self.noise_sigma >= 0, "noise_sigma", "must be >= 0")
        require(self.blur_px >= 0, "blur_px", "must be >= 0")
        require(0.05 <= self.exposure_gain <= 20, "exposure_gain", "must be within 0.05..20")

    def model(self, *, relative_to: Path | None = None) -> CameraModel:
        base = RPI_CAMERA_V2_640X480
        if self.calibration is not None:
            path = Path(self.calibration)
            if relative_to is not None and not path.is_absolute():
                path = relative_to / path
            base = load_calibration(path)
        return replace(base, frame_rate_hz=self.frame_rate_hz, mount_offset_frd_m=self.mount_offset_frd_m)

    def effects(self) -> ImageEffects:
        return ImageEffects(noise_sigma=self.noise_sigma, blur_px=self.blur_px, exposure_gain=self.exposure_gain)


@dataclass(frozen=True)
class MarkerSensorSpec:
    """Marker processing on the companion: `processing_latency_s` from capture to reading
    (thesis: about 50 ms on a Raspberry Pi). Frames are processed one at a time, so the
    reading rate is the frame rate divided by the frames each one takes (15 Hz at 30 fps).
    `detector`: OpenCV ArUco detector parameters by OpenCV's names (cv2.aruco.DetectorParameters),
    over its defaults with sub-pixel corners; empty, the thesis' detector."""

    processing_latency_s: float = 0.05
    # Hashed only when set (config/mission.py's HASH_WHEN_SET), so stored campaigns still resume.
    detector: dict[str, Any] = field(default_factory=dict, metadata={
        "hash": "when-set", "schema": {"propertyNames": {"enum": sorted(DETECTOR_PARAMETER_KINDS)}}})

    def __post_init__(self) -> None:
        require(0 <= self.processing_latency_s <= 2.0, "processing_latency_s", "must be within 0..2 s")
        for name, value in self.detector.items():
            problem = detector_parameter_problem(name, value)
            require(problem is None, f"detector.{name}", problem or "")
        if self.detector:
            problem = opencv_refusal(self.detector)
            require(problem is None, "detector", problem or "")


@dataclass(frozen=True)
class SensorsSpec:
    camera: CameraSpec = field(default_factory=CameraSpec)
    marker: MarkerSensorSpec = field(default_factory=MarkerSensorSpec)
    irlock: IrLockSpec = field(default_factory=IrLockSpec)
    fusion: FusionSpec = field(default_factory=FusionSpec)

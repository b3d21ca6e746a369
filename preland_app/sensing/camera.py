"""Camera models: pinhole intrinsics with OpenCV distortion, and how the camera sits on the vehicle.

Frames: the OpenCV camera frame has x right, y down (in the image) and z along
the optical axis. The camera looks straight down with the image's top towards
the vehicle's nose, so camera x = body right, camera y = body backward,
camera z = body down (body FRD). `mount_offset_frd_m` is the camera's position
from the vehicle's centre, body FRD, metres.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import yaml

from ..errors import SpecError, require

# Body FRD -> camera (OpenCV) axes for a downward camera, image top = nose.
R_CAM_FROM_BODY = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics in pixels, OpenCV distortion (k1, k2, p1, p2, k3), frame size and rate."""

    width_px: int = 640
    height_px: int = 480
    fx_px: float = 530.0
    fy_px: float = 530.0
    cx_px: float = 320.0
    cy_px: float = 240.0
    distortion: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    frame_rate_hz: float = 30.0
    mount_offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    name: str = "Raspberry Pi camera v2, 640x480 (nominal)"

    def __post_init__(self) -> None:
        require(16 <= self.width_px <= 8192 and 16 <= self.height_px <= 8192, "width_px", "frame size out of range")
        require(self.fx_px > 0 and self.fy_px > 0, "fx_px", "focal lengths must be > 0")
        require(len(self.distortion) in (4, 5, 8), "distortion", "expected 4, 5 or 8 OpenCV coefficients")
        require(0 < self.frame_rate_hz <= 240, "frame_rate_hz", "must be within 0..240 Hz")

    @property
    def camera_matrix(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        return np.array(self.distortion, dtype=float)

    @property
    def has_distortion(self) -> bool:
        return any(abs(c) > 0 for c in self.distortion)

    @property
    def horizontal_fov_deg(self) -> float:
        return math.degrees(2.0 * math.atan(self.width_px / (2.0 * self.fx_px)))

    @property
    def frame_period_s(self) -> float:
        return 1.0 / self.frame_rate_hz


# The Raspberry Pi camera module v2 at 640x480: 62.2 deg horizontal field of view
# (3.04 mm lens on a 3.68 mm wide sensor), so fx = 320 / tan(31.1 deg) = 530 px.
RPI_CAMERA_V2_640X480 = CameraModel()


def load_calibration(path: str | Path, *, base: CameraModel = RPI_CAMERA_V2_640X480) -> CameraModel:
    """Read an OpenCV calibration (YAML/JSON with camera_matrix, distortion_coefficients, image size).

    Accepts OpenCV FileStorage YAML (`%YAML:1.0`, opencv-matrix nodes) and plain
    YAML/JSON with `camera_matrix` (3x3 list) and `dist_coeffs` or
    `distortion_coefficients` (list), plus optional `image_width`/`image_height`.
    """
    path_text = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as error:
        raise SpecError(path=path_text, field="", problem=f"cannot read calibration ({error.strerror})") from None
    except UnicodeDecodeError as error:
        from ..config.loader import not_utf8_problem

        raise SpecError(path=path_text, field="", problem=not_utf8_problem(error)) from None
    if text.lstrip().startswith("%YAML"):
        return _load_filestorage(path_text, base)
    try:
        data: Any = json.loads(text) if path_text.endswith(".json") else yaml.safe_load(text)
    except (ValueError, yaml.YAMLError) as error:
        raise SpecError(path=path_text, field="", problem=f"malformed calibration file: {error}") from None
    if not isinstance(data, dict):
        raise SpecError(path=path_text, field="", problem="expected a mapping")
    matrix = data.get("camera_matrix")
    if isinstance(matrix, dict) and "data" in matrix:
        matrix = np.array(matrix["data"], float).reshape(3, 3).tolist()
    dist = data.get("dist_coeffs", data.get("distortion_coefficients"))
    if isinstance(dist, dict) and "data" in dist:
        dist = list(dist["data"])
    try:
        k = np.array(matrix, float).reshape(3, 3)
    except (TypeError, ValueError):
        raise SpecError(path=path_text, field="camera_matrix", problem="expected a 3x3 matrix") from None
    try:
        coefficients = tuple(float(c) for c in np.array(dist if dist is not None else [0, 0, 0, 0, 0], float).ravel())
    except (TypeError, ValueError):
        raise SpecError(path=path_text, field="dist_coeffs", problem="expected a list of numbers") from None
    return _with_intrinsics(base, k, coefficients, data.get("image_width"), data.get("image_height"), path_text)


def _load_filestorage(path_text: str, base: CameraModel) -> CameraModel:
    import cv2

    storage = cv2.FileStorage(path_text, cv2.FILE_STORAGE_READ)
    try:
        k = storage.getNode("camera_matrix").mat()
        dist = storage.getNode("distortion_coefficients").mat()
        if dist is None:
            dist = storage.getNode("dist_coeffs").mat()
        width = storage.getNode("image_width").real() or None
        height = storage.getNode("image_height").real() or None
    finally:
        storage.release()
    if k is None or k.shape != (3, 3):
        raise SpecError(path=path_text, field="camera_matrix", problem="missing or not 3x3")
    coefficients = tuple(float(c) for c in (dist.ravel() if dist is not None else np.zeros(5)))
    return _with_intrinsics(base, k, coefficients, width, height, path_text)


def _with_intrinsics(base: CameraModel, k: np.ndarray, coefficients: tuple[float, ...], width, height,
                     path_text: str) -> CameraModel:
    try:
        return replace(base, fx_px=float(k[0, 0]), fy_px=float(k[1, 1]), cx_px=float(k[0, 2]), cy_px=float(k[1, 2]),
                       distortion=coefficients, width_px=int(width or base.width_px),
                       height_px=int(height or base.height_px), name=Path(path_text).name)
    except ValueError as error:
        raise SpecError(path=path_text, field="camera_matrix", problem=str(error)) from None


@dataclass(frozen=True, slots=True)
class Frame:
    """One camera frame: an ordinary numpy image (grayscale or BGR uint8) and its capture time (vehicle clock, s)."""

    image: np.ndarray
    capture_time_s: float
    index: int = 0

    @property
    def size_px(self) -> tuple[int, int]:
        """(width, height) in px."""
        return self.image.shape[1], self.image.shape[0]

    def region(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        """The pixels in columns x0..x1 and rows y0..y1 (px, ends exclusive), as a contiguous image."""
        return np.ascontiguousarray(self.image[y0:y1, x0:x1])


class FrameSource(Protocol):
    """Anything that yields frames: the virtual camera, an OpenCV capture, a video file. A frame has
    `image`, `capture_time_s`, `index`, `size_px` and `region()` (the virtual camera's frames draw their
    pixels only when `image` or `region()` is read)."""

    camera: CameraModel

    async def next_frame(self) -> Frame | None:
        """The next frame (waits for it on the vehicle clock), or None when the source is exhausted."""
        ...

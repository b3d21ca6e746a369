"""Camera calibration from views of a ChArUco board (OpenCV), written as an OpenCV calibration file
that the marker sensor reads (`camera.load_calibration`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from ..errors import PrelandError, require
from .pad import DICTIONARIES, aruco_dictionary


class CalibrationError(PrelandError):
    """Calibration failed (too few usable views, unreadable images...)."""


@dataclass(frozen=True)
class CharucoBoardSpec:
    """A ChArUco board: squares across and down, square and marker sides in m, the ArUco dictionary."""

    squares_x: int = 7
    squares_y: int = 5
    square_m: float = 0.04
    marker_m: float = 0.03
    dictionary: str = "DICT_4X4_50"

    def __post_init__(self) -> None:
        require(2 <= self.squares_x <= 40, "squares_x", f"must be within 2..40, got {self.squares_x}")
        require(2 <= self.squares_y <= 40, "squares_y", f"must be within 2..40, got {self.squares_y}")
        require(0 < self.square_m <= 0.5, "square_m", f"must be > 0 and <= 0.5 m, got {self.square_m:g}")
        require(0 < self.marker_m < self.square_m, "marker_m",
                f"must be > 0 and smaller than the square ({self.square_m:g} m), got {self.marker_m:g}")
        require(self.dictionary in DICTIONARIES, "dictionary",
                f"unknown ArUco dictionary {self.dictionary!r} (e.g. {', '.join(list(DICTIONARIES)[:4])})")

    def board(self) -> cv2.aruco.CharucoBoard:
        return cv2.aruco.CharucoBoard((self.squares_x, self.squares_y), self.square_m, self.marker_m,
                                      aruco_dictionary(self.dictionary))


@dataclass(frozen=True)
class CalibrationResult:
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_error_px: float
    views_used: int

    @property
    def fx_px(self) -> float:
        return float(self.camera_matrix[0, 0])

    @property
    def fy_px(self) -> float:
        return float(self.camera_matrix[1, 1])

    def write(self, path: str | Path) -> Path:
        """An OpenCV FileStorage YAML: camera_matrix, distortion_coefficients, image_width, image_height."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        storage.write("image_width", int(self.image_size[0]))
        storage.write("image_height", int(self.image_size[1]))
        storage.write("camera_matrix", self.camera_matrix)
        storage.write("distortion_coefficients", self.dist_coeffs.reshape(1, -1))
        storage.write("rms_error_px", float(self.rms_error_px))
        storage.release()
        return path


def calibrate(images: list[np.ndarray], *, board_spec: CharucoBoardSpec = CharucoBoardSpec(),
              min_corners: int = 8) -> CalibrationResult:
    """Calibrate from images of the board. Raises CalibrationError with fewer than 4 usable views."""
    board = board_spec.board()
    detector = cv2.aruco.CharucoDetector(board)
    object_points, image_points = [], []
    size = None
    for image in images:
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        size = (gray.shape[1], gray.shape[0])
        corners, ids, _, _ = detector.detectBoard(gray)
        if ids is None or len(ids) < min_corners:
            continue
        objects, points = board.matchImagePoints(corners, ids)
        if objects is None or len(objects) < min_corners:
            continue
        object_points.append(objects)
        image_points.append(points)
    if len(object_points) < 4 or size is None:
        raise CalibrationError(f"only {len(object_points)} usable view(s) of the board; at least 4 are needed")
    rms, matrix, dist, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    return CalibrationResult(camera_matrix=matrix, dist_coeffs=dist, image_size=size, rms_error_px=float(rms),
                             views_used=len(object_points))


def read_images(*, folder: Path | None = None, video: Path | None = None, every: int = 10) -> list[np.ndarray]:
    """Images from a folder (png/jpg), or every `every`-th frame of a video."""
    images: list[np.ndarray] = []
    if folder is not None:
        for path in sorted(p for p in Path(folder).iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg")):
            image = cv2.imread(str(path))
            if image is not None:
                images.append(image)
    if video is not None:
        capture = cv2.VideoCapture(str(video))
        index = 0
        while True:
            ok, frame = capture.read()
            if not ok:
                break
            if index % every == 0:
                images.append(frame)
            index += 1
        capture.release()
    if not images:
        raise CalibrationError("no images to calibrate from")
    return images

"""Marker sensor: ArUco detection on camera frames -> landing-target readings for the pad's centre.

Every frame goes through `cv2.aruco.ArucoDetector`. Each detected marker that
belongs to the pad gets a pose from `cv2.solvePnP` (IPPE_SQUARE) with its known
side length; from the chosen marker the pad's centre is located in the camera
frame, which gives the LANDING_TARGET angles and the distance. Only the image
and the pad's layout enter a reading, never the simulator's truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import CameraModel, Frame
from .pad import MarkerSpec, PadSpec, aruco_dictionary
from .readings import TargetReading, angles_from_camera_point


@dataclass(frozen=True, slots=True, kw_only=True)
class MarkerDetection:
    """One pad marker found in a frame. `pad_center_cam_m`: the pad centre in the camera frame (m)."""

    marker_id: int
    side_m: float
    corners_px: np.ndarray
    rvec: np.ndarray
    tvec: np.ndarray
    pad_center_cam_m: np.ndarray

    @property
    def distance_m(self) -> float:
        return float(np.linalg.norm(self.pad_center_cam_m))

    @property
    def marker_distance_m(self) -> float:
        return float(np.linalg.norm(self.tvec))

    def angles_rad(self) -> tuple[float, float]:
        x, y, z = self.pad_center_cam_m
        return angles_from_camera_point(float(x), float(y), float(z))


def detector_parameters() -> cv2.aruco.DetectorParameters:
    """OpenCV's defaults plus sub-pixel corner refinement (the angles need it)."""
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    return parameters


class MarkerDetector:
    """Finds the pad's markers in an image and estimates each one's pose."""

    def __init__(self, *, pad: PadSpec, camera: CameraModel,
                 parameters: cv2.aruco.DetectorParameters | None = None) -> None:
        self.pad = pad
        self.camera = camera
        self.detector = cv2.aruco.ArucoDetector(aruco_dictionary(pad.dictionary), parameters or detector_parameters())
        self._k = camera.camera_matrix
        self._dist = camera.dist_coeffs
        self._markers = {m.id: m for m in pad.markers}
        self._object_points = {m.id: self._square(m.side_m) for m in pad.markers}
        self._pad_center_local = {m.id: self._center_in_marker_frame(m) for m in pad.markers}

    @staticmethod
    def _square(side_m: float) -> np.ndarray:
        h = side_m / 2.0
        return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]], dtype=np.float64)

    @staticmethod
    def _center_in_marker_frame(marker: MarkerSpec) -> np.ndarray:
        """The pad's centre in the marker's own frame (x right/east, y up/north, z out of the pad)."""
        north, east = -marker.center_m[0], -marker.center_m[1]
        yaw = math.radians(marker.yaw_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        return np.array([east * c + north * s, -east * s + north * c, 0.0])

    def detect(self, image: np.ndarray) -> list[MarkerDetection]:
        """All of the pad's markers found in `image` (grayscale or BGR), with poses."""
        corners, ids, _ = self.detector.detectMarkers(_gray(image))
        return self._poses(corners, ids, offset=(0.0, 0.0))

    def detect_frame(self, frame) -> list[MarkerDetection]:
        """`detect` on a camera frame (`Frame`, or a virtual camera's frame, drawn as it is read)."""
        return self.detect(frame.image)

    def _poses(self, corners, ids, *, offset: tuple[float, float]) -> list[MarkerDetection]:
        if ids is None:
            return []
        detections = []
        shift = np.array(offset, dtype=np.float64)
        for marker_corners, marker_id in zip(corners, ids.ravel().tolist()):
            marker = self._markers.get(marker_id)
            if marker is None:
                continue
            image_points = marker_corners.reshape(4, 2).astype(np.float64) + shift
            ok, rvec, tvec = cv2.solvePnP(self._object_points[marker_id], image_points, self._k, self._dist,
                                          flags=cv2.SOLVEPNP_IPPE_SQUARE)
            if not ok or tvec[2, 0] <= 0:
                continue
            rotation, _ = cv2.Rodrigues(rvec)
            center = rotation @ self._pad_center_local[marker_id] + tvec.ravel()
            detections.append(MarkerDetection(marker_id=marker_id, side_m=marker.side_m, corners_px=image_points,
                                              rvec=rvec.ravel(), tvec=tvec.ravel(), pad_center_cam_m=center))
        return detections


class TrackingMarkerDetector(MarkerDetector):
    """A MarkerDetector that looks first where the pad was in the previous frame.

    Real-time trackers on small computers do the same: after a detection, the
    next frame is searched in a window around it (twice the markers' extent
    plus a margin); the whole frame is searched when that finds nothing, and
    every `full_frame_every` frames so that markers coming into view elsewhere
    are not missed. In the window, the detector keeps the whole frame's marker
    size limits in pixels (OpenCV states them relative to the image searched),
    so a window finds what the whole frame would find there. Given a virtual
    camera's frame (`detect_frame`), only the window is drawn.
    """

    def __init__(self, *, pad: PadSpec, camera: CameraModel, parameters: cv2.aruco.DetectorParameters | None = None,
                 full_frame_every: int = 10, margin_px: int = 24) -> None:
        super().__init__(pad=pad, camera=camera, parameters=parameters)
        self.full_frame_every = full_frame_every
        self.margin_px = margin_px
        self._window_parameters = self.detector.getDetectorParameters()
        self._min_perimeter_rate = self._window_parameters.minMarkerPerimeterRate
        self._max_perimeter_rate = self._window_parameters.maxMarkerPerimeterRate
        self._window_detector = cv2.aruco.ArucoDetector(self.detector.getDictionary(), self._window_parameters)
        self._window: tuple[int, int, int, int] | None = None
        self._frames = 0
        self.window_hits = 0

    def detect(self, image: np.ndarray) -> list[MarkerDetection]:
        return self.detect_frame(Frame(_gray(image), capture_time_s=0.0))

    def detect_frame(self, frame) -> list[MarkerDetection]:
        self._frames += 1
        width, height = frame.size_px
        detections: list[MarkerDetection] = []
        if self._window is not None and self._frames % self.full_frame_every != 0:
            x0, y0, x1, y1 = self._window
            corners, ids, _ = self._window_detector_for(x1 - x0, y1 - y0, max(width, height)).detectMarkers(
                _gray(frame.region(x0, y0, x1, y1)))
            detections = self._poses(corners, ids, offset=(float(x0), float(y0)))
            if detections:
                self.window_hits += 1
        if not detections:
            detections = super().detect(frame.image)
        self._window = self._window_around(detections, (height, width)) if detections else None
        return detections

    def _window_detector_for(self, width_px: int, height_px: int, frame_side_px: int) -> cv2.aruco.ArucoDetector:
        """The window's detector, with the marker perimeter limits of the whole frame in pixels."""
        scale = frame_side_px / max(width_px, height_px)
        self._window_parameters.minMarkerPerimeterRate = self._min_perimeter_rate * scale
        self._window_parameters.maxMarkerPerimeterRate = self._max_perimeter_rate * scale
        self._window_detector.setDetectorParameters(self._window_parameters)
        return self._window_detector

    def _window_around(self, detections: list[MarkerDetection], shape) -> tuple[int, int, int, int] | None:
        points = np.vstack([d.corners_px for d in detections])
        (x_min, y_min), (x_max, y_max) = points.min(axis=0), points.max(axis=0)
        half_w = (x_max - x_min) + self.margin_px
        half_h = (y_max - y_min) + self.margin_px
        cx, cy = (x_min + x_max) / 2.0, (y_min + y_max) / 2.0
        height, width = shape[:2]
        x0, x1 = max(0, int(cx - half_w)), min(width, int(cx + half_w) + 1)
        y0, y1 = max(0, int(cy - half_h)), min(height, int(cy + half_h) + 1)
        if (x1 - x0) * (y1 - y0) > 0.6 * width * height:
            return None  # the window would be most of the frame: search the frame
        return x0, y0, x1, y1


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def choose_smallest(detections: list[MarkerDetection]) -> MarkerDetection | None:
    """The smallest detected marker: the most precise one that is fully in view."""
    return min(detections, key=lambda d: (d.side_m, -d.marker_id)) if detections else None


def reading_from_detection(detection: MarkerDetection, *, capture_time_s: float) -> TargetReading:
    angle_x, angle_y = detection.angles_rad()
    return TargetReading(sensor="marker", capture_time_s=capture_time_s, angle_x_rad=angle_x, angle_y_rad=angle_y,
                         distance_m=detection.distance_m, marker_id=detection.marker_id)

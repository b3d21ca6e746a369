"""Marker sensor: ArUco detection on camera frames -> landing-target readings for the pad's centre.

Every frame goes through `cv2.aruco.ArucoDetector`. Each detected marker that
belongs to the pad gets a pose from `cv2.solvePnP` (IPPE_SQUARE) with its known
side length; from the chosen marker the pad's centre is located in the camera
frame, which gives the LANDING_TARGET angles and the distance. Only the image
and the pad's layout enter a reading, never the simulator's truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

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

    def displaced(self, *, offset_cam_m: tuple[float, float], height_m: float | None = None) -> "MarkerDetection":
        """This detection as if its marker lay `offset_cam_m` (x right, y down in the image; m) away in the
        camera frame: its pose and the pad centre move, its pixel corners stay (a false detection's pose is
        what a land mode reads). `height_m` is not needed: the pose has the range."""
        shift = np.array([offset_cam_m[0], offset_cam_m[1], 0.0])
        return replace(self, tvec=np.asarray(self.tvec, dtype=float).reshape(3) + shift,
                       pad_center_cam_m=np.asarray(self.pad_center_cam_m, dtype=float) + shift)


def _parameter_kinds() -> dict[str, type]:
    defaults = cv2.aruco.DetectorParameters()
    return {name: type(getattr(defaults, name)) for name in dir(defaults)
            if not name.startswith("_") and not callable(getattr(defaults, name))}


_CORNER_REFINE_METHODS = {cv2.aruco.CORNER_REFINE_NONE, cv2.aruco.CORNER_REFINE_SUBPIX, cv2.aruco.CORNER_REFINE_CONTOUR,
                          cv2.aruco.CORNER_REFINE_APRILTAG}
# Every settable field of OpenCV's DetectorParameters, by its type there (bool, int or float).
DETECTOR_PARAMETER_KINDS: dict[str, type] = _parameter_kinds()


def detector_parameter_problem(name: str, value: object) -> str | None:
    """Why `value` cannot be OpenCV ArUco detector parameter `name`, or None when it can."""
    kind = DETECTOR_PARAMETER_KINDS.get(name)
    if kind is None:
        close = [known for known in DETECTOR_PARAMETER_KINDS if known.lower() == name.lower()]
        hint = f" (did you mean {close[0]}?)" if close else " (see cv2.aruco.DetectorParameters)"
        return f"not an OpenCV ArUco detector parameter{hint}"
    if kind is bool:
        return None if isinstance(value, bool) else f"expected true or false, got {value!r}"
    if kind is int:
        if not isinstance(value, int) or isinstance(value, bool):
            return f"expected an integer, got {value!r}"
        if name == "cornerRefinementMethod" and value not in _CORNER_REFINE_METHODS:
            return f"expected one of {sorted(_CORNER_REFINE_METHODS)} (cv2.aruco.CORNER_REFINE_*), got {value!r}"
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"expected a number, got {value!r}"
    return None


def opencv_refusal(overrides: dict[str, object]) -> str | None:
    """Why OpenCV refuses these detector parameters together (its detector run once on a blank image), or None."""
    try:
        parameters = detector_parameters(overrides)
        cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(cv2.aruco.DICT_4X4_50), parameters).detectMarkers(
            np.full((64, 64), 128, dtype=np.uint8))
    except (ValueError, cv2.error) as error:
        text = " ".join(str(error).split())
        return f"OpenCV refuses them: {text.split(' error: ', 1)[-1]}"
    return None


def detector_parameters(overrides: dict[str, object] | None = None) -> cv2.aruco.DetectorParameters:
    """OpenCV's defaults plus sub-pixel corner refinement (the angles need it), then `overrides` (OpenCV's
    names, checked by `detector_parameter_problem`)."""
    parameters = cv2.aruco.DetectorParameters()
    parameters.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    for name, value in (overrides or {}).items():
        problem = detector_parameter_problem(name, value)
        if problem is not None:
            raise ValueError(f"{name}: {problem}")
        setattr(parameters, name, value)
    return parameters


@dataclass(frozen=True, slots=True)
class _SubPixRefinement:
    """OpenCV's CORNER_REFINE_SUBPIX, done here on a patch anchored at the marker.

    OpenCV refines in the coordinates of the image it was given. For a small
    marker its window is 1 px, where cornerSubPix is ill-conditioned: float32
    rounding of the corners' absolute coordinates then moves a corner by up to
    0.84 px (measured: the same frame, cropped 99 px further right). Refining in
    a patch whose origin is fixed to the marker's pixels makes the corners the
    same wherever the marker lies in the image searched, with OpenCV's own window
    rule (relative to the module size, at most cornerRefinementWinSize) and
    stopping criteria."""

    relative_window: float
    max_window_px: int
    max_iterations: int
    min_accuracy_px: float
    modules: int

    def refine(self, gray: np.ndarray, corners_px: np.ndarray) -> np.ndarray:
        """`corners_px` (4x2, float32, pixels of `gray`) refined, as float64."""
        (ax, ay), (bx, by), (cx, cy), (dx, dy) = corners_px.tolist()
        f32 = np.float32
        # OpenCV's average module size: the four side lengths summed in float32, in its order.
        perimeter = f32(0.0)
        for ex, ey in ((ax - bx, ay - by), (bx - cx, by - cy), (cx - dx, cy - dy), (dx - ax, dy - ay)):
            perimeter = f32(perimeter + f32(math.sqrt(f32(f32(f32(ex) * f32(ex)) + f32(f32(ey) * f32(ey))))))
        module_px = float(perimeter / f32(4 * self.modules))
        window = min(self.max_window_px, max(1, round(self.relative_window * module_px)))
        reach = window + 8
        height, width = gray.shape[:2]
        x0 = max(0, math.floor(min(ax, bx, cx, dx)) - reach)
        y0 = max(0, math.floor(min(ay, by, cy, dy)) - reach)
        x1 = min(width, math.ceil(max(ax, bx, cx, dx)) + reach + 1)
        y1 = min(height, math.ceil(max(ay, by, cy, dy)) + reach + 1)
        local = np.array([[ax - x0, ay - y0], [bx - x0, by - y0], [cx - x0, cy - y0], [dx - x0, dy - y0]],
                         dtype=np.float32).reshape(4, 1, 2)
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, self.max_iterations, self.min_accuracy_px)
        cv2.cornerSubPix(gray[y0:y1, x0:x1], local, (window, window), (-1, -1), criteria)
        return local.reshape(4, 2).astype(np.float64) + (x0, y0)


class MarkerDetector:
    """Finds the pad's markers in an image and estimates each one's pose."""

    def __init__(self, *, pad: PadSpec, camera: CameraModel,
                 parameters: cv2.aruco.DetectorParameters | None = None) -> None:
        self.pad = pad
        self.camera = camera
        parameters = parameters or detector_parameters()
        dictionary = aruco_dictionary(pad.dictionary)
        self._refinement: _SubPixRefinement | None = None
        if parameters.cornerRefinementMethod == cv2.aruco.CORNER_REFINE_SUBPIX:
            self._refinement = _SubPixRefinement(
                relative_window=float(parameters.relativeCornerRefinmentWinSize),
                max_window_px=int(parameters.cornerRefinementWinSize),
                max_iterations=int(parameters.cornerRefinementMaxIterations),
                min_accuracy_px=float(parameters.cornerRefinementMinAccuracy),
                modules=dictionary.markerSize + 2 * int(parameters.markerBorderBits))
            unrefined = cv2.aruco.DetectorParameters()
            for name in dir(parameters):
                if not name.startswith("_") and not callable(getattr(parameters, name)):
                    setattr(unrefined, name, getattr(parameters, name))
            unrefined.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
            parameters = unrefined
        self.detector = cv2.aruco.ArucoDetector(dictionary, parameters)
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
        gray = _gray(image)
        corners, ids, _ = self.detector.detectMarkers(gray)
        return self._poses(gray, corners, ids, offset=(0.0, 0.0))

    def detect_frame(self, frame) -> list[MarkerDetection]:
        """`detect` on a camera frame (`Frame`, or a virtual camera's frame, drawn as it is read)."""
        return self.detect(frame.image)

    def _poses(self, gray: np.ndarray, corners, ids, *, offset: tuple[float, float]) -> list[MarkerDetection]:
        """Poses of the pad's markers among `corners` (pixels of `gray`, whose origin is at `offset` in the
        frame), refined to sub-pixel first when the parameters ask for it."""
        if ids is None:
            return []
        detections = []
        shift = np.array(offset, dtype=np.float64)
        for marker_corners, marker_id in zip(corners, ids.ravel().tolist()):
            marker = self._markers.get(marker_id)
            if marker is None:
                continue
            found = marker_corners.reshape(4, 2)
            if self._refinement is not None:
                image_points = self._refinement.refine(gray, found) + shift
            else:
                image_points = found.astype(np.float64) + shift
            ok, rvec, tvec = cv2.solvePnP(self._object_points[marker_id], image_points, self._k, self._dist,
                                          flags=cv2.SOLVEPNP_IPPE_SQUARE)
            # A degenerate fit (corners nearly collinear after refinement) can come back "ok" with NaNs.
            if not ok or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()) or tvec[2, 0] <= 0:
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
    so a window finds what the whole frame would find there, but for markers of
    a few pixels a cell: whether OpenCV reads the bits of a candidate outline
    can depend on where the marker lies in the image searched, and a window may
    then keep another outline of the same marker, a pixel apart before corner
    refinement. Given a virtual camera's frame (`detect_frame`), only the window
    is drawn.
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
        frame_side_px = max(width, height)
        # A virtual camera's frame knows where it draws the markers that can be found (those wholly in the
        # frame); beyond them there is only ground and cut-off markers, where the detector finds nothing, so
        # no search goes beyond them, nor is any pixel drawn there; a frame with none is not searched.
        extent = getattr(frame, "markers_extent_px", None)
        bounds = None
        if extent is not None:
            bounds = self._box_around(extent, (height, width)) if extent else None
            if bounds is None:
                self._window = None
                return []
        detections: list[MarkerDetection] = []
        if self._window is not None and self._frames % self.full_frame_every != 0:
            window = self._window if bounds is None else _intersection(self._window, bounds)
            if window is not None:
                detections = self._detect_in(frame, window, frame_side_px)
                if detections:
                    self.window_hits += 1
        if not detections:
            if bounds is None or bounds == (0, 0, width, height):
                detections = super().detect(frame.image)
            else:
                detections = self._detect_in(frame, bounds, frame_side_px)
        self._window = self._window_around(detections, (height, width)) if detections else None
        return detections

    def _detect_in(self, frame, region: tuple[int, int, int, int], frame_side_px: int) -> list[MarkerDetection]:
        x0, y0, x1, y1 = region
        gray = _gray(frame.region(x0, y0, x1, y1))
        corners, ids, _ = self._window_detector_for(x1 - x0, y1 - y0, frame_side_px).detectMarkers(gray)
        return self._poses(gray, corners, ids, offset=(float(x0), float(y0)))

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
        window = self._box_around((x_min, y_min, x_max, y_max), shape)
        height, width = shape[:2]
        if window is None or (window[2] - window[0]) * (window[3] - window[1]) > 0.6 * width * height:
            return None  # the window would be most of the frame: search the frame
        return window

    def _box_around(self, extent, shape) -> tuple[int, int, int, int] | None:
        """Twice `extent` (x0, y0, x1, y1; px) about its centre plus the margin, clipped to the frame; None
        when that misses the frame. (OpenCV's detector can miss a marker that fills much of the image it is
        given, so a search region is never cut tight around what it looks for.)"""
        x_min, y_min, x_max, y_max = extent
        half_w = (x_max - x_min) + self.margin_px
        half_h = (y_max - y_min) + self.margin_px
        cx, cy = (x_min + x_max) / 2.0, (y_min + y_max) / 2.0
        height, width = shape[:2]
        x0, x1 = max(0, int(cx - half_w)), min(width, int(cx + half_w) + 1)
        y0, y1 = max(0, int(cy - half_h)), min(height, int(cy + half_h) + 1)
        if x1 <= x0 or y1 <= y0:
            return None
        return x0, y0, x1, y1


def _intersection(a: tuple[int, int, int, int], b: tuple[int, int, int, int]) -> tuple[int, int, int, int] | None:
    x0, y0, x1, y1 = max(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), min(a[3], b[3])
    return (x0, y0, x1, y1) if x0 < x1 and y0 < y1 else None


def _gray(image: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image


def choose_smallest(detections: list[MarkerDetection]) -> MarkerDetection | None:
    """The smallest detected marker: the most precise one that is fully in view."""
    return min(detections, key=lambda d: (d.side_m, -d.marker_id)) if detections else None


def reading_from_detection(detection: MarkerDetection, *, capture_time_s: float) -> TargetReading:
    angle_x, angle_y = detection.angles_rad()
    return TargetReading(sensor="marker", capture_time_s=capture_time_s, angle_x_rad=angle_x, angle_y_rad=angle_y,
                         distance_m=detection.distance_m, marker_id=detection.marker_id)

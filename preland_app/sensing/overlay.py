"""Detection overlays for bench checks: marker outlines and ids, the chosen marker's axes, the angles."""

from __future__ import annotations

import math

import cv2
import numpy as np

from .camera import CameraModel
from .marker import MarkerDetection, choose_smallest


def draw_detections(image: np.ndarray, detections: list[MarkerDetection], camera: CameraModel) -> np.ndarray:
    """A BGR copy of `image` with every detection outlined, the chosen one's axes and its angles."""
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    chosen = choose_smallest(detections)
    for detection in detections:
        corners = detection.corners_px.astype(np.int32).reshape(-1, 1, 2)
        color = (0, 200, 0) if detection is chosen else (0, 160, 255)
        cv2.polylines(canvas, [corners], True, color, 2)
        x, y = detection.corners_px[0]
        cv2.putText(canvas, f"id {detection.marker_id}", (int(x), int(y) - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                    color, 1, cv2.LINE_AA)
    if chosen is not None:
        cv2.drawFrameAxes(canvas, camera.camera_matrix, camera.dist_coeffs, chosen.rvec, chosen.tvec,
                          chosen.side_m / 2.0)
        angle_x, angle_y = (math.degrees(a) for a in chosen.angles_rad())
        text = f"chosen id {chosen.marker_id}  x {angle_x:+.2f} deg  y {angle_y:+.2f} deg  {chosen.distance_m:.2f} m"
        cv2.putText(canvas, text, (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 200, 0), 1, cv2.LINE_AA)
    return canvas

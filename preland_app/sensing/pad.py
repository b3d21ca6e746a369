"""Landing pads: ArUco markers and an IR beacon, laid out on the ground.

Pad frame: origin at the pad's centre (the point a precision landing aims at),
x north and y east when the pad's yaw is 0, metres. A marker's `yaw_deg`
turns it about the pad's vertical axis. Presets:

* `thesis`: a DICT_4X4_50 marker (id 16, 0.60 m) whose central 2x2 cells are
  white, with a 0.09 m marker (id 0) nested in that white area, and the IR
  beacon at the centre, as the thesis' Section 8.2.1 describes. The outer
  marker fills 53 px at 6 m and is detected from 10 m down to about 5 m; the
  inner one from about 4 m down to touchdown (once it is resolved it hides
  the outer marker's central bits), so one of the two is always in view.
* `paper`: DICT_6X6_250, a 0.56 m marker (id 0) and a 0.18 m marker (id 1,
  higher id = smaller, as the paper's algorithms expect); the small marker is
  at the pad's centre and the large one beside it (centres 0.45 m apart,
  8 cm of white between them, a white margin of at least a cell around each).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import SpecError, require
from ..config.loader import build, read_yaml_mapping

DICTIONARIES = {
    "DICT_4X4_50": cv2.aruco.DICT_4X4_50,
    "DICT_4X4_100": cv2.aruco.DICT_4X4_100,
    "DICT_5X5_100": cv2.aruco.DICT_5X5_100,
    "DICT_6X6_250": cv2.aruco.DICT_6X6_250,
    "DICT_7X7_250": cv2.aruco.DICT_7X7_250,
    "DICT_ARUCO_ORIGINAL": cv2.aruco.DICT_ARUCO_ORIGINAL,
}


def aruco_dictionary(name: str) -> cv2.aruco.Dictionary:
    return cv2.aruco.getPredefinedDictionary(DICTIONARIES[name])


@dataclass(frozen=True)
class MarkerSpec:
    """One ArUco marker on the pad: id, side length in m (black border included), centre and yaw on the pad."""

    id: int
    side_m: float
    center_m: tuple[float, float] = (0.0, 0.0)
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        require(self.id >= 0, "id", "must be >= 0")
        require(0.01 <= self.side_m <= 5.0, "side_m", "must be within 0.01..5 m")


@dataclass(frozen=True)
class PadSpec:
    """A landing pad. `size_m` is the printed sheet's side (white background)."""

    name: str
    dictionary: str
    markers: tuple[MarkerSpec, ...]
    beacon_m: tuple[float, float] | None = (0.0, 0.0)
    size_m: float = 1.0

    def __post_init__(self) -> None:
        require(self.dictionary in DICTIONARIES, "dictionary",
                f"unknown ArUco dictionary (expected one of: {', '.join(DICTIONARIES)})")
        require(len(self.markers) > 0, "markers", "needs at least one marker")
        ids = [m.id for m in self.markers]
        require(len(set(ids)) == len(ids), "markers", "marker ids must be unique")
        limit = aruco_dictionary(self.dictionary).bytesList.shape[0]
        for i, marker in enumerate(self.markers):
            require(marker.id < limit, f"markers[{i}].id", f"{self.dictionary} has ids 0..{limit - 1}")
        require(0.05 <= self.size_m <= 10.0, "size_m", "must be within 0.05..10 m")

    def marker(self, marker_id: int) -> MarkerSpec | None:
        return next((m for m in self.markers if m.id == marker_id), None)

    def marker_corners_pad_m(self, marker: MarkerSpec) -> np.ndarray:
        """The marker's corners in the pad frame (x north, y east), in ArUco order:
        top-left, top-right, bottom-right, bottom-left, where 'top' faces pad north."""
        half = marker.side_m / 2.0
        # Marker-local (x right = east, y up = north) corners, ArUco order.
        local = np.array([[-half, half], [half, half], [half, -half], [-half, -half]])
        yaw = math.radians(marker.yaw_deg)
        c, s = math.cos(yaw), math.sin(yaw)
        east = local[:, 0] * c - local[:, 1] * s
        north = local[:, 0] * s + local[:, 1] * c
        return np.stack([north + marker.center_m[0], east + marker.center_m[1]], axis=1)


THESIS_PAD = PadSpec(
    name="thesis",
    dictionary="DICT_4X4_50",
    markers=(MarkerSpec(id=16, side_m=0.60), MarkerSpec(id=0, side_m=0.09)),
    beacon_m=(0.0, 0.0),
    size_m=0.80,
)

PAPER_PAD = PadSpec(
    name="paper",
    dictionary="DICT_6X6_250",
    markers=(MarkerSpec(id=0, side_m=0.56, center_m=(0.45, 0.0)), MarkerSpec(id=1, side_m=0.18)),
    beacon_m=None,
    size_m=1.80,
)

PAD_PRESETS = {"thesis": THESIS_PAD, "paper": PAPER_PAD}


def load_pad(reference: str) -> PadSpec:
    """A preset name (`thesis`, `paper`) or a YAML file with PadSpec's fields."""
    if reference in PAD_PRESETS:
        return PAD_PRESETS[reference]
    if not reference.endswith((".yaml", ".yml")):
        raise SpecError(path=reference, field="pad",
                        problem=f"unknown pad preset (expected one of: {', '.join(PAD_PRESETS)}, or a .yaml file)")
    return build(PadSpec, read_yaml_mapping(reference), path=reference)


def render_pad_texture(pad: PadSpec, *, pixels_per_m: float) -> np.ndarray:
    """The pad seen from above (north up), grayscale uint8, white background, `pixels_per_m` resolution.

    Pixel (row, col) centre maps to pad (x north, y east) =
    (size/2 - (row + 0.5)/ppm, -size/2 + (col + 0.5)/ppm).
    """
    size_px = int(round(pad.size_m * pixels_per_m))
    image = np.full((size_px, size_px), 255, np.uint8)
    dictionary = aruco_dictionary(pad.dictionary)
    # Larger markers first, so nested ones are drawn on top.
    for marker in sorted(pad.markers, key=lambda m: -m.side_m):
        cells = dictionary.markerSize + 2
        side_px = max(cells, int(round(marker.side_m * pixels_per_m / cells)) * cells)
        marker_img = cv2.aruco.generateImageMarker(dictionary, marker.id, side_px)
        corners = pad.marker_corners_pad_m(marker)
        dst = np.stack([(corners[:, 1] + pad.size_m / 2) * pixels_per_m,
                        (pad.size_m / 2 - corners[:, 0]) * pixels_per_m], axis=1).astype(np.float32)
        src = np.array([[0, 0], [side_px, 0], [side_px, side_px], [0, side_px]], np.float32)
        warp = cv2.getPerspectiveTransform(src, dst)
        mask = cv2.warpPerspective(np.full_like(marker_img, 255), warp, (size_px, size_px), flags=cv2.INTER_NEAREST)
        warped = cv2.warpPerspective(marker_img, warp, (size_px, size_px), flags=cv2.INTER_AREA)
        image[mask > 0] = warped[mask > 0]
    return image

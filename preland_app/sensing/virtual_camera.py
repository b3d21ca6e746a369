"""The virtual camera: renders the ground (a textured field with the pad on it) from the true pose.

Rendering is a plane-to-image homography (OpenCV warpPerspective) per layer:
a grass texture covering the whole field (drawn in tiles as frames first
read them: `ground_texture`) and a pyramid of pad
textures from which the level closest to the image's ground resolution is
used (so the pad stays sharp up close and is not aliased from high up). Lens
distortion, sensor noise, blur and exposure changes are applied on top. The
pose comes from ground truth; what leaves this module is only an image.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..geo import ned_from_body_rows
from .camera import R_CAM_FROM_BODY, CameraModel
from .ground_texture import FIELD_EXTENT_M, FIELD_PX_PER_M, GrassTexture, texels_read_by
from .pad import PadSpec, render_pad_texture

_PAD_MAX_PX_PER_M = 1600.0
_MIN_LENS_HEIGHT_M = 0.08
_MAP_STEP_PX = 8


@dataclass(frozen=True)
class ImageEffects:
    """Optional image degradations. `noise_sigma`: Gaussian pixel noise (grey levels);
    `blur_px`: Gaussian blur sigma in pixels; `exposure_gain`: brightness scale (1 = none)."""

    noise_sigma: float = 2.0
    blur_px: float = 0.0
    exposure_gain: float = 1.0


@dataclass(frozen=True, slots=True)
class CameraPose:
    """The vehicle's true pose: position NED in m (origin on the ground plane), attitude in rad."""

    north_m: float
    east_m: float
    down_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


def rotation_ned_from_body(roll_rad: float, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """ZYX Euler rotation taking body FRD vectors to NED."""
    return np.array(ned_from_body_rows(roll_rad, pitch_rad, yaw_rad))


def camera_extrinsics(camera: CameraModel, pose: CameraPose) -> tuple[np.ndarray, np.ndarray]:
    """(R_cam_from_ned, camera centre NED in m) for the true pose."""
    r_ned_body = rotation_ned_from_body(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
    centre = np.array([pose.north_m, pose.east_m, pose.down_m]) + r_ned_body @ np.array(camera.mount_offset_frd_m)
    return R_CAM_FROM_BODY @ r_ned_body.T, centre


@dataclass(frozen=True, slots=True, kw_only=True)
class Shot:
    """One frame as captured, before any pixel is drawn: image -> texture homographies (px) of the
    background and of the pad's pyramid level, the pad frame (north, east, 1; m) -> image homography, the
    sensor-noise draw (bank index, row, column offset), and `markers_extent_px`: the box (x0, y0, x1, y1;
    image px, unclipped, so possibly off the image) that holds every pixel of the markers a detector can
    find, those wholly in the frame (OpenCV rejects any candidate that reaches the image's border); through
    lens distortion, the whole pad's extent (`VirtualCamera.pad_extent_px`); () when there is none; None when
    it cannot be bounded.
    """

    image_to_background: np.ndarray
    image_to_pad: np.ndarray
    pad_to_image: np.ndarray
    noise: tuple[int, int, int] | None
    pad_texture: np.ndarray
    markers_extent_px: tuple[float, float, float, float] | tuple[()] | None = None


class VirtualCamera:
    """Renders grayscale frames of the pad lying at `pad_origin_ned_m` (north, east) on flat ground."""

    def __init__(
        self,
        *,
        camera: CameraModel,
        pad: PadSpec,
        pad_origin_ned_m: tuple[float, float],
        pad_yaw_deg: float = 0.0,
        rng: np.random.Generator,
        effects: ImageEffects = ImageEffects(),
    ) -> None:
        self.camera = camera
        self.pad = pad
        self.pad_origin_ned_m = pad_origin_ned_m
        self.pad_yaw_rad = math.radians(pad_yaw_deg)
        self.effects = effects
        self._rng = rng
        self._k = camera.camera_matrix
        self._size = (camera.width_px, camera.height_px)
        self._ground = GrassTexture(rng=rng)
        self._undistort_maps = self._make_distortion_maps() if camera.has_distortion else None
        self._pad_outline = _pad_outline_m(pad)
        # Every marker's corners, pad frame (north, east, 1), one column each, four per marker.
        corners = np.vstack([pad.marker_corners_pad_m(marker) for marker in pad.markers])
        self._markers_corners_h = np.vstack([corners.T, np.ones(len(corners))])
        # The parts of each frame's homographies that do not depend on the pose, built once per camera.
        half = FIELD_EXTENT_M / 2.0
        ppm = FIELD_PX_PER_M
        self._bg_to_ground = np.array([[0.0, -1.0 / ppm, half], [1.0 / ppm, 0.0, -half], [0.0, 0.0, 1.0]])
        c, s = math.cos(self.pad_yaw_rad), math.sin(self.pad_yaw_rad)
        self._pad_rotate = np.array([[c, -s, pad_origin_ned_m[0]], [s, c, pad_origin_ned_m[1]], [0.0, 0.0, 1.0]])
        size_m = pad.size_m
        # Per pyramid level, from the finest: (px per m, texture, pad texture pixel -> pad frame (north, east)).
        self._pad_level_maps = tuple(
            (level_ppm, texture, np.array([[0.0, -1.0 / level_ppm, size_m / 2.0],
                                           [1.0 / level_ppm, 0.0, -size_m / 2.0],
                                           [0.0, 0.0, 1.0]]))
            for level_ppm, texture in self._make_pad_pyramid(pad))
        # The sources in the ideal image of every 8th pixel (and the last row and column), to bound where lens
        # distortion draws a region; a box narrower than twice their widest spacing is not bounded.
        self._map_samples = None
        if self._undistort_maps is not None:
            w, h = self._size
            cols = np.unique(np.r_[np.arange(0, w, _MAP_STEP_PX), w - 1])
            rows = np.unique(np.r_[np.arange(0, h, _MAP_STEP_PX), h - 1])
            map_x, map_y = (m[np.ix_(rows, cols)] for m in self._undistort_maps)
            # Sources beyond the ideal image read it reflected (cv2.BORDER_REFLECT, as `render_shot` remaps).
            map_x, map_y = _reflected(map_x, w), _reflected(map_y, h)
            spacing = max(float(np.abs(np.diff(map_x, axis=1)).max()), float(np.abs(np.diff(map_y, axis=0)).max()))
            self._map_samples = (map_x, map_y, rows, cols, spacing)
        h, w = camera.height_px + 32, camera.width_px + 32
        # OpenCV's Gaussian kernel for 8-bit images reaches round(3 sigma) px; one more for rounding.
        self._blur_radius_px = math.ceil(3.0 * effects.blur_px) + 1 if effects.blur_px > 0 else 0
        if effects.noise_sigma > 0:
            levels = _rounded_normal_levels(effects.noise_sigma)
            self._noise_bank = [levels[rng.integers(0, len(levels), size=(h, w), dtype=np.uint16)] for _ in range(4)]
        else:
            self._noise_bank = []

    # ---------------------------------------------------------------- textures

    @staticmethod
    @functools.lru_cache(maxsize=8)
    def _make_pad_pyramid(pad: PadSpec) -> tuple[tuple[float, np.ndarray], ...]:
        """The pad's textures from `_PAD_MAX_PX_PER_M` down, halving; shared (read-only) by every camera
        that sees the same pad, since a trial's camera would otherwise redraw it."""
        levels = []
        ppm = _PAD_MAX_PX_PER_M
        texture = render_pad_texture(pad, pixels_per_m=ppm)
        while True:
            texture.flags.writeable = False
            levels.append((ppm, texture))
            if texture.shape[0] < 32:
                break
            texture = cv2.pyrDown(texture)
            ppm /= 2.0
        return tuple(levels)

    def _make_distortion_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """For each distorted output pixel, where it falls in the ideal pinhole image."""
        w, h = self._size
        grid = np.stack(np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32)), -1)
        undistorted = cv2.undistortPoints(grid.reshape(-1, 1, 2), self._k, self.camera.dist_coeffs, P=self._k)
        maps = undistorted.reshape(h, w, 2)
        return maps[..., 0].copy(), maps[..., 1].copy()

    # ---------------------------------------------------------------- rendering

    def _ground_homography(self, pose: CameraPose) -> np.ndarray:
        """3x3 homography from ground (north, east, 1) to image pixels."""
        r, centre = camera_extrinsics(self.camera, pose)
        # The lens sits above the landing gear: never closer to the ground than this.
        centre[2] = min(centre[2], -_MIN_LENS_HEIGHT_M)
        t = -r @ centre
        return self._k @ np.column_stack([r[:, 0], r[:, 1], t])

    def capture(self, pose: CameraPose) -> Shot:
        """Everything a frame seen from `pose` depends on, fixed now (the pixels come later, and only those
        asked for): the layers' homographies, the pad's pyramid level and this frame's sensor-noise draw."""
        ground_to_image = self._ground_homography(pose)
        # Background: texture pixel (col, row) -> ground (north, east), field centred on the origin.
        image_to_bg = np.linalg.inv(ground_to_image @ self._bg_to_ground)
        # Pad: the coarsest pyramid level that still has twice the image's ground resolution
        # (sharp edges for the detector, no aliasing from high up).
        height_m = max(0.05, -pose.down_m)
        image_ppm = self.camera.fx_px / height_m
        levels = self._pad_level_maps
        _, texture, pad_to_ground_local = levels[0]
        for candidate_ppm, candidate, candidate_map in levels:
            if candidate_ppm >= 2.0 * image_ppm:
                texture, pad_to_ground_local = candidate, candidate_map
        pad_to_image = ground_to_image @ self._pad_rotate
        image_to_pad = np.linalg.inv(pad_to_image @ pad_to_ground_local)
        noise = None
        if self.effects.noise_sigma > 0:
            # Sensor noise: one of a bank of pre-drawn noise fields, shifted by a random offset
            # (drawing 300k normals per frame would cost more than rendering it).
            index = int(self._rng.integers(len(self._noise_bank)))
            dy, dx = self._rng.integers(0, 32, size=2).tolist()
            noise = (index, dy, dx)
        return Shot(image_to_background=image_to_bg, image_to_pad=image_to_pad, pad_texture=texture, noise=noise,
                    pad_to_image=pad_to_image,
                    markers_extent_px=(self._markers_extent_px(pad_to_image) if self._map_samples is None
                                       else self._pad_extent_px(pad_to_image)))

    def pad_extent_px(self, shot: Shot) -> tuple[float, float, float, float] | tuple[()] | None:
        """The box (x0, y0, x1, y1; image px, unclipped) holding every pixel the pad (its printed sheet,
        markers and all) is drawn into in `shot`; () when no part of it is in the frame; None when it cannot
        be bounded (part of the pad behind the camera, or too small to bound through the lens distortion)."""
        return self._pad_extent_px(shot.pad_to_image)

    def _markers_extent_px(self, pad_to_image: np.ndarray) -> tuple[float, float, float, float] | tuple[()]:
        """The box (pinhole image px) drawn into by the markers wholly in the frame; () when there are none."""
        # In Python floats: a handful of corners, where numpy's per-call cost would be most of the work.
        xs, ys, depths = (pad_to_image @ self._markers_corners_h).tolist()
        w, h = self._size
        spread = 2.0 + self._blur_radius_px
        box = None
        for start in range(0, len(xs), 4):
            depth = depths[start:start + 4]
            if min(depth) <= 1e-6:
                continue
            u = [x / d for x, d in zip(xs[start:start + 4], depth)]
            v = [y / d for y, d in zip(ys[start:start + 4], depth)]
            u0, v0, u1, v1 = min(u), min(v), max(u), max(v)
            if u0 < -1.0 or v0 < -1.0 or u1 > w or v1 > h:
                continue  # reaches past the frame's edge: no detector finds it
            box = (u0, v0, u1, v1) if box is None else (min(box[0], u0), min(box[1], v0),
                                                         max(box[2], u1), max(box[3], v1))
        if box is None:
            return ()
        return box[0] - spread, box[1] - spread, box[2] + spread, box[3] + spread

    def _pad_extent_px(self, pad_to_image: np.ndarray) -> tuple[float, float, float, float] | tuple[()] | None:
        """The image box the pad is drawn into (see `pad_extent_px`). Straight edges stay straight in the
        ideal image, so the corners bound them there; lens distortion is bounded through its sampled maps,
        one sampling step wider on each side."""
        outline = self._pad_outline
        projected = pad_to_image @ np.vstack([outline.T, np.ones(len(outline))])
        if projected[2].min() <= 1e-6:
            return None
        u, v = projected[0] / projected[2], projected[1] / projected[2]
        # A pixel reads the texture up to a pixel around it (bilinear warp); a corner may also round outwards.
        # Blur spreads them by its kernel's reach.
        spread = 2.0 + self._blur_radius_px
        box = (float(u.min()) - spread, float(v.min()) - spread, float(u.max()) + spread, float(v.max()) + spread)
        if self._map_samples is None:
            w, h = self._size
            return () if box[2] < 0 or box[3] < 0 or box[0] > w or box[1] > h else box
        map_x, map_y, rows, cols, spacing = self._map_samples
        if box[2] - box[0] < 2.0 * spacing or box[3] - box[1] < 2.0 * spacing:
            return None
        box = (box[0] + self._blur_radius_px, box[1] + self._blur_radius_px,  # blur is applied after the lens
               box[2] - self._blur_radius_px, box[3] - self._blur_radius_px)
        inside = (map_x >= box[0]) & (map_x <= box[2]) & (map_y >= box[1]) & (map_y <= box[3])
        if not inside.any():
            return ()  # wholly outside the frame
        hit_rows, hit_cols = np.nonzero(inside)
        reach = _MAP_STEP_PX + self._blur_radius_px
        return (float(cols[hit_cols.min()] - reach), float(rows[hit_rows.min()] - reach),
                float(cols[hit_cols.max()] + reach), float(rows[hit_rows.max()] + reach))

    def render(self, pose: CameraPose) -> np.ndarray:
        """One grayscale frame (height x width, uint8) seen from `pose`."""
        return self.render_shot(self.capture(pose))

    def render_shot(self, shot: Shot, region: tuple[int, int, int, int] | None = None) -> np.ndarray:
        """The pixels of `shot` in `region` (x0, y0, x1, y1; px, end exclusive; default the whole frame):
        exactly the same pixels as the whole frame cropped there. Each layer is warped straight into the
        region with its homography shifted by the region's origin; blur and lens distortion widen what is
        warped by what they read around each pixel; the noise is the same field at the same offsets."""
        w, h = self._size
        x0, y0, x1, y1 = region if region is not None else (0, 0, w, h)
        radius = self._blur_radius_px
        blurred = (max(0, x0 - radius), max(0, y0 - radius), min(w, x1 + radius), min(h, y1 + radius))
        if self._undistort_maps is not None:
            ideal = self._ideal_region(blurred)
            frame = self._warp_layers(shot, ideal)
            bx0, by0, bx1, by1 = blurred
            map_x = self._undistort_maps[0][by0:by1, bx0:bx1]
            map_y = self._undistort_maps[1][by0:by1, bx0:bx1]
            if ideal[0] or ideal[1]:
                map_x, map_y = map_x - np.float32(ideal[0]), map_y - np.float32(ideal[1])
            frame = cv2.remap(frame, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        else:
            frame = self._warp_layers(shot, blurred)
        effects = self.effects
        if effects.blur_px > 0:
            frame = cv2.GaussianBlur(frame, (0, 0), effects.blur_px)
        if blurred != (x0, y0, x1, y1):
            frame = frame[y0 - blurred[1]:y1 - blurred[1], x0 - blurred[0]:x1 - blurred[0]]
        if effects.exposure_gain != 1.0:
            frame = cv2.convertScaleAbs(frame, alpha=effects.exposure_gain)
        if shot.noise is not None:
            index, dy, dx = shot.noise
            noise = self._noise_bank[index][dy + y0:dy + y1, dx + x0:dx + x1]
            # The 8-bit frame plus the int16 noise, saturated to 0..255 in one pass (numpy's widen, add, clip
            # and narrow give the same pixels in four).
            frame = cv2.add(frame, noise, dtype=cv2.CV_8U)
        return np.ascontiguousarray(frame)

    def _warp_layers(self, shot: Shot, region: tuple[int, int, int, int]) -> np.ndarray:
        """Background then pad, warped into `region` of the ideal (undistorted) image."""
        x0, y0, x1, y1 = region
        size = (x1 - x0, y1 - y0)
        image_to_bg, image_to_pad = shot.image_to_background, shot.image_to_pad
        if x0 or y0:
            shift = np.array([[1.0, 0.0, x0], [0.0, 1.0, y0], [0.0, 0.0, 1.0]])
            image_to_bg, image_to_pad = image_to_bg @ shift, image_to_pad @ shift
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        rows, cols = shot.pad_texture.shape[:2]
        pad_box = texels_read_by(image_to_pad, size)
        if pad_box is not None and pad_box[0] >= 0 and pad_box[1] >= 0 and pad_box[2] < cols and pad_box[3] < rows:
            # Every pixel reads the pad's texture: BORDER_TRANSPARENT then leaves none unwritten, so no ground
            # is drawn under it (a tracking window on a marker at close range).
            frame = np.empty((size[1], size[0]), dtype=np.uint8)
        else:
            self._ground.ensure_read_by(image_to_bg, size)
            frame = cv2.warpPerspective(self._ground.pixels, image_to_bg, size, flags=flags,
                                        borderMode=cv2.BORDER_REFLECT)
        # BORDER_TRANSPARENT leaves the background wherever the pad texture does not reach.
        cv2.warpPerspective(shot.pad_texture, image_to_pad, size, dst=frame, flags=flags,
                            borderMode=cv2.BORDER_TRANSPARENT)
        return frame

    def _ideal_region(self, region: tuple[int, int, int, int]) -> tuple[int, int, int, int]:
        """The part of the ideal image that lens distortion reads for `region` of the output: the bilinear
        taps around each pixel's source point; the whole image when a tap falls outside it (the border is
        then reflected about the image's own edge)."""
        w, h = self._size
        x0, y0, x1, y1 = region
        if (x0, y0, x1, y1) == (0, 0, w, h):
            return region
        map_x = self._undistort_maps[0][y0:y1, x0:x1]
        map_y = self._undistort_maps[1][y0:y1, x0:x1]
        ix0, ix1 = math.floor(float(map_x.min())) - 1, math.floor(float(map_x.max())) + 3
        iy0, iy1 = math.floor(float(map_y.min())) - 1, math.floor(float(map_y.max())) + 3
        if ix0 < 0 or iy0 < 0 or ix1 > w or iy1 > h:
            return 0, 0, w, h
        return ix0, iy0, ix1, iy1


class RenderedFrame:
    """A virtual camera frame, captured (pose, noise draw) but drawn only when read: `image` renders the
    whole frame once; `region()` renders only the part asked for (the same pixels as `image` there, to
    within the warp's rounding), or crops `image` when it is already drawn. Same interface as `Frame`."""

    __slots__ = ("_renderer", "_shot", "_image", "capture_time_s", "index")

    def __init__(self, *, renderer: VirtualCamera, shot: Shot, capture_time_s: float, index: int) -> None:
        self._renderer = renderer
        self._shot = shot
        self._image: np.ndarray | None = None
        self.capture_time_s = capture_time_s
        self.index = index

    @property
    def image(self) -> np.ndarray:
        if self._image is None:
            self._image = self._renderer.render_shot(self._shot)
        return self._image

    @property
    def size_px(self) -> tuple[int, int]:
        return self._renderer.camera.width_px, self._renderer.camera.height_px

    def preset_image(self, image: np.ndarray) -> None:
        """Take `image` as this frame's drawing (the whole frame, already drawn from the same shot)."""
        self._image = image

    @property
    def markers_extent_px(self) -> tuple[float, float, float, float] | tuple[()] | None:
        """The box (x0, y0, x1, y1; image px, unclipped) holding every marker a detector can find in this
        frame, () when there is none, None when the frame cannot say (see `Shot`)."""
        return self._shot.markers_extent_px

    def region(self, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
        if self._image is not None:
            return np.ascontiguousarray(self._image[y0:y1, x0:x1])
        return self._renderer.render_shot(self._shot, (x0, y0, x1, y1))


@functools.lru_cache(maxsize=4)
def _rounded_normal_levels(sigma: float) -> np.ndarray:
    """A table of 65536 int16 values whose uniform draw is round(N(0, sigma^2)) to within 1/65536 in each
    level's probability (tails beyond that truncated): sensor noise in whole grey levels, from 2 bytes of
    random stream a pixel instead of a Gaussian draw."""
    count = 65536
    reach = int(math.ceil(8.0 * sigma)) + 1
    levels = np.arange(-reach, reach + 1)
    upper = np.array([0.5 * (1.0 + math.erf((k + 0.5) / (sigma * math.sqrt(2.0)))) for k in levels])
    # Slot i (of `count`) takes the level whose cumulative probability first exceeds the slot's centre.
    index = np.searchsorted(upper * count, np.arange(count) + 0.5, side="right")
    table = levels[np.minimum(index, len(levels) - 1)].astype(np.int16)
    table.flags.writeable = False
    return table


def _pad_outline_m(pad: PadSpec) -> np.ndarray:
    """The corners of the pad's printed sheet, pad frame (north, east) in m, one row each."""
    half = pad.size_m / 2.0
    return np.array([[half, -half], [half, half], [-half, half], [-half, -half]])


def _reflected(coordinates: np.ndarray, size_px: int) -> np.ndarray:
    """Pixel coordinates folded into 0..size_px-1 as cv2.BORDER_REFLECT folds them (edge pixel repeated)."""
    period = 2.0 * size_px
    folded = np.mod(coordinates + 0.5, period)
    return np.where(folded < size_px, folded, period - folded) - 0.5

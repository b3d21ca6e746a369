"""The virtual camera: renders the ground (a textured field with the pad on it) from the true pose.

Rendering is a plane-to-image homography (OpenCV warpPerspective) per layer:
a coarse background texture covering the whole field and a pyramid of pad
textures from which the level closest to the image's ground resolution is
used (so the pad stays sharp up close and is not aliased from high up). Lens
distortion, sensor noise, blur and exposure changes are applied on top. The
pose comes from ground truth; what leaves this module is only an image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .camera import R_CAM_FROM_BODY, CameraModel
from .pad import PadSpec, render_pad_texture

_BACKGROUND_EXTENT_M = 80.0
_BACKGROUND_PX_PER_M = 24.0
_PAD_MAX_PX_PER_M = 1600.0
_MIN_LENS_HEIGHT_M = 0.08


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
    cr, sr = math.cos(roll_rad), math.sin(roll_rad)
    cp, sp = math.cos(pitch_rad), math.sin(pitch_rad)
    cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([
        [cp * cy, sr * sp * cy - cr * sy, cr * sp * cy + sr * sy],
        [cp * sy, sr * sp * sy + cr * cy, cr * sp * sy - sr * cy],
        [-sp, sr * cp, cr * cp],
    ])


def camera_extrinsics(camera: CameraModel, pose: CameraPose) -> tuple[np.ndarray, np.ndarray]:
    """(R_cam_from_ned, camera centre NED in m) for the true pose."""
    r_ned_body = rotation_ned_from_body(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
    centre = np.array([pose.north_m, pose.east_m, pose.down_m]) + r_ned_body @ np.array(camera.mount_offset_frd_m)
    return R_CAM_FROM_BODY @ r_ned_body.T, centre


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
        self._background = self._make_background(rng)
        self._pad_levels = self._make_pad_pyramid(pad)
        self._undistort_maps = self._make_distortion_maps() if camera.has_distortion else None
        h, w = camera.height_px + 32, camera.width_px + 32
        self._noise_bank = [
            np.round(rng.standard_normal((h, w), dtype=np.float32) * effects.noise_sigma).astype(np.int16)
            for _ in range(4)
        ] if effects.noise_sigma > 0 else []

    # ---------------------------------------------------------------- textures

    @staticmethod
    def _make_background(rng: np.random.Generator) -> np.ndarray:
        """Grass-like texture: smoothed noise at a few scales, mid grey, low contrast."""
        size = int(_BACKGROUND_EXTENT_M * _BACKGROUND_PX_PER_M)
        texture = np.zeros((size, size), np.float32)
        for cells, weight in ((size // 64, 30.0), (size // 8, 18.0), (size, 10.0)):
            small = rng.standard_normal((cells, cells)).astype(np.float32)
            texture += weight * cv2.resize(small, (size, size), interpolation=cv2.INTER_CUBIC)
        return np.clip(110.0 + texture, 40, 190).astype(np.uint8)

    @staticmethod
    def _make_pad_pyramid(pad: PadSpec) -> list[tuple[float, np.ndarray]]:
        levels = []
        ppm = _PAD_MAX_PX_PER_M
        texture = render_pad_texture(pad, pixels_per_m=ppm)
        while True:
            levels.append((ppm, texture))
            if texture.shape[0] < 32:
                break
            texture = cv2.pyrDown(texture)
            ppm /= 2.0
        return levels

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

    def render(self, pose: CameraPose) -> np.ndarray:
        """One grayscale frame (height x width, uint8) seen from `pose`."""
        ground_to_image = self._ground_homography(pose)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        # Background: texture pixel (col, row) -> ground (north, east), field centred on the origin.
        half = _BACKGROUND_EXTENT_M / 2.0
        ppm = _BACKGROUND_PX_PER_M
        bg_to_ground = np.array([[0.0, -1.0 / ppm, half], [1.0 / ppm, 0.0, -half], [0.0, 0.0, 1.0]])
        image_to_bg = np.linalg.inv(ground_to_image @ bg_to_ground)
        frame = cv2.warpPerspective(self._background, image_to_bg, self._size, flags=flags,
                                    borderMode=cv2.BORDER_REFLECT)
        # Pad: the coarsest pyramid level that still has twice the image's ground resolution
        # (sharp edges for the detector, no aliasing from high up).
        height_m = max(0.05, -pose.down_m)
        image_ppm = self.camera.fx_px / height_m
        level_ppm, texture = self._pad_levels[0]
        for candidate_ppm, candidate in self._pad_levels:
            if candidate_ppm >= 2.0 * image_ppm:
                level_ppm, texture = candidate_ppm, candidate
        size_m = self.pad.size_m
        c, s = math.cos(self.pad_yaw_rad), math.sin(self.pad_yaw_rad)
        pad_to_ground_local = np.array([[0.0, -1.0 / level_ppm, size_m / 2.0],
                                        [1.0 / level_ppm, 0.0, -size_m / 2.0],
                                        [0.0, 0.0, 1.0]])
        rotate = np.array([[c, -s, self.pad_origin_ned_m[0]], [s, c, self.pad_origin_ned_m[1]], [0.0, 0.0, 1.0]])
        image_to_pad = np.linalg.inv(ground_to_image @ rotate @ pad_to_ground_local)
        # BORDER_TRANSPARENT leaves the background wherever the pad texture does not reach.
        cv2.warpPerspective(texture, image_to_pad, self._size, dst=frame, flags=flags,
                            borderMode=cv2.BORDER_TRANSPARENT)
        return self._apply_effects(frame)

    def _apply_effects(self, frame: np.ndarray) -> np.ndarray:
        if self._undistort_maps is not None:
            frame = cv2.remap(frame, self._undistort_maps[0], self._undistort_maps[1], cv2.INTER_LINEAR,
                              borderMode=cv2.BORDER_REFLECT)
        effects = self.effects
        if effects.blur_px > 0:
            frame = cv2.GaussianBlur(frame, (0, 0), effects.blur_px)
        if effects.exposure_gain != 1.0:
            frame = cv2.convertScaleAbs(frame, alpha=effects.exposure_gain)
        if effects.noise_sigma > 0:
            # Sensor noise: one of a bank of pre-drawn noise fields, shifted by a random offset
            # (drawing 300k normals per frame would cost more than rendering it).
            index = int(self._rng.integers(len(self._noise_bank)))
            dy, dx = (int(v) for v in self._rng.integers(0, 32, size=2))
            noise = self._noise_bank[index][dy:dy + frame.shape[0], dx:dx + frame.shape[1]]
            frame = np.clip(frame.astype(np.int16) + noise, 0, 255).astype(np.uint8)
        return frame

"""IR-LOCK sensor model: angles to the IR beacon at 50 Hz, with noise, no range.

Visibility follows the sensor's field of view (Pixy with the 3.6 mm lens:
about 60 x 47 deg) and the beacon's reach, shaped as ArduPilot's simulated
precision-landing device (SIM_PLD_TYPE cone or cylinder, SIM_PLD_ALT_LMT,
SIM_PLD_DIST_LMT). The model takes the true pose from the runtime (simulator
or SITL); what it returns is only a reading.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np

from ..errors import require
from ..geo import body_to_ned, ned_from_body_rows
from .readings import TargetReading, angles_from_camera_point
from .virtual_camera import CameraPose


class BeaconShape(enum.Enum):
    """Where the beacon can be seen from, as SIM_PLD_TYPE (0 cylinder, 1 cone)."""

    CYLINDER = "cylinder"
    CONE = "cone"


@dataclass(frozen=True)
class IrLockSpec:
    """IR-LOCK defaults: 50 Hz (thesis Section 3.4), beacon seen within 15 m height (MarkOne,
    SIM_PLD_ALT_LMT) and, at that height, 10 m sideways (SIM_PLD_DIST_LMT, cone).

    `pixels`: the Pixy's block output grid (320 x 200, Charmed Labs); a reading is the block's
    integer pixel centre turned into angles with the IR-LOCK driver's scale (60 x 35 deg over that
    grid, `driver_fov_deg`, as ArduPilot's and PX4's irlock drivers convert); `quantize` False gives
    exact angles. `latency_s`: how old the pose a reading describes is when it is read (one Pixy
    frame, 20 ms: the Pixy reports the frame it finished processing). `mount_offset_frd_m`: the
    sensor's position from the vehicle's centre (body FRD, m)."""

    rate_hz: float = 50.0
    fov_x_deg: float = 60.0
    fov_y_deg: float = 47.0
    alt_limit_m: float = 15.0
    dist_limit_m: float = 10.0
    shape: BeaconShape = BeaconShape.CONE
    noise_sigma_deg: float = 0.15
    # Thesis Fig. 14b: IR-LOCK (left) and camera side by side at the frame's centre; with the Pixy board
    # 53 mm wide and the camera board 25 mm, the pair centred puts the Pixy's lens 12.5 mm left.
    mount_offset_frd_m: tuple[float, float, float] = (0.0, -0.0125, 0.0)
    pixels: tuple[int, int] = (320, 200)
    driver_fov_deg: tuple[float, float] = (60.0, 35.0)
    quantize: bool = True
    latency_s: float = 0.02

    def __post_init__(self) -> None:
        require(0 < self.rate_hz <= 400, "rate_hz", "must be within 0..400 Hz")
        require(0 < self.fov_x_deg < 180 and 0 < self.fov_y_deg < 180, "fov_x_deg", "must be within 0..180 deg")
        require(self.alt_limit_m > 0 and self.dist_limit_m > 0, "alt_limit_m", "limits must be > 0 m")
        require(self.noise_sigma_deg >= 0, "noise_sigma_deg", "must be >= 0")
        require(self.pixels[0] >= 1 and self.pixels[1] >= 1, "pixels", "must be >= 1")
        require(all(0 < f < 180 for f in self.driver_fov_deg), "driver_fov_deg", "must be within 0..180 deg")
        require(0 <= self.latency_s <= 1.0, "latency_s", "must be within 0..1 s")


class IrLockModel:
    """Computes IR-LOCK readings of a beacon at `beacon_ned_m` (on the ground) from true poses."""

    def __init__(self, *, spec: IrLockSpec, beacon_ned_m: tuple[float, float], rng: np.random.Generator) -> None:
        self.spec = spec
        self.beacon_ned_m = (float(beacon_ned_m[0]), float(beacon_ned_m[1]), 0.0)
        self._rng = rng
        self._half_fov_x = math.radians(spec.fov_x_deg) / 2.0
        self._half_fov_y = math.radians(spec.fov_y_deg) / 2.0
        self._noise_rad = math.radians(spec.noise_sigma_deg)
        # tan(angle) per pixel of the driver's conversion.
        self._tan_per_px = (2.0 * math.tan(math.radians(spec.driver_fov_deg[0]) / 2.0) / spec.pixels[0],
                            2.0 * math.tan(math.radians(spec.driver_fov_deg[1]) / 2.0) / spec.pixels[1])

    def visible(self, pose: CameraPose) -> bool:
        height_m = -pose.down_m
        if not 0.0 < height_m <= self.spec.alt_limit_m:
            return False
        lateral_m = math.hypot(self.beacon_ned_m[0] - pose.north_m, self.beacon_ned_m[1] - pose.east_m)
        if self.spec.shape is BeaconShape.CONE:
            return lateral_m <= self.spec.dist_limit_m * height_m / self.spec.alt_limit_m
        return lateral_m <= self.spec.dist_limit_m

    def read(self, pose: CameraPose, *, capture_time_s: float) -> TargetReading | None:
        """A reading at `pose`, or None when the beacon is out of view or out of reach."""
        if not self.visible(pose):
            return None
        # In plain floats: read at the sensor's rate (50 Hz) through a landing, where numpy's overhead on
        # 3-vectors was most of a reading's cost; plain arithmetic also gives the same bits whichever BLAS
        # kernel the machine would pick.
        rows = ned_from_body_rows(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
        (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rows
        mount_n, mount_e, mount_d = body_to_ned(rows, self.spec.mount_offset_frd_m)
        beacon_n, beacon_e, beacon_d = self.beacon_ned_m
        # From the sensor (the vehicle plus its mount offset turned into NED) to the beacon, NED (m).
        to_n = beacon_n - (pose.north_m + mount_n)
        to_e = beacon_e - (pose.east_m + mount_e)
        to_d = beacon_d - (pose.down_m + mount_d)
        # Into the body (the rotation's transpose), then the camera frame (`camera.R_CAM_FROM_BODY`: x = right,
        # y = -forward, z = down).
        x = r01 * to_n + r11 * to_e + r21 * to_d
        y = -(r00 * to_n + r10 * to_e + r20 * to_d)
        z = r02 * to_n + r12 * to_e + r22 * to_d
        if z <= 0:
            return None
        angle_x, angle_y = angles_from_camera_point(x, y, z)
        if abs(angle_x) > self._half_fov_x or abs(angle_y) > self._half_fov_y:
            return None
        noise = self._noise_rad
        angle_x += noise * float(self._rng.standard_normal())
        angle_y += noise * float(self._rng.standard_normal())
        if self.spec.quantize:
            angle_x, angle_y = self._quantized(angle_x, angle_y)
        return TargetReading(sensor="irlock", capture_time_s=capture_time_s, angle_x_rad=angle_x,
                             angle_y_rad=angle_y)

    def _quantized(self, angle_x: float, angle_y: float) -> tuple[float, float]:
        """The angles of the pixel the block centre falls in (pixel centres on the driver's scale)."""
        step_x, step_y = self._tan_per_px
        tan_x = (math.floor(math.tan(angle_x) / step_x) + 0.5) * step_x
        tan_y = (math.floor(math.tan(angle_y) / step_y) + 0.5) * step_y
        return math.atan(tan_x), math.atan(tan_y)

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
from .camera import R_CAM_FROM_BODY
from .readings import TargetReading, angles_from_camera_point
from .virtual_camera import CameraPose, rotation_ned_from_body


class BeaconShape(enum.Enum):
    """Where the beacon can be seen from, as SIM_PLD_TYPE (0 cylinder, 1 cone)."""

    CYLINDER = "cylinder"
    CONE = "cone"


@dataclass(frozen=True)
class IrLockSpec:
    """IR-LOCK defaults: 50 Hz (thesis Section 3.4), beacon seen within 15 m height (MarkOne,
    SIM_PLD_ALT_LMT) and, at that height, 10 m sideways (SIM_PLD_DIST_LMT, cone)."""

    rate_hz: float = 50.0
    fov_x_deg: float = 60.0
    fov_y_deg: float = 47.0
    alt_limit_m: float = 15.0
    dist_limit_m: float = 10.0
    shape: BeaconShape = BeaconShape.CONE
    noise_sigma_deg: float = 0.15
    mount_offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        require(0 < self.rate_hz <= 400, "rate_hz", "must be within 0..400 Hz")
        require(0 < self.fov_x_deg < 180 and 0 < self.fov_y_deg < 180, "fov_x_deg", "must be within 0..180 deg")
        require(self.alt_limit_m > 0 and self.dist_limit_m > 0, "alt_limit_m", "limits must be > 0 m")
        require(self.noise_sigma_deg >= 0, "noise_sigma_deg", "must be >= 0")


class IrLockModel:
    """Computes IR-LOCK readings of a beacon at `beacon_ned_m` (on the ground) from true poses."""

    def __init__(self, *, spec: IrLockSpec, beacon_ned_m: tuple[float, float], rng: np.random.Generator) -> None:
        self.spec = spec
        self.beacon = np.array([beacon_ned_m[0], beacon_ned_m[1], 0.0])
        self._rng = rng
        self._half_fov_x = math.radians(spec.fov_x_deg) / 2.0
        self._half_fov_y = math.radians(spec.fov_y_deg) / 2.0
        self._noise_rad = math.radians(spec.noise_sigma_deg)

    def visible(self, pose: CameraPose) -> bool:
        height_m = -pose.down_m
        if not 0.0 < height_m <= self.spec.alt_limit_m:
            return False
        lateral_m = math.hypot(self.beacon[0] - pose.north_m, self.beacon[1] - pose.east_m)
        if self.spec.shape is BeaconShape.CONE:
            return lateral_m <= self.spec.dist_limit_m * height_m / self.spec.alt_limit_m
        return lateral_m <= self.spec.dist_limit_m

    def read(self, pose: CameraPose, *, capture_time_s: float) -> TargetReading | None:
        """A reading at `pose`, or None when the beacon is out of view or out of reach."""
        if not self.visible(pose):
            return None
        r_ned_body = rotation_ned_from_body(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
        sensor = np.array([pose.north_m, pose.east_m, pose.down_m]) + r_ned_body @ np.array(self.spec.mount_offset_frd_m)
        x, y, z = R_CAM_FROM_BODY @ r_ned_body.T @ (self.beacon - sensor)
        if z <= 0:
            return None
        angle_x, angle_y = angles_from_camera_point(float(x), float(y), float(z))
        if abs(angle_x) > self._half_fov_x or abs(angle_y) > self._half_fov_y:
            return None
        noise = self._noise_rad
        return TargetReading(sensor="irlock", capture_time_s=capture_time_s,
                             angle_x_rad=angle_x + noise * float(self._rng.standard_normal()),
                             angle_y_rad=angle_y + noise * float(self._rng.standard_normal()))

"""Onboard precision landing, after ArduPilot's AC_PrecLand with a companion source (PLND_TYPE=1).

LANDING_TARGET angles are turned into a line of sight in body FRD,
(-tan(angle_y), tan(angle_x), 1), rotated to NED with the attitude at the
measurement's capture time, and scaled by the measured distance or, without
one, by the height above ground (rangefinder, else barometer). The target's
position in the autopilot's (estimated) NED frame is then either the raw
measurement (PLND_EST_TYPE=0) or a per-axis position/velocity Kalman filter
(PLND_EST_TYPE=1) with PLND_ACC_P_NSE process noise and ArduPilot's
measurement noise (0.01 of the height plus 2 cm). Measurements older than 1 s
are dropped; the target counts as lost 2 s after the last one.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ..vehicle.types import LandingTarget
from .params import ParameterTable

MEASUREMENT_MAX_AGE_S = 1.0
TARGET_LOST_AFTER_S = 2.0
_HISTORY_S = 1.5


@dataclass(slots=True)
class _PoseSample:
    time_s: float
    north_m: float
    east_m: float
    height_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float


class _AxisFilter:
    """Constant-velocity Kalman filter on one horizontal axis (position m, velocity m/s)."""

    __slots__ = ("position", "velocity", "p00", "p01", "p11")

    def __init__(self, position: float, variance: float) -> None:
        self.position = position
        self.velocity = 0.0
        self.p00, self.p01, self.p11 = variance, 0.0, 1.0

    def predict(self, dt_s: float, accel_noise: float) -> None:
        self.position += self.velocity * dt_s
        q = accel_noise * accel_noise
        dt2 = dt_s * dt_s
        p00 = self.p00 + dt_s * (2.0 * self.p01 + dt_s * self.p11) + q * dt2 * dt2 / 4.0
        p01 = self.p01 + dt_s * self.p11 + q * dt2 * dt_s / 2.0
        p11 = self.p11 + q * dt2
        self.p00, self.p01, self.p11 = p00, p01, p11

    def update(self, measurement: float, variance: float) -> None:
        innovation = measurement - self.position
        s = self.p00 + variance
        k0, k1 = self.p00 / s, self.p01 / s
        self.position += k0 * innovation
        self.velocity += k1 * innovation
        self.p11 -= k1 * self.p01
        self.p01 -= k0 * self.p01
        self.p00 -= k0 * self.p00


class PrecisionLandingEstimator:
    """Tracks the landing target from LANDING_TARGET messages. Positions NED (autopilot's estimate frame), m."""

    def __init__(self, params: ParameterTable) -> None:
        self.params = params
        self._history: deque[_PoseSample] = deque()
        self._filters: tuple[_AxisFilter, _AxisFilter] | None = None
        self._raw: tuple[float, float] | None = None
        self._last_update_s: float | None = None
        self._last_predict_s: float | None = None
        self.last_measured_height_m: float | None = None
        self.measurements_used = 0
        self.measurements_dropped = 0

    def reset(self) -> None:
        self._filters = None
        self._raw = None
        self._last_update_s = None

    def record_pose(self, sample_time_s: float, *, north_m: float, east_m: float, height_m: float,
                    roll_rad: float, pitch_rad: float, yaw_rad: float) -> None:
        """Keep the recent estimated poses, so measurements use the pose at their capture time."""
        self._history.append(_PoseSample(sample_time_s, north_m, east_m, height_m, roll_rad, pitch_rad, yaw_rad))
        while self._history and self._history[0].time_s < sample_time_s - _HISTORY_S:
            self._history.popleft()

    def _pose_at(self, time_s: float) -> _PoseSample | None:
        best = None
        for sample in reversed(self._history):
            best = sample
            if sample.time_s <= time_s:
                break
        return best

    def handle(self, now_s: float, target: LandingTarget) -> bool:
        """Fuse one measurement; False when it was dropped (stale, or pointing above the horizon)."""
        if now_s - target.timestamp_s > MEASUREMENT_MAX_AGE_S:
            self.measurements_dropped += 1
            return False
        pose = self._pose_at(target.timestamp_s)
        if pose is None:
            self.measurements_dropped += 1
            return False
        forward, right, down = -math.tan(target.angle_y_rad), math.tan(target.angle_x_rad), 1.0
        cr, sr = math.cos(pose.roll_rad), math.sin(pose.roll_rad)
        cp, sp = math.cos(pose.pitch_rad), math.sin(pose.pitch_rad)
        cy, sy = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
        north = cp * cy * forward + (sr * sp * cy - cr * sy) * right + (cr * sp * cy + sr * sy) * down
        east = cp * sy * forward + (sr * sp * sy + cr * cy) * right + (cr * sp * sy - sr * cy) * down
        downward = -sp * forward + sr * cp * right + cr * cp * down
        if downward <= 0.05:
            self.measurements_dropped += 1
            return False
        if target.distance_m is not None and target.distance_m > 0:
            scale = target.distance_m / math.sqrt(north * north + east * east + downward * downward)
        else:
            scale = max(pose.height_m, 0.0) / downward
        rel_north, rel_east, rel_down = north * scale, east * scale, downward * scale
        target_north, target_east = pose.north_m + rel_north, pose.east_m + rel_east
        self.last_measured_height_m = rel_down
        self._raw = (target_north, target_east)
        noise_m = 0.01 * rel_down + 0.02  # AC_PrecLand's xy measurement noise
        if self._filters is None or self._last_update_s is None or \
                now_s - self._last_update_s > TARGET_LOST_AFTER_S:
            self._filters = (_AxisFilter(target_north, noise_m**2), _AxisFilter(target_east, noise_m**2))
            self._last_predict_s = now_s
        else:
            self._predict(now_s)
            self._filters[0].update(target_north, noise_m**2)
            self._filters[1].update(target_east, noise_m**2)
        self._last_update_s = now_s
        self.measurements_used += 1
        return True

    def _predict(self, now_s: float) -> None:
        if self._filters is None or self._last_predict_s is None:
            return
        dt_s = now_s - self._last_predict_s
        if dt_s <= 0:
            return
        accel_noise = self.params.value("PLND_ACC_P_NSE")
        self._filters[0].predict(dt_s, accel_noise)
        self._filters[1].predict(dt_s, accel_noise)
        self._last_predict_s = now_s

    def target_acquired(self, now_s: float) -> bool:
        return self._last_update_s is not None and now_s - self._last_update_s <= TARGET_LOST_AFTER_S

    def target_position_m(self, now_s: float) -> tuple[float, float] | None:
        """The target's (north, east) in the autopilot's NED frame, or None when not acquired."""
        if not self.target_acquired(now_s):
            return None
        if self.params.value("PLND_EST_TYPE") == 0 or self._filters is None:
            return self._raw
        self._predict(now_s)
        return self._filters[0].position, self._filters[1].position

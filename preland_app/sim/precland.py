"""Onboard precision landing, after ArduPilot's AC_PrecLand with a companion source (PLND_TYPE=1).

LANDING_TARGET angles are turned into a line of sight in body FRD,
(-tan(angle_y), tan(angle_x), 1), rotated to NED with the attitude estimate of
PLND_LAG seconds before the measurement arrived (ArduPilot keeps an inertial
history buffer PLND_LAG long and treats every measurement as that old, whatever
the message's timestamp says; a sensor whose true delay differs from PLND_LAG
is fused with the wrong attitude and position), and scaled by the measured
distance or, without one, by the height above ground (rangefinder, else barometer). The result is the
target's position *relative to the vehicle*, moved to the present with the
vehicle's motion since the capture. As in ArduPilot, the estimator works in that
relative frame: PLND_EST_TYPE=1 is a per-axis position/velocity Kalman filter
predicted with the IMU's delta-velocity (PLND_ACC_P_NSE) and corrected with the
measurements (noise 1 % of the height, 1 % more per rad/s of the vehicle's
rotation, plus 2 cm), each refused while its normalised innovation squared is 3
or more on either axis unless the three before it were refused (AC_PrecLand's
outlier gate, in 3.6, 4.0 and 4.6 alike); PLND_EST_TYPE=0 uses the raw
measurement, ungated. The target's position for the controller is the vehicle's
position estimate plus the relative estimate, so GPS noise does not move the target.
Measurements older than 1 s are dropped; the target counts as lost 2 s after the
last one.

`firmware` chooses between ArduCopter releases (`sim.spec.Firmware`). As 3.6/4.0, the thesis' (the default):
the filter starts at zero relative velocity and the target is used from its first reading. As 4.1 and later
(4.6), with PLND_EST_TYPE=1: the filter starts at minus the vehicle's velocity PLND_LAG ago with a variance
of 2^2 (m/s)^2, fuses readings from the first, and the target is used only once 2 s of readings have come
without a gap over 0.5 s (a longer gap restarts that wait at the next reading).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

from ..geo import body_to_ned, ned_from_body_rows
from ..vehicle.types import LandingTarget
from .params import ParameterTable
from .spec import Firmware

MEASUREMENT_MAX_AGE_S = 1.0
TARGET_LOST_AFTER_S = 2.0
_HISTORY_S = 1.5
# AC_PrecLand::init constrains PLND_LAG to this range before sizing the inertial history buffer.
PLND_LAG_MIN_S = 0.02
PLND_LAG_MAX_S = 0.25
# AC_PrecLand::run_estimator: a measurement whose NIS is 3 or more on either axis is an outlier; after three
# outliers in a row the next measurement is fused whatever its NIS (so a target that really moved is followed).
OUTLIER_NIS_MAX = 3.0
OUTLIER_REJECT_LIMIT = 3
# ArduCopter 4.1+ (AC_PrecLand.cpp): EKF_INIT_TIME_MS of readings, none more than EKF_INIT_SENSOR_MIN_UPDATE_MS
# apart, before the target is used; its filter starts at minus the vehicle's velocity with 2^2 (m/s)^2.
INIT_TIME_S = 2.0
INIT_MAX_GAP_S = 0.5
INIT_VELOCITY_VARIANCE = 2.0 ** 2


@dataclass(slots=True)
class _PoseSample:
    time_s: float
    north_m: float
    east_m: float
    height_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    velocity_north_m_s: float
    velocity_east_m_s: float


class _AxisFilter:
    """AC_PrecLand's PosVelEKF on one horizontal axis: relative position (m) and velocity (m/s)."""

    __slots__ = ("position", "velocity", "p00", "p01", "p11")

    def __init__(self, position: float, variance: float, *, velocity: float = 0.0,
                 velocity_variance: float = 1.0) -> None:
        self.position = position
        self.velocity = velocity
        self.p00, self.p01, self.p11 = variance, 0.0, velocity_variance

    def predict(self, dt_s: float, delta_velocity: float, delta_velocity_noise: float) -> None:
        self.position += self.velocity * dt_s
        self.velocity += delta_velocity
        p00 = self.p00 + dt_s * (2.0 * self.p01 + dt_s * self.p11)
        p01 = self.p01 + dt_s * self.p11
        p11 = self.p11 + delta_velocity_noise * delta_velocity_noise
        self.p00, self.p01, self.p11 = p00, p01, p11

    def nis(self, measurement: float, variance: float) -> float:
        """The measurement's normalised innovation squared (PosVelEKF::getPosNIS)."""
        innovation = measurement - self.position
        return innovation * innovation / (self.p00 + variance)

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
    """Tracks the landing target from LANDING_TARGET messages. NED, metres, the autopilot's estimate frame."""

    def __init__(self, params: ParameterTable, *, firmware: Firmware = Firmware.COPTER_4_0) -> None:
        self.params = params
        self.firmware = firmware
        # Whether the target is used (while its last reading is under TARGET_LOST_AFTER_S old); 4.1+: readings
        # are being fused, since `_init_s`, but the target is not used yet.
        self._acquired = False
        self._initialising = False
        self._init_s = 0.0
        self._history: deque[_PoseSample] = deque()
        self._filters: tuple[_AxisFilter, _AxisFilter] | None = None
        self._raw_rel: tuple[float, float] | None = None
        self._last_update_s: float | None = None
        self.last_measured_height_m: float | None = None
        self.measurements_used = 0
        self.measurements_dropped = 0
        self.measurements_rejected = 0  # refused by the outlier gate
        self._outlier_reject_count = 0
        self.gyro_rad_s = 0.0

    def reset(self) -> None:
        self._filters = None
        self._raw_rel = None
        self._last_update_s = None
        self._acquired = False
        self._initialising = False

    def record_pose(self, sample_time_s: float, *, north_m: float, east_m: float, height_m: float,
                    roll_rad: float, pitch_rad: float, yaw_rad: float, gyro_rad_s: float = 0.0,
                    velocity_ne_m_s: tuple[float, float] = (0.0, 0.0)) -> None:
        """Keep the recent estimated poses, so measurements use the pose at their capture time. `gyro_rad_s`:
        the vehicle's rotation rate now (the length of the gyro's vector), which widens the measurement noise;
        `velocity_ne_m_s`: the estimated velocity (north, east), where a 4.1+ filter starts."""
        self.gyro_rad_s = gyro_rad_s
        self._history.append(_PoseSample(sample_time_s, north_m, east_m, height_m, roll_rad, pitch_rad, yaw_rad,
                                         velocity_ne_m_s[0], velocity_ne_m_s[1]))
        while self._history and self._history[0].time_s < sample_time_s - _HISTORY_S:
            self._history.popleft()

    def _pose_at(self, time_s: float) -> _PoseSample | None:
        best = None
        for sample in reversed(self._history):
            best = sample
            if sample.time_s <= time_s:
                break
        return best

    def predict(self, *, dt_s: float, delta_velocity_ned_m_s: tuple[float, float]) -> None:
        """Propagate the relative estimate with the vehicle's IMU delta-velocity over `dt_s`."""
        if self._filters is None:
            return
        noise = self.params.value("PLND_ACC_P_NSE") * dt_s
        self._filters[0].predict(dt_s, -delta_velocity_ned_m_s[0], noise)
        self._filters[1].predict(dt_s, -delta_velocity_ned_m_s[1], noise)

    def handle(self, now_s: float, target: LandingTarget) -> bool:
        """Fuse one measurement received at `now_s`; False when it was dropped (older than 1 s by its
        timestamp, not a number, or pointing above the horizon) or refused as an outlier (the filter's NIS gate,
        PLND_EST_TYPE=1). Its pose is the one PLND_LAG before `now_s`."""
        if now_s - target.timestamp_s > MEASUREMENT_MAX_AGE_S or not _finite(target):
            self.measurements_dropped += 1
            return False
        lag_s = min(max(self.params.value("PLND_LAG"), PLND_LAG_MIN_S), PLND_LAG_MAX_S)
        pose = self._pose_at(now_s - lag_s)
        current = self._history[-1] if self._history else None
        if pose is None or current is None:
            self.measurements_dropped += 1
            return False
        rows = ned_from_body_rows(pose.roll_rad, pose.pitch_rad, pose.yaw_rad)
        north, east, downward = body_to_ned(rows, (-math.tan(target.angle_y_rad), math.tan(target.angle_x_rad), 1.0))
        if downward <= 0.05:
            self.measurements_dropped += 1
            return False
        # PLND_CAM_POS_*: the sensor's offset from the vehicle's centre, rotated to NED with the same attitude.
        cam_n, cam_e, cam_d = _offset_to_ned(self._cam_pos_frd_m(), rows)
        if target.distance_m is not None and target.distance_m > 0:
            scale = target.distance_m / math.sqrt(north * north + east * east + downward * downward)
        else:
            scale = max(pose.height_m - cam_d, 0.0) / downward
        # Relative position PLND_LAG ago, moved to now by the vehicle's motion since then.
        rel_north = north * scale + cam_n - (current.north_m - pose.north_m)
        rel_east = east * scale + cam_e - (current.east_m - pose.east_m)
        rel_down = downward * scale + cam_d
        self.last_measured_height_m = rel_down
        self._raw_rel = (rel_north, rel_east)
        # AC_PrecLand's xy measurement noise: 1 % of the height, 1 % more per rad/s of rotation, plus 2 cm.
        variance = (rel_down * (0.01 + 0.01 * self.gyro_rad_s) + 0.02) ** 2
        # 4.1+ waits only with its filter (PLND_EST_TYPE=1); its raw estimator uses each reading at once.
        waits = self.firmware is Firmware.COPTER_4_6 and self.params.value("PLND_EST_TYPE") != 0
        if waits:
            starting = not self._initialising and not self.target_acquired(now_s)
        else:
            starting = self._filters is None or not self.target_acquired(now_s)
        if starting:
            if waits:
                self._filters = (
                    _AxisFilter(rel_north, variance, velocity=-pose.velocity_north_m_s,
                                velocity_variance=INIT_VELOCITY_VARIANCE),
                    _AxisFilter(rel_east, variance, velocity=-pose.velocity_east_m_s,
                                velocity_variance=INIT_VELOCITY_VARIANCE))
                self._initialising, self._init_s, self._acquired = True, now_s, False
            else:
                # Zero velocity with 1 (m/s)^2. AC_PrecLand 3.6/4.0 starts at minus the vehicle's velocity
                # with 2^2: a departure that the docs name (explanation, "Departures from the sources").
                self._filters = (_AxisFilter(rel_north, variance), _AxisFilter(rel_east, variance))
        else:
            if self.params.value("PLND_EST_TYPE") != 0:
                nis = max(self._filters[0].nis(rel_north, variance), self._filters[1].nis(rel_east, variance))
                if nis >= OUTLIER_NIS_MAX and self._outlier_reject_count < OUTLIER_REJECT_LIMIT:
                    # Not fused, and the target's last update stays where it was (target_acquired ages).
                    self._outlier_reject_count += 1
                    self.measurements_rejected += 1
                    return False
            self._outlier_reject_count = 0
            self._filters[0].update(rel_north, variance)
            self._filters[1].update(rel_east, variance)
        self._last_update_s = now_s
        self._acquired = not self._initialising
        self.measurements_used += 1
        return True

    def update(self, now_s: float) -> None:
        """Once a control cycle (AC_PrecLand::check_ekf_init_timeout, 4.1+): a wait whose readings stopped
        for over INIT_MAX_GAP_S fails; one that lasted INIT_TIME_S makes the target used."""
        if not self._initialising or self._last_update_s is None:
            return
        if now_s - self._last_update_s > INIT_MAX_GAP_S:
            self._initialising = False
            self._filters = None
        elif now_s - self._init_s > INIT_TIME_S:
            self._initialising, self._acquired = False, True

    def target_acquired(self, now_s: float) -> bool:
        return (self._acquired and self._last_update_s is not None
                and now_s - self._last_update_s <= TARGET_LOST_AFTER_S)

    def _cam_pos_frd_m(self) -> tuple[float, float, float]:
        p = self.params
        return p.value("PLND_CAM_POS_X"), p.value("PLND_CAM_POS_Y"), p.value("PLND_CAM_POS_Z")

    def relative_position_m(self, now_s: float) -> tuple[float, float] | None:
        """Where the vehicle steers to, relative to itself (north, east) in m, or None when not acquired.

        As AC_PrecLand::run_output_prediction: the target's relative position minus the sensor's
        horizontal offset (PLND_CAM_POS_X/Y rotated with the current attitude), so the sensor, not the
        vehicle's centre, ends up over the target."""
        if not self.target_acquired(now_s):
            return None
        if self.params.value("PLND_EST_TYPE") == 0 or self._filters is None:
            rel = self._raw_rel
        else:
            rel = self._filters[0].position, self._filters[1].position
        cam_x, cam_y, _ = self._cam_pos_frd_m()
        if rel is None or (cam_x == 0.0 and cam_y == 0.0) or not self._history:
            return rel
        latest = self._history[-1]
        cam_n, cam_e, _ = _offset_to_ned((cam_x, cam_y, 0.0),
                                         ned_from_body_rows(latest.roll_rad, latest.pitch_rad, latest.yaw_rad))
        return rel[0] - cam_n, rel[1] - cam_e

    def relative_velocity_m_s(self, now_s: float) -> tuple[float, float] | None:
        """Target minus vehicle velocity (north, east) in m/s from the filter; None for the raw estimator."""
        if self.params.value("PLND_EST_TYPE") == 0 or self._filters is None or not self.target_acquired(now_s):
            return None
        return self._filters[0].velocity, self._filters[1].velocity

    def target_position_m(self, now_s: float, *, vehicle_north_m: float,
                          vehicle_east_m: float) -> tuple[float, float] | None:
        """The target's (north, east) in the autopilot's NED frame, or None when not acquired."""
        rel = self.relative_position_m(now_s)
        if rel is None:
            return None
        return vehicle_north_m + rel[0], vehicle_east_m + rel[1]


def _finite(target: LandingTarget) -> bool:
    """Whether a measurement's angles (and distance, when it has one) are numbers: one NaN fused would make
    the estimate, and so the vehicle's position target, NaN for good."""
    values = (target.angle_x_rad, target.angle_y_rad) + (() if target.distance_m is None else (target.distance_m,))
    return all(math.isfinite(v) for v in values)


def _offset_to_ned(vector_frd: tuple[float, float, float],
                   rows: tuple[tuple[float, float, float], ...]) -> tuple[float, float, float]:
    """A body FRD offset rotated to NED by `rows`; none (all zeros) stays exactly zero."""
    if vector_frd[0] == 0.0 and vector_frd[1] == 0.0 and vector_frd[2] == 0.0:
        return 0.0, 0.0, 0.0
    return body_to_ned(rows, vector_frd)

"""ArduCopter 4.1+'s kinematic shaping of the position target (AP_Math/control.cpp, read at Copter-4.6.3,
92b0cd78): `AC_PosControl` moves a desired position, velocity and acceleration along a jerk-limited path to
the commanded position (`input_pos_xyz` -> `shape_pos_vel_accel_xy`, and `shape_pos_vel_accel` on z) or to a
stop (`input_vel_accel_xy` with zero velocity -> `shape_vel_accel_xy`), and the position loop then follows the
desired position with its velocity and acceleration as feed-forward. Horizontal positions NED and altitudes
up, in m; velocities m/s, accelerations m/s^2, jerk m/s^3.
"""

from __future__ import annotations

import math

from .control import limit_length_ne, sqrt_controller, sqrt_controller_ne

CORNER_ACCELERATION_RATIO = 1.0 / math.sqrt(2.0)  # control.cpp: the share of acceleration kept for a turn


class PositionShaper:
    """The desired horizontal position (`position_ne_m`), velocity and acceleration of ArduCopter 4.1+'s position
    controller, started from the vehicle's state (`init_xy_controller`)."""

    def __init__(self, *, position_ne_m: tuple[float, float], velocity_ne_m_s: tuple[float, float] = (0.0, 0.0)
                 ) -> None:
        self.position_ne_m = list(position_ne_m)
        self.velocity_ne_m_s = list(velocity_ne_m_s)
        self.accel_ne_m_s2 = [0.0, 0.0]

    def to_position(self, target_ne_m: tuple[float, float], *, dt_s: float, speed_max_m_s: float,
                    accel_max_m_s2: float, jerk_max_m_s3: float) -> None:
        """One step towards `target_ne_m` (`input_pos_xyz`'s horizontal part)."""
        self._advance(dt_s)
        error_north, error_east = target_ne_m[0] - self.position_ne_m[0], target_ne_m[1] - self.position_ne_m[1]
        north, east = sqrt_controller_ne(error_north, error_east, 0.5 * jerk_max_m_s3 / accel_max_m_s2,
                                         0.5 * accel_max_m_s2, dt_s)
        self._shape_velocity(limit_length_ne(north, east, speed_max_m_s), accel_max_m_s2, jerk_max_m_s3, dt_s)

    def to_stop(self, *, dt_s: float, accel_max_m_s2: float, jerk_max_m_s3: float) -> None:
        """One step of stopping (`input_vel_accel_xy` with zero velocity and acceleration)."""
        self._advance(dt_s)
        self._shape_velocity((0.0, 0.0), accel_max_m_s2, jerk_max_m_s3, dt_s)

    def _advance(self, dt_s: float) -> None:
        """`update_pos_vel_accel_xy` without limits."""
        for axis in (0, 1):
            self.position_ne_m[axis] += self.velocity_ne_m_s[axis] * dt_s + self.accel_ne_m_s2[axis] * 0.5 * dt_s * dt_s
            self.velocity_ne_m_s[axis] += self.accel_ne_m_s2[axis] * dt_s

    def _shape_velocity(self, velocity_ne_m_s: tuple[float, float], accel_max_m_s2: float, jerk_max_m_s3: float,
                        dt_s: float) -> None:
        """`shape_vel_accel_xy` (no acceleration input, the correction limited, not the total)."""
        accel = sqrt_controller_ne(velocity_ne_m_s[0] - self.velocity_ne_m_s[0],
                                   velocity_ne_m_s[1] - self.velocity_ne_m_s[1],
                                   jerk_max_m_s3 / accel_max_m_s2, jerk_max_m_s3, dt_s)
        speed = math.hypot(*velocity_ne_m_s)
        if speed == 0.0:
            accel = limit_length_ne(*accel, accel_max_m_s2)
        else:
            unit = (velocity_ne_m_s[0] / speed, velocity_ne_m_s[1] / speed)
            along = unit[0] * accel[0] + unit[1] * accel[1]
            cross = (accel[0] - unit[0] * along, accel[1] - unit[1] * along)
            if along * along <= cross[0] ** 2 + cross[1] ** 2:
                accel = limit_length_ne(*accel, accel_max_m_s2)
            else:
                cross = limit_length_ne(*cross, CORNER_ACCELERATION_RATIO * accel_max_m_s2)
                along_max = math.sqrt(max(0.0, accel_max_m_s2 ** 2 - cross[0] ** 2 - cross[1] ** 2))
                along = max(-along_max, min(along_max, along))
                accel = (cross[0] + unit[0] * along, cross[1] + unit[1] * along)
        # shape_accel_xy: the acceleration moves towards its target at most jerk_max * dt a step
        step = limit_length_ne(accel[0] - self.accel_ne_m_s2[0], accel[1] - self.accel_ne_m_s2[1], jerk_max_m_s3 * dt_s)
        self.accel_ne_m_s2[0] += step[0]
        self.accel_ne_m_s2[1] += step[1]


class AltitudeShaper:
    """The desired altitude (`altitude_m`, up), climb rate and vertical acceleration of ArduCopter 4.1+'s
    position controller (`shape_pos_vel_accel` on z with zero input velocity), started from the vehicle's
    altitude, climb rate and acceleration (`init_z_controller`)."""

    def __init__(self, *, altitude_m: float, climb_rate_m_s: float = 0.0, accel_up_m_s2: float = 0.0) -> None:
        self.altitude_m = altitude_m
        self.climb_rate_m_s = climb_rate_m_s
        self.accel_up_m_s2 = accel_up_m_s2

    def to_altitude(self, target_m: float, *, dt_s: float, speed_up_m_s: float, speed_down_m_s: float,
                    accel_max_m_s2: float, jerk_max_m_s3: float) -> None:
        """One step towards `target_m` (m up): the same accelerations up and down (input_pos_xyz's z, whose
        downward limit is the same accel_max_z up to 7.5 m/s/s)."""
        self.altitude_m += self.climb_rate_m_s * dt_s + self.accel_up_m_s2 * 0.5 * dt_s * dt_s
        self.climb_rate_m_s += self.accel_up_m_s2 * dt_s
        accel_m_s2 = min(accel_max_m_s2, 7.5)
        # shape_pos_vel_accel: velocity to correct the position, braking at half the acceleration
        rate = sqrt_controller(target_m - self.altitude_m, 0.5 * jerk_max_m_s3 / accel_m_s2, 0.5 * accel_m_s2, dt_s)
        rate = max(-speed_down_m_s, min(speed_up_m_s, rate))
        # shape_vel_accel: acceleration to correct the velocity, then jerk-limited (shape_accel)
        accel = sqrt_controller(rate - self.climb_rate_m_s, jerk_max_m_s3 / accel_m_s2, jerk_max_m_s3, dt_s)
        accel = max(-accel_m_s2, min(accel_m_s2, accel))
        step = max(-jerk_max_m_s3 * dt_s, min(jerk_max_m_s3 * dt_s, accel - self.accel_up_m_s2))
        self.accel_up_m_s2 += step

"""ArduCopter-style position control (after AC_PosControl): sqrt controller, xy and z loops.

Units are SI. Positions and velocities NED from the simulation origin, as the
autopilot *estimates* them.
"""

from __future__ import annotations

import math

from .dynamics import GRAVITY_M_S2


def sqrt_controller(error: float, p_gain: float, accel_max: float, dt_s: float = 0.0) -> float:
    """AC_PosControl's sqrt controller (AP_Math/control.cpp `sqrt_controller`): linear near zero,
    constant-deceleration far away, so that the vehicle can stop at `accel_max` (the error's units per second
    per second); the square root alone when `p_gain` is 0. Given `dt_s`, it never passes zero in one step.
    Returns the correction rate (the error's units per second)."""
    if accel_max <= 0.0:
        rate = error * p_gain
    elif p_gain == 0.0:
        rate = math.copysign(math.sqrt(2.0 * accel_max * abs(error)), error)
    else:
        linear_dist = accel_max / (p_gain * p_gain)
        if error > linear_dist:
            rate = math.sqrt(2.0 * accel_max * (error - linear_dist / 2.0))
        elif error < -linear_dist:
            rate = -math.sqrt(2.0 * accel_max * (-error - linear_dist / 2.0))
        else:
            rate = error * p_gain
    if dt_s > 0.0:
        return max(-abs(error) / dt_s, min(abs(error) / dt_s, rate))
    return rate


def limit_length_ne(north: float, east: float, limit: float) -> tuple[float, float]:
    """The vector (north, east) shortened to length `limit` when longer (Vector2f::limit_length); unchanged
    when `limit` is not positive."""
    length = math.hypot(north, east)
    if length > limit > 0.0:
        scale = limit / length
        return north * scale, east * scale
    return north, east


def sqrt_controller_ne(north: float, east: float, p_gain: float, accel_max: float,
                       dt_s: float = 0.0) -> tuple[float, float]:
    """`sqrt_controller` on a horizontal error vector (AP_Math's Vector2f version): the correction along the
    error, sized by the error's length; none for an error under a micrometre."""
    length = math.hypot(north, east)
    if length <= 1e-6:
        return 0.0, 0.0
    correction = sqrt_controller(length, p_gain, accel_max, dt_s)
    return correction * north / length, correction * east / length


def stopping_distance_m(speed_m_s: float, p_gain: float, accel_max_m_s2: float) -> float:
    """Distance to stop from `speed_m_s` under the sqrt controller (inverse of it)."""
    if accel_max_m_s2 <= 0 or p_gain <= 0:
        return 0.0
    linear_velocity = accel_max_m_s2 / p_gain
    if speed_m_s <= linear_velocity:
        return speed_m_s / p_gain
    return accel_max_m_s2 / (2.0 * p_gain * p_gain) + speed_m_s * speed_m_s / (2.0 * accel_max_m_s2)


class HorizontalController:
    """Position -> velocity (sqrt controller) -> acceleration (PI) -> lean angles."""

    def __init__(self) -> None:
        self.velocity_demand_north_m_s = 0.0
        self.velocity_demand_east_m_s = 0.0
        self._integrator_north = 0.0
        self._integrator_east = 0.0
        self.position_error_m = 0.0

    def reset(self, *, velocity_north_m_s: float = 0.0, velocity_east_m_s: float = 0.0) -> None:
        """Forget integrators and start the velocity demand from the current velocity."""
        self.velocity_demand_north_m_s = velocity_north_m_s
        self.velocity_demand_east_m_s = velocity_east_m_s
        self._integrator_north = 0.0
        self._integrator_east = 0.0

    def update(
        self,
        *,
        dt_s: float,
        yaw_rad: float,
        est_north_m: float,
        est_east_m: float,
        est_velocity_north_m_s: float,
        est_velocity_east_m_s: float,
        target_north_m: float | None,
        target_east_m: float | None,
        velocity_ff_north_m_s: float,
        velocity_ff_east_m_s: float,
        accel_ff_ne_m_s2: tuple[float, float] | None = None,
        speed_max_m_s: float,
        accel_max_m_s2: float,
        pos_p: float,
        vel_p: float,
        vel_i: float,
        vel_imax_m_s2: float,
        angle_max_rad: float,
    ) -> tuple[float, float]:
        """One control step. Returns (roll_rad, pitch_rad) demands.

        With a target position, the velocity demand is the sqrt controller's
        correction plus the feed-forward; without one, it is the feed-forward
        alone. Its change is limited to `accel_max_m_s2`, and that change is the acceleration feed-forward,
        unless `accel_ff_ne_m_s2` is given: then the feed-forward comes from a kinematic target (AC_PosControl
        4.1+, whose target already moves within the limits) and the demand is not slewed.
        """
        want_north, want_east = velocity_ff_north_m_s, velocity_ff_east_m_s
        if target_north_m is not None and target_east_m is not None:
            error_north = target_north_m - est_north_m
            error_east = target_east_m - est_east_m
            self.position_error_m = math.hypot(error_north, error_east)
            correction_north, correction_east = sqrt_controller_ne(error_north, error_east, pos_p, accel_max_m_s2)
            want_north += correction_north
            want_east += correction_east
        else:
            self.position_error_m = 0.0
        want_north, want_east = limit_length_ne(want_north, want_east, speed_max_m_s)
        if accel_ff_ne_m_s2 is not None:
            self.velocity_demand_north_m_s, self.velocity_demand_east_m_s = want_north, want_east
            feedforward_north, feedforward_east = accel_ff_ne_m_s2
        else:
            feedforward_north, feedforward_east = self._slew(want_north, want_east, accel_max_m_s2, dt_s)

        vel_error_north = self.velocity_demand_north_m_s - est_velocity_north_m_s
        vel_error_east = self.velocity_demand_east_m_s - est_velocity_east_m_s
        self._integrator_north += vel_i * vel_error_north * dt_s
        self._integrator_east += vel_i * vel_error_east * dt_s
        self._integrator_north, self._integrator_east = limit_length_ne(self._integrator_north,
                                                                        self._integrator_east, vel_imax_m_s2)
        accel_north = feedforward_north + vel_p * vel_error_north + self._integrator_north
        accel_east = feedforward_east + vel_p * vel_error_east + self._integrator_east
        accel_north, accel_east = limit_length_ne(accel_north, accel_east, GRAVITY_M_S2 * math.tan(angle_max_rad))
        # AC_PosControl::accel_to_lean_angles
        cy, sy = math.cos(yaw_rad), math.sin(yaw_rad)
        accel_forward = accel_north * cy + accel_east * sy
        accel_right = -accel_north * sy + accel_east * cy
        pitch_rad = math.atan(-accel_forward / GRAVITY_M_S2)
        roll_rad = math.atan(accel_right * math.cos(pitch_rad) / GRAVITY_M_S2)
        return roll_rad, pitch_rad

    def _slew(self, want_north: float, want_east: float, accel_max_m_s2: float, dt_s: float) -> tuple[float, float]:
        """Move the velocity demand towards the wanted one by at most `accel_max_m_s2` (as the S-curve does);
        returns the acceleration that took (m/s/s, NE)."""
        delta_north, delta_east = limit_length_ne(want_north - self.velocity_demand_north_m_s,
                                                  want_east - self.velocity_demand_east_m_s, accel_max_m_s2 * dt_s)
        self.velocity_demand_north_m_s += delta_north
        self.velocity_demand_east_m_s += delta_east
        return delta_north / dt_s, delta_east / dt_s


class VerticalController:
    """Altitude -> climb rate (sqrt controller), with climb-rate demand slewed by the vertical accel limit;
    climb rate -> vertical acceleration (AC_PosControl's z velocity loop, P gain PSC_VELZ_P)."""

    def __init__(self) -> None:
        self.climb_demand_m_s = 0.0
        self._last_delta_m_s = 0.0

    def reset(self, climb_rate_m_s: float = 0.0) -> None:
        self.climb_demand_m_s = climb_rate_m_s
        self._last_delta_m_s = 0.0

    def accel_for_climb(self, *, dt_s: float, est_climb_rate_m_s: float, vel_p: float) -> float:
        """Vertical acceleration demand (m/s/s, up) for the current climb demand: the shaped demand's
        own acceleration as feed-forward plus PSC_VELZ_P times the climb-rate error, limited to +-1 g."""
        feedforward = self._last_delta_m_s / dt_s if dt_s > 0 else 0.0
        accel = feedforward + vel_p * (self.climb_demand_m_s - est_climb_rate_m_s)
        return max(-GRAVITY_M_S2, min(GRAVITY_M_S2, accel))

    def climb_for_altitude(self, *, target_alt_m: float, est_alt_m: float, pos_p: float,
                           accel_max_m_s2: float, speed_up_m_s: float, speed_down_m_s: float) -> float:
        rate = sqrt_controller(target_alt_m - est_alt_m, pos_p, accel_max_m_s2)
        return max(-speed_down_m_s, min(speed_up_m_s, rate))

    def shape(self, *, dt_s: float, climb_rate_m_s: float, accel_max_m_s2: float) -> float:
        """Slew the climb demand towards `climb_rate_m_s` at `accel_max_m_s2`; returns it."""
        max_delta = accel_max_m_s2 * dt_s
        delta = max(-max_delta, min(max_delta, climb_rate_m_s - self.climb_demand_m_s))
        self.climb_demand_m_s += delta
        self._last_delta_m_s = delta
        return self.climb_demand_m_s

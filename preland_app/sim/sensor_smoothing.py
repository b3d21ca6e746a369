"""What SITL is told of preland's physics: ArduPilot SITL's `Aircraft::smooth_sensors`
(libraries/SITL/SIM_Aircraft.cpp), for the same reason.

The ground contact levels the vehicle and stops it within one step (SITL's GROUND_BEHAVIOR_NO_MOVEMENT,
as `QuadXMultirotor` does). Told as it is, a touchdown in wind is a roll and pitch jump the gyro never saw
and a velocity step the accelerometer never saw: ArduCopter's EKF then keeps the tilt the vehicle had
into the wind for seconds, sees a horizontal acceleration that is not there, and LAND asks for a lean the
grounded vehicle cannot make, so the land detector (its angle checks) never fires and the vehicle never
disarms. SITL's own physics sends smoothed sensors instead, from boot (a SITL vehicle starts on the ground
and `use_smoothing` is never cleared), and so does the bridge: a smoothed body follows the true one with
a 0.1 s time constant; its gyro is the true rate plus the rotation to the true attitude over the time
constant, its specific force the acceleration that brings its velocity and position to the true ones
(limited to 14 g); the attitude sent stays the true one (fill_fdm sends the unsmoothed attitude).
In flight the smoothed velocity stays within about 1 cm/s of the true one.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .multirotor import GRAVITY_M_S2, MultirotorState, rotation_body_to_ned

TIME_CONSTANT_S = 0.1  # smooth_sensors' time_constant
ACCEL_LIMIT_M_S2 = 14 * GRAVITY_M_S2  # smooth_sensors' limit on the smoothed body's acceleration
_MAX_DT_S = 0.1  # smooth_sensors skips a step longer than this
_RESET_DISTANCE_M = 10.0  # and starts again from the true state when it is this far from it


def _multiply(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


class SensorSmoothing:
    """`smoothed(state)`: the state SITL is told, for each new true state of the physics (in order)."""

    def __init__(self) -> None:
        self._time_s: float | None = None

    def reset(self) -> None:
        """Start again from the next state (the physics was reset)."""
        self._time_s = None

    def smoothed(self, state: MultirotorState) -> MultirotorState:
        if self._time_s is None or math.dist(state.position_ned_m, self._p) > _RESET_DISTANCE_M:
            self._time_s = state.time_s
            self._p, self._v = list(state.position_ned_m), list(state.velocity_ned_m_s)
            self._q = state.quaternion_wxyz
            self._gyro, self._accel = state.gyro_frd_rad_s, state.accel_frd_m_s2
            return state
        dt_s = state.time_s - self._time_s
        self._time_s = state.time_s
        if 0.0 < dt_s <= _MAX_DT_S:
            self._step(state, dt_s)
        p, v = self._p, self._v
        return MultirotorState(time_s=state.time_s, position_ned_m=(p[0], p[1], p[2]),
                               velocity_ned_m_s=(v[0], v[1], v[2]), quaternion_wxyz=state.quaternion_wxyz,
                               gyro_frd_rad_s=self._gyro, accel_frd_m_s2=self._accel,
                               motor_commands=state.motor_commands, on_ground=state.on_ground,
                               rangefinder_down_m=state.rangefinder_down_m)

    def _step(self, state: MultirotorState, dt_s: float) -> None:
        # Written out per axis (once per physics step): the same operations, in the same order, as the
        # vector forms in the comments.
        tc = TIME_CONSTANT_S
        limit = ACCEL_LIMIT_M_S2
        p, v, q = state.position_ned_m, state.velocity_ned_m_s, state.quaternion_wxyz
        r = rotation_body_to_ned(*q)
        f0, f1, f2 = state.accel_frd_m_s2
        # the true acceleration in NED: R f + g
        t0 = r[0][0] * f0 + r[0][1] * f1 + r[0][2] * f2
        t1 = r[1][0] * f0 + r[1][1] * f1 + r[1][2] * f2
        t2 = r[2][0] * f0 + r[2][1] * f1 + r[2][2] * f2 + GRAVITY_M_S2
        # the smoothed body's: towards the true velocity and position, within the limit
        sp, sv = self._p, self._v
        a0 = min(max(((v[0] - sv[0]) + (p[0] - sp[0]) / tc) / tc + t0, -limit), limit)
        a1 = min(max(((v[1] - sv[1]) + (p[1] - sp[1]) / tc) / tc + t1, -limit), limit)
        a2 = min(max(((v[2] - sv[2]) + (p[2] - sp[2]) / tc) / tc + t2, -limit), limit)
        rs = rotation_body_to_ned(*self._q)
        fn, fe, fd = a0, a1, a2 - GRAVITY_M_S2
        # the specific force in the smoothed body: R_s^T (a - g)
        self._accel = (rs[0][0] * fn + rs[1][0] * fe + rs[2][0] * fd, rs[0][1] * fn + rs[1][1] * fe + rs[2][1] * fd,
                       rs[0][2] * fn + rs[1][2] * fe + rs[2][2] * fd)
        # the body-frame rotation from the smoothed attitude to the true one (AP's Quaternion operator/)
        sq = self._q
        w, x, y, z = _multiply((sq[0], -sq[1], -sq[2], -sq[3]), q)
        if w < 0:
            w, x, y, z = -w, -x, -y, -z
        sin_half = math.sqrt(x * x + y * y + z * z)
        gain = 2.0 * math.atan2(sin_half, w) / (sin_half * tc) if sin_half > 1e-12 else 0.0
        gyro = state.gyro_frd_rad_s
        self._gyro = (gyro[0] + x * gain, gyro[1] + y * gain, gyro[2] + z * gain)
        g0, g1, g2 = self._gyro
        rate = math.sqrt(g0 * g0 + g1 * g1 + g2 * g2)
        if rate * dt_s > 1e-12:
            half = 0.5 * rate * dt_s
            k = math.sin(half) / rate
            nw, nx, ny, nz = _multiply(sq, (math.cos(half), g0 * k, g1 * k, g2 * k))
            norm = math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
            self._q = (nw / norm, nx / norm, ny / norm, nz / norm)
        # velocity, then position with the new velocity (as SITL)
        v0, v1, v2 = sv[0] + a0 * dt_s, sv[1] + a1 * dt_s, sv[2] + a2 * dt_s
        self._v = [v0, v1, v2]
        self._p = [sp[0] + v0 * dt_s, sp[1] + v1 * dt_s, sp[2] + v2 * dt_s]

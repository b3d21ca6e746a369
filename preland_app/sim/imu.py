"""A gyro error for preland's physics under ArduPilot SITL (the JSON bridge), to study the attitude
estimate's share of a landing's error.

The embedded simulator models the autopilot's roll and pitch estimate error directly (`NavigationSpec`'s
`attitude_noise_sigma_deg` and `attitude_noise_tau_s`: vibration and EKF error). Under SITL, ArduCopter's
own EKF makes the estimate from the IMU the physics sends: told the true body rates, it estimates roll and
pitch within about 0.1 degree rms (ArduCopter 4.6.3, `benchmarks/sitl_attitude_error.py`). A `GyroError`
adds to the roll and pitch rates SITL is told a Gauss-Markov error with the mission's time constant and a
standard deviation `per_attitude_error` (1/s) times the mission's attitude error, so that ArduCopter's EKF
errs by about as much as the embedded estimate does. It is off unless asked for (`sitl:` option
`gyro_error`): no source gives the IMU error that makes the field's estimate error, and with one of this form
ArduCopter lands much further off than the field did (docs: explanation, "SITL and the embedded simulator").
"""

from __future__ import annotations

import math

from .multirotor import MultirotorState
from .noise import GaussianStream, GaussMarkov, child_rng
from .spec import NavigationSpec

STREAM = "sitl_imu"
"""The trial seed's stream the gyro error draws from (its own, so no other stream's draws move)."""


class GyroError:
    """A Gauss-Markov error on the body roll and pitch rates (rad/s, FRD x and y), stepped with the physics."""

    __slots__ = ("_roll", "_pitch")

    def __init__(self, *, sigma_rad_s: float, tau_s: float, seed: int) -> None:
        noise = GaussianStream(child_rng(seed, STREAM))
        self._roll = GaussMarkov(sigma=sigma_rad_s, tau_s=tau_s, noise=noise)
        self._pitch = GaussMarkov(sigma=sigma_rad_s, tau_s=tau_s, noise=noise)

    @classmethod
    def for_mission(cls, spec: NavigationSpec, *, seed: int, per_attitude_error: float) -> "GyroError | None":
        """The error for a mission's navigation spec: `per_attitude_error` (1/s) times its attitude error
        (rad/s per rad), its time constant; None (a true IMU) when either is 0."""
        sigma_rad_s = math.radians(spec.attitude_noise_sigma_deg) * per_attitude_error
        return cls(sigma_rad_s=sigma_rad_s, tau_s=spec.attitude_noise_tau_s, seed=seed) if sigma_rad_s > 0 else None

    def applied(self, state: MultirotorState, dt_s: float) -> MultirotorState:
        """`state` with the error, stepped by `dt_s` (s), added to its body rates; the rest as it is."""
        p, q, r = state.gyro_frd_rad_s
        return MultirotorState(time_s=state.time_s, position_ned_m=state.position_ned_m,
                               velocity_ned_m_s=state.velocity_ned_m_s, quaternion_wxyz=state.quaternion_wxyz,
                               gyro_frd_rad_s=(p + self._roll.step(dt_s), q + self._pitch.step(dt_s), r),
                               accel_frd_m_s2=state.accel_frd_m_s2, motor_commands=state.motor_commands,
                               on_ground=state.on_ground, rangefinder_down_m=state.rangefinder_down_m)

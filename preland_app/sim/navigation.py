"""The vehicle's own estimate of where it is: GPS/EKF position error, barometer, rangefinder.

The autopilot controls on these estimates, never on the true state, as a real
one does. Frames: positions are NED in metres relative to the simulation origin
(the true take-off spot); the estimate's error is added to the truth.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .dynamics import GRAVITY_M_S2
from .noise import GaussianStream, GaussMarkov, SmoothGaussMarkov, child_rng
from .spec import NavigationSpec

# Each error source draws from its own named stream of the trial seed, so switching one source on, off or
# to another magnitude never changes what the others draw.
NAVIGATION_STREAMS = ("gps", "baro", "imu", "rangefinder", "velocity", "attitude", "heading")

_FAST_NOISE_TAU_S = 1.0
_BARO_NOISE_TAU_S = 0.3


@dataclass(slots=True, kw_only=True)
class NavEstimate:
    """One navigation output. Positions NED in m from the simulation origin."""

    position_ok: bool
    north_m: float
    east_m: float
    down_m: float
    velocity_north_m_s: float
    velocity_east_m_s: float
    velocity_down_m_s: float
    rangefinder_m: float | None
    gps_error_north_m: float
    gps_error_east_m: float
    roll_error_rad: float = 0.0
    pitch_error_rad: float = 0.0
    heading_error_rad: float = 0.0
    delta_velocity_north_m_s: float = 0.0
    delta_velocity_east_m_s: float = 0.0


class GpsPositionError:
    """The GPS position error, north and east (m): a slow drift (per axis a Gauss-Markov process of stationary
    std `gps_drift_sigma_m` and time constant `gps_drift_tau_s`, low-pass filtered over `gps_drift_smooth_s`)
    plus a fast noise (`position_noise_sigma_m`, 1 s correlation), all drawing from the trial seed's `gps`
    stream in one fixed order. The embedded autopilot's estimate and SITL's glitch offsets step the same one,
    so a seed gives the same drift path on both."""

    def __init__(self, *, spec: NavigationSpec, noise: GaussianStream) -> None:
        self._drift_north, self._drift_east = (
            SmoothGaussMarkov(sigma=spec.gps_drift_sigma_m, tau_s=spec.gps_drift_tau_s,
                              smooth_s=spec.gps_drift_smooth_s, noise=noise) for _ in range(2))
        self._fast_north = GaussMarkov(sigma=spec.position_noise_sigma_m, tau_s=_FAST_NOISE_TAU_S, noise=noise)
        self._fast_east = GaussMarkov(sigma=spec.position_noise_sigma_m, tau_s=_FAST_NOISE_TAU_S, noise=noise)

    @classmethod
    def for_seed(cls, spec: NavigationSpec, seed: int) -> "GpsPositionError":
        return cls(spec=spec, noise=GaussianStream(child_rng(seed, "gps")))

    def step(self, dt_s: float) -> tuple[float, float]:
        """Advance by `dt_s` seconds; the whole error (drift plus fast noise), north and east in m."""
        north = self._drift_north.step(dt_s) + self._fast_north.step(dt_s)
        east = self._drift_east.step(dt_s) + self._fast_east.step(dt_s)
        return north, east

    @property
    def drift_ne_m(self) -> tuple[float, float]:
        """The drift alone, north and east (m)."""
        return self._drift_north.value, self._drift_east.value


class NavigationModel:
    """Turns the true state into the autopilot's estimate, with seeded errors."""

    def __init__(self, *, spec: NavigationSpec, rangefinder_min_m: float, rangefinder_max_m: float,
                 seed: int) -> None:
        self.spec = spec
        self.rangefinder_min_m = rangefinder_min_m
        self.rangefinder_max_m = rangefinder_max_m
        streams = {name: GaussianStream(child_rng(seed, name)) for name in NAVIGATION_STREAMS}
        gps, baro, attitude = streams["gps"], streams["baro"], streams["attitude"]
        self._imu_noise = streams["imu"]
        self._rangefinder_noise = streams["rangefinder"]
        self._velocity_noise = streams["velocity"]
        self._gps_error = GpsPositionError(spec=spec, noise=gps)
        self._baro_drift = GaussMarkov(sigma=spec.baro_drift_sigma_m, tau_s=spec.baro_drift_tau_s, noise=baro)
        self._baro_noise = GaussMarkov(sigma=spec.baro_noise_sigma_m, tau_s=_BARO_NOISE_TAU_S, noise=baro)
        attitude_sigma = math.radians(spec.attitude_noise_sigma_deg)
        self._roll_error = GaussMarkov(sigma=attitude_sigma, tau_s=spec.attitude_noise_tau_s, noise=attitude)
        self._pitch_error = GaussMarkov(sigma=attitude_sigma, tau_s=spec.attitude_noise_tau_s, noise=attitude)
        self._heading_error = GaussMarkov(sigma=math.radians(spec.heading_error_sigma_deg),
                                          tau_s=spec.heading_error_tau_s, noise=streams["heading"])
        # The EKF's height origin is set at boot, so only the baro's change since then counts.
        self._baro_origin_m = self._baro_drift.value + self._baro_noise.value
        self._previous_velocity: tuple[float, float] | None = None
        self.elapsed_s = 0.0
        # The error processes' steps, looked up once (called ~12 times a physics step).
        self._gps_step = self._gps_error.step
        self._baro_steps = self._baro_drift.step, self._baro_noise.step
        self._attitude_steps = self._roll_error.step, self._pitch_error.step, self._heading_error.step

    @property
    def gps_drift_ne_m(self) -> tuple[float, float]:
        """The GPS error's slow drift now, north and east (m)."""
        return self._gps_error.drift_ne_m

    def step(self, *, dt_s: float, north_m: float, east_m: float, down_m: float,
             velocity_ned_m_s: tuple[float, float, float], tilt_cos: float, yaw_rad: float) -> NavEstimate:
        """Advance error processes by `dt_s` and return the estimate of the given true state.

        `yaw_rad` (true heading, NED) turns the attitude error's gravity leak from body to NED axes.
        """
        self.elapsed_s += dt_s
        spec = self.spec
        error_north, error_east = self._gps_step(dt_s)
        baro_drift_step, baro_noise_step = self._baro_steps
        error_down = -(baro_drift_step(dt_s) + baro_noise_step(dt_s) - self._baro_origin_m)
        velocity_sigma = spec.velocity_noise_sigma_m_s
        imu_next = self._imu_noise.next
        true_north_m_s, true_east_m_s, true_down_m_s = velocity_ned_m_s
        # IMU delta-velocity over the step (true change plus accelerometer noise, plus the gravity
        # leak below).
        previous = self._previous_velocity or (true_north_m_s, true_east_m_s)
        self._previous_velocity = (true_north_m_s, true_east_m_s)
        accel_noise = spec.imu_accel_noise_m_s2 * dt_s
        delta_north = true_north_m_s - previous[0] + accel_noise * imu_next()
        delta_east = true_east_m_s - previous[1] + accel_noise * imu_next()
        rangefinder_m = None
        if spec.rangefinder_present:
            height_m = -down_m
            slant_m = height_m / max(tilt_cos, 0.3) + spec.rangefinder_noise_sigma_m * self._rangefinder_noise.next()
            if self.rangefinder_min_m <= slant_m <= self.rangefinder_max_m:
                rangefinder_m = slant_m * tilt_cos
        velocity_next = self._velocity_noise.next
        velocity_north_m_s = true_north_m_s + velocity_sigma * velocity_next()
        velocity_east_m_s = true_east_m_s + velocity_sigma * velocity_next()
        velocity_down_m_s = true_down_m_s + velocity_sigma * velocity_next()
        roll_step, pitch_step, heading_step = self._attitude_steps
        roll_error_rad = roll_step(dt_s)
        pitch_error_rad = pitch_step(dt_s)
        heading_error_rad = heading_step(dt_s)
        # The EKF rotates the accelerometers' specific force (about g upwards) with its own attitude,
        # so an attitude error leaks gravity into the NED delta-velocity: body (forward, right)
        # error (-g * pitch error, g * roll error). It is what makes dead-reckoning between sensor
        # values drift.
        leak_forward = -GRAVITY_M_S2 * pitch_error_rad * dt_s
        leak_right = GRAVITY_M_S2 * roll_error_rad * dt_s
        cos_yaw, sin_yaw = math.cos(yaw_rad), math.sin(yaw_rad)
        delta_north += cos_yaw * leak_forward - sin_yaw * leak_right
        delta_east += sin_yaw * leak_forward + cos_yaw * leak_right
        return NavEstimate(
            position_ok=self.elapsed_s >= spec.gps_fix_delay_s,
            north_m=north_m + error_north,
            east_m=east_m + error_east,
            down_m=down_m + error_down,
            velocity_north_m_s=velocity_north_m_s,
            velocity_east_m_s=velocity_east_m_s,
            velocity_down_m_s=velocity_down_m_s,
            rangefinder_m=rangefinder_m,
            gps_error_north_m=error_north,
            gps_error_east_m=error_east,
            roll_error_rad=roll_error_rad,
            pitch_error_rad=pitch_error_rad,
            heading_error_rad=heading_error_rad,
            delta_velocity_north_m_s=delta_north,
            delta_velocity_east_m_s=delta_east,
        )


def tilt_cosine(roll_rad: float, pitch_rad: float) -> float:
    """cos of the angle between body down and earth down."""
    return math.cos(roll_rad) * math.cos(pitch_rad)

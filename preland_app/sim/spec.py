"""What the embedded simulator is configured with: frozen dataclasses with defaults.

Missions and campaigns override any of these fields by name (`environment:`
in YAML); unknown names are rejected at load time. Defaults are chosen so that
a GPS-only landing misses by what the sources report (docs: explanation, "The error model").
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from ..errors import require as _require
from ..geo import GeoPoint

# ArduPilot SITL's default home (CMAC, Canberra): a neutral, well-known place.
DEFAULT_HOME = GeoPoint(latitude_deg=-35.363261, longitude_deg=149.165230, altitude_amsl_m=584.0)


@dataclass(frozen=True)
class WindSpec:
    """Steady wind plus Dryden-style turbulence (MIL-F-8785C low-altitude scales).

    `direction_from_deg`: where the wind blows from, degrees clockwise from
    north; None draws it uniformly per trial. `turbulence_w20_m_s`: the wind
    speed at 20 ft that sets gust intensity (sigma_w = 0.1 W20); 0 disables gusts.
    """

    speed_m_s: float = 1.5
    direction_from_deg: float | None = None
    turbulence_w20_m_s: float = 2.0

    def __post_init__(self) -> None:
        _require(self.speed_m_s >= 0, "speed_m_s", "must be >= 0")
        _require(self.turbulence_w20_m_s >= 0, "turbulence_w20_m_s", "must be >= 0")


@dataclass(frozen=True)
class GroundEffectSpec:
    """Rotor wash recirculating near the ground, felt as a horizontal air velocity (NED, m/s).

    A rotor near the ground sends its wash outward along it, and part of it recirculates through the
    rotors unevenly, so a hovering or descending vehicle is pushed about at random in the last part of a
    landing. Modelled as a first-order Gauss-Markov velocity per horizontal axis with time constant
    `tau_s`, whose standard deviation is `sigma_m_s` at the ground and falls linearly to 0 at `height_m`.
    `height_m` 0.5: ground effect on a rotor's thrust is below 1.6 % beyond two rotor radii and fades by
    four (Cheeseman & Bennett, 1955), four radii of the 10-inch propellers of a thesis-sized hexacopter.
    No source gives the lateral velocity's size: `sigma_m_s` is 0 (off) by default and calibratable.
    """

    sigma_m_s: float = 0.0
    height_m: float = 0.5
    tau_s: float = 0.5

    def __post_init__(self) -> None:
        _require(self.sigma_m_s >= 0, "sigma_m_s", "must be >= 0")
        _require(self.height_m > 0, "height_m", "must be > 0")
        _require(self.tau_s > 0, "tau_s", "must be > 0")


@dataclass(frozen=True)
class NavigationSpec:
    """Errors of the vehicle's own position estimate (what a GPS+EKF autopilot believes).

    The horizontal GPS error is a slowly varying bias (a Gauss-Markov process,
    stationary std `gps_drift_sigma_m`, time constant `gps_drift_tau_s`,
    low-pass filtered with `gps_drift_smooth_s` so it wanders smoothly) plus
    fast noise (`position_noise_sigma_m`, time constant 1 s). Barometric
    altitude drifts (`baro_drift_sigma_m`, `baro_drift_tau_s`) and is noisy; the
    downward rangefinder is accurate within its range. The attitude estimate
    (roll and pitch) wanders around the truth (`attitude_noise_sigma_deg`,
    time constant `attitude_noise_tau_s`: vibration and EKF error), which is
    what turns a camera or IR-LOCK angle into a position error h * tan(error).
    The heading estimate is off by a slowly varying error (`heading_error_sigma_deg`,
    `heading_error_tau_s`: compass calibration and local magnetic disturbance), which
    rotates every body-frame target measurement on its way to NED.
    """

    gps_drift_sigma_m: float = 0.75
    gps_drift_tau_s: float = 120.0
    gps_drift_smooth_s: float = 10.0
    position_noise_sigma_m: float = 0.05
    velocity_noise_sigma_m_s: float = 0.05
    gps_fix_delay_s: float = 3.0
    baro_drift_sigma_m: float = 0.3
    baro_drift_tau_s: float = 300.0
    baro_noise_sigma_m: float = 0.05
    rangefinder_noise_sigma_m: float = 0.02
    rangefinder_present: bool = True
    attitude_noise_sigma_deg: float = 0.7
    attitude_noise_tau_s: float = 0.5
    imu_accel_noise_m_s2: float = 0.1
    heading_error_sigma_deg: float = 1.5
    heading_error_tau_s: float = 300.0

    def __post_init__(self) -> None:
        for name in (
            "gps_drift_sigma_m",
            "position_noise_sigma_m",
            "velocity_noise_sigma_m_s",
            "gps_fix_delay_s",
            "baro_drift_sigma_m",
            "baro_noise_sigma_m",
            "rangefinder_noise_sigma_m",
            "attitude_noise_sigma_deg",
            "imu_accel_noise_m_s2",
            "heading_error_sigma_deg",
        ):
            _require(getattr(self, name) >= 0, name, "must be >= 0")
        _require(self.gps_drift_tau_s > 0, "gps_drift_tau_s", "must be > 0")
        _require(self.gps_drift_smooth_s > 0, "gps_drift_smooth_s", "must be > 0")
        _require(self.baro_drift_tau_s > 0, "baro_drift_tau_s", "must be > 0")
        _require(self.attitude_noise_tau_s > 0, "attitude_noise_tau_s", "must be > 0")
        _require(self.heading_error_tau_s > 0, "heading_error_tau_s", "must be > 0")


@dataclass(frozen=True)
class AirframeSpec:
    """The multirotor's response, folded into first-order lags (docs: explanation, "The error model").

    `attitude_tau_s`: lean-angle response to a lean demand; `thrust_tau_s`:
    vertical-acceleration response to the autopilot's acceleration demand (motors and
    the z acceleration loop; the climb-rate loop around it is PSC_VELZ_P's); `drag_per_s`: linear drag of the
    air-relative velocity (1/s); `crash_speed_m_s`: vertical touchdown speed
    above which the touchdown is a crash.
    """

    attitude_tau_s: float = 0.15
    thrust_tau_s: float = 0.1
    yaw_rate_max_deg_s: float = 60.0
    drag_per_s: float = 0.35
    crash_speed_m_s: float = 3.0
    battery_capacity_mah: float = 5000.0
    hover_current_a: float = 18.0
    battery_cells: int = 4

    def __post_init__(self) -> None:
        for name in ("attitude_tau_s", "thrust_tau_s", "yaw_rate_max_deg_s", "crash_speed_m_s"):
            _require(getattr(self, name) > 0, name, "must be > 0")
        _require(self.drag_per_s >= 0, "drag_per_s", "must be >= 0")
        _require(self.battery_capacity_mah > 0, "battery_capacity_mah", "must be > 0")
        _require(self.battery_cells >= 1, "battery_cells", "must be >= 1")


class Firmware(enum.Enum):
    """The ArduCopter release whose precision landing the embedded autopilot follows."""

    # The thesis' drone (ArduCopter 3.6/4.0, whose precision landing is the same): the estimator's
    # target-relative velocity feeds the horizontal velocity loop, and a target is used from its first reading.
    COPTER_4_0 = "copter-4.0"
    # ArduCopter 4.1 and later, as ArduPilot SITL 4.6.3 flies: the velocity loop stays on the EKF's velocity, a
    # target is used after 2 s of readings without a 0.5 s gap, and the filter starts at minus the vehicle's
    # velocity (AC_PrecLand::run_estimator, check_ekf_init_timeout; mode.cpp land_run_horizontal_control).
    COPTER_4_6 = "copter-4.6"


@dataclass(frozen=True)
class AutopilotSpec:
    """The embedded autopilot. `firmware`: whose precision landing and LAND entry it follows (`copter-4.0`, the
    thesis' and the default, or `copter-4.6`). SITL and a real vehicle fly their own firmware."""

    firmware: Firmware = Firmware.COPTER_4_0


@dataclass(frozen=True)
class EnvironmentSpec:
    """Everything about the simulated world a mission or scenario may override."""

    wind: WindSpec = field(default_factory=WindSpec)
    ground_effect: GroundEffectSpec = field(default_factory=GroundEffectSpec)
    navigation: NavigationSpec = field(default_factory=NavigationSpec)
    airframe: AirframeSpec = field(default_factory=AirframeSpec)
    autopilot: AutopilotSpec = field(default_factory=AutopilotSpec)
    physics_rate_hz: float = 100.0

    def __post_init__(self) -> None:
        _require(20.0 <= self.physics_rate_hz <= 1000.0, "physics_rate_hz", "must be within 20..1000")

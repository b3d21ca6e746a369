"""The embedded simulator: one multirotor, its autopilot, its sensors' errors and the wind.

Deterministic for a given seed: every random stream is a named child of the
trial seed. Physics and control run at `EnvironmentSpec.physics_rate_hz` in
simulated time; `run()` paces steps on a Clock, so on a virtual-time loop a
simulated minute costs only the CPU it needs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..clock import Clock
from ..geo import GeoPoint
from .autopilot import Autopilot
from .dynamics import BodyState, MultirotorDynamics, Touchdown
from .air import AirAtVehicle
from .navigation import NavEstimate, NavigationModel, tilt_cosine
from .params import ParameterTable
from .spec import DEFAULT_HOME, EnvironmentSpec

# Physics steps taken in a row without yielding to the event loop (virtual time only), at most.
_STEPS_WITHOUT_YIELD = 50


@dataclass(frozen=True, slots=True)
class TruePose:
    """Ground truth: NED in m from the simulation origin (the take-off spot), attitude in rad."""

    time_s: float
    north_m: float
    east_m: float
    down_m: float
    roll_rad: float
    pitch_rad: float
    yaw_rad: float
    on_ground: bool


class Simulator:
    """A simulated vehicle and its world. Ground truth is read here and only for scoring and rendering."""

    def __init__(
        self,
        *,
        seed: int,
        environment: EnvironmentSpec | None = None,
        origin: GeoPoint = DEFAULT_HOME,
        params: dict[str, float] | None = None,
        initial_yaw_deg: float = 0.0,
    ) -> None:
        self.seed = seed
        self.environment = environment or EnvironmentSpec()
        self.origin = origin
        self.dt_s = 1.0 / self.environment.physics_rate_hz
        self.time_s = 0.0
        self.params = ParameterTable(params)
        self.air = AirAtVehicle(environment=self.environment, seed=seed)
        self.wind = self.air.wind
        self.navigation = NavigationModel(
            spec=self.environment.navigation,
            rangefinder_min_m=self.params.m_s("RNGFND1_MIN_CM"),
            rangefinder_max_m=self.params.m_s("RNGFND1_MAX_CM"),
            seed=seed,
        )
        yaw_rad = math.radians(initial_yaw_deg)
        self.dynamics = MultirotorDynamics(airframe=self.environment.airframe, state=BodyState(yaw_rad=yaw_rad))
        self.autopilot = Autopilot(params=self.params, initial_yaw_rad=yaw_rad,
                                   firmware=self.environment.autopilot.firmware)
        self.battery_used_mah = 0.0
        self.steps = 0
        self.nav: NavEstimate = self._estimate(0.0)
        # Give the autopilot its first estimate so commands can be checked before the first step.
        self.autopilot.nav = self.nav

    def _estimate(self, dt_s: float) -> NavEstimate:
        s = self.dynamics.state
        return self.navigation.step(
            dt_s=dt_s,
            north_m=s.north_m,
            east_m=s.east_m,
            down_m=s.down_m,
            velocity_ned_m_s=(s.velocity_north_m_s, s.velocity_east_m_s, s.velocity_down_m_s),
            tilt_cos=tilt_cosine(s.roll_rad, s.pitch_rad),
            yaw_rad=s.yaw_rad,
        )

    def step(self) -> None:
        """Advance the world by one physics step."""
        dt_s = self.dt_s
        s = self.dynamics.state
        wind = self.air.step(dt_s=dt_s, height_m=-s.down_m,
                             velocity_ned_m_s=(s.velocity_north_m_s, s.velocity_east_m_s, s.velocity_down_m_s))
        demand = self.autopilot.step(dt_s=dt_s, now_s=self.time_s, nav=self.nav, yaw_rad=s.yaw_rad,
                                     touching_ground=s.on_ground, roll_rad=s.roll_rad, pitch_rad=s.pitch_rad)
        self.dynamics.step(dt_s=dt_s, time_s=self.time_s + dt_s, demand=demand, wind_ned_m_s=wind)
        self.time_s += dt_s
        self.steps += 1
        self.nav = self._estimate(dt_s)
        self._drain_battery(dt_s, demand.motors_armed, s.on_ground)

    def _drain_battery(self, dt_s: float, armed: bool, on_ground: bool) -> None:
        airframe = self.environment.airframe
        if armed:
            current_a = 1.5 if on_ground else airframe.hover_current_a
        else:
            current_a = 0.3
        self.battery_used_mah += current_a * dt_s / 3.6

    def battery_remaining_fraction(self) -> float:
        return max(0.0, 1.0 - self.battery_used_mah / self.environment.airframe.battery_capacity_mah)

    def battery_voltage_v(self) -> float:
        # A simple linear LiPo curve, 4.2 V full to 3.5 V empty per cell.
        return self.environment.airframe.battery_cells * (3.5 + 0.7 * self.battery_remaining_fraction())

    async def run(self, clock: Clock) -> None:
        """Step the world forever, one physics step per `dt_s` of `clock` time."""
        dt_s = self.dt_s
        skip_alone = getattr(clock, "skip_alone", None)
        while True:
            await clock.sleep(dt_s)
            self.step()
            if skip_alone is None:
                continue
            # In virtual time, the steps until another task's timer need no trip through the event loop
            # (the same steps at the same times); a bounded run keeps real I/O polled.
            for _ in range(_STEPS_WITHOUT_YIELD):
                if not skip_alone(dt_s):
                    break
                self.step()

    # ------------------------------------------------------------------ truth (scoring and rendering only)

    def true_pose(self) -> TruePose:
        s = self.dynamics.state
        return TruePose(self.time_s, s.north_m, s.east_m, s.down_m, s.roll_rad, s.pitch_rad, s.yaw_rad, s.on_ground)

    def touchdowns(self) -> list[Touchdown]:
        return list(self.dynamics.state.touchdowns)

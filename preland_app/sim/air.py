"""The air at the vehicle: the scenario's wind and Dryden gusts plus the rotor wash near the ground, one
model for every physics preland runs (the embedded simulator's, and its quad X under ArduPilot SITL).

Both draw from the trial seed's `wind` and `ground_effect` streams, so a seed blows the same steady wind
from the same direction on both, with the same gust and wash statistics. The gust path itself is the same
where both take the same step (the embedded simulator at `physics_rate_hz: 400`, SITL's loop rate) and start
their flight at the same point of it: SITL's physics starts the air when its motors first turn, after
`lead_on_ground_s` stepped at rest, the embedded simulator's time on the ground before its arming.
"""

from __future__ import annotations

import math

from .environment import WindModel
from .ground_effect import GroundEffectFlow
from .noise import child_rng
from .spec import EnvironmentSpec


class AirAtVehicle:
    """The velocity of the air at the vehicle, NED in m/s, stepped with the vehicle's motion."""

    def __init__(self, *, environment: EnvironmentSpec, seed: int, lead_on_ground_s: float = 0.0) -> None:
        self.wind = WindModel(spec=environment.wind, rng=child_rng(seed, "wind"))
        self.ground_effect = GroundEffectFlow(spec=environment.ground_effect, rng=child_rng(seed, "ground_effect"))
        self._lead_s = lead_on_ground_s  # stepped at rest, in steps of the first step's size, before it

    def step(self, *, dt_s: float, height_m: float, velocity_ned_m_s: tuple[float, float, float]
             ) -> tuple[float, float, float]:
        """Advance by `dt_s` with the vehicle `height_m` above the ground moving at `velocity_ned_m_s`
        (m/s); returns the air's velocity (NED, m/s): wind, gusts and, near the ground, the wash."""
        if self._lead_s > 0.0:
            for _ in range(round(self._lead_s / dt_s)):
                self._step(dt_s=dt_s, height_m=0.0, velocity_ned_m_s=(0.0, 0.0, 0.0))
            self._lead_s = 0.0
        return self._step(dt_s=dt_s, height_m=height_m, velocity_ned_m_s=velocity_ned_m_s)

    def _step(self, *, dt_s: float, height_m: float, velocity_ned_m_s: tuple[float, float, float]
              ) -> tuple[float, float, float]:
        current = self.wind.current_ned_m_s  # the gusts' speed scale follows the airspeed of the last step
        airspeed_m_s = math.hypot(velocity_ned_m_s[0] - current[0], velocity_ned_m_s[1] - current[1])
        wind = self.wind.step(dt_s=dt_s, altitude_m=height_m, airspeed_m_s=airspeed_m_s)
        if self.ground_effect.enabled:
            wash_north, wash_east = self.ground_effect.step(dt_s=dt_s, height_m=height_m)
            wind = (wind[0] + wash_north, wind[1] + wash_east, wind[2])
        return wind

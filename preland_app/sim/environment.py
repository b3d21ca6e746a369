"""Wind: a steady component plus Dryden-style turbulence.

Turbulence scales and intensities follow the MIL-F-8785C low-altitude model
(altitude h in feet, W20 the wind speed at 20 ft):

    L_w = h,  L_u = L_v = h / (0.177 + 0.000823 h)^1.2
    sigma_w = 0.1 W20,  sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4

Each component is a first-order Gauss-Markov process with time constant L / V
(V: the air-relative speed, at least 1 m/s so a hovering vehicle still sees
gusts). This keeps the Dryden spectrum's corner frequency and variance; the
true Dryden lateral and vertical filters are second order.
"""

from __future__ import annotations

import math

import numpy as np

from .noise import GaussianStream, GaussMarkov
from .spec import WindSpec

_FT_PER_M = 3.28084
_MIN_AIRSPEED_M_S = 1.0


def dryden_scales(*, altitude_m: float, w20_m_s: float) -> tuple[float, float, float, float]:
    """(L_u_m, L_w_m, sigma_u_m_s, sigma_w_m_s) at `altitude_m` above ground."""
    h_ft = min(max(altitude_m * _FT_PER_M, 10.0), 1000.0)
    denominator = 0.177 + 0.000823 * h_ft
    length_u_m = h_ft / denominator**1.2 / _FT_PER_M
    length_w_m = h_ft / _FT_PER_M
    sigma_w = 0.1 * w20_m_s
    sigma_u = sigma_w / denominator**0.4
    return length_u_m, length_w_m, sigma_u, sigma_w


class WindModel:
    """Wind velocity in m/s, NED (the velocity of the air), at the vehicle."""

    def __init__(self, *, spec: WindSpec, rng: np.random.Generator) -> None:
        self.spec = spec
        direction_from_deg = (
            spec.direction_from_deg if spec.direction_from_deg is not None else float(rng.uniform(0.0, 360.0))
        )
        self.direction_from_deg = direction_from_deg
        # Air moves *towards* the opposite of where it comes from.
        towards_rad = math.radians(direction_from_deg + 180.0)
        self._unit_north = math.cos(towards_rad)
        self._unit_east = math.sin(towards_rad)
        self.steady_ned_m_s = (spec.speed_m_s * self._unit_north, spec.speed_m_s * self._unit_east, 0.0)
        noise = GaussianStream(rng)
        length_u, length_w, sigma_u, sigma_w = dryden_scales(altitude_m=10.0, w20_m_s=spec.turbulence_w20_m_s)
        tau_u = length_u / max(spec.speed_m_s, _MIN_AIRSPEED_M_S)
        tau_w = length_w / max(spec.speed_m_s, _MIN_AIRSPEED_M_S)
        self._gust_u = GaussMarkov(sigma=sigma_u, tau_s=tau_u, noise=noise)
        self._gust_v = GaussMarkov(sigma=sigma_u, tau_s=tau_u, noise=noise)
        self._gust_w = GaussMarkov(sigma=sigma_w, tau_s=tau_w, noise=noise)
        self._retune_every_s = 0.5
        self._since_retune_s = 0.0
        self.current_ned_m_s = self.steady_ned_m_s

    def step(self, *, dt_s: float, altitude_m: float, airspeed_m_s: float) -> tuple[float, float, float]:
        """Advance the gusts by `dt_s` at `altitude_m`; returns wind NED in m/s."""
        if self.spec.turbulence_w20_m_s <= 0.0:
            return self.current_ned_m_s
        self._since_retune_s += dt_s
        if self._since_retune_s >= self._retune_every_s:
            # Scales change slowly with altitude and airspeed: retune at 2 Hz.
            self._since_retune_s = 0.0
            length_u, length_w, sigma_u, sigma_w = dryden_scales(
                altitude_m=altitude_m, w20_m_s=self.spec.turbulence_w20_m_s
            )
            speed = max(airspeed_m_s, _MIN_AIRSPEED_M_S)
            self._gust_u.retune(sigma=sigma_u, tau_s=length_u / speed)
            self._gust_v.retune(sigma=sigma_u, tau_s=length_u / speed)
            self._gust_w.retune(sigma=sigma_w, tau_s=length_w / speed)
        u = self._gust_u.step(dt_s)
        v = self._gust_v.step(dt_s)
        w = self._gust_w.step(dt_s)
        # u along the mean wind, v across it (to its right), w up.
        north = self.steady_ned_m_s[0] + u * self._unit_north - v * self._unit_east
        east = self.steady_ned_m_s[1] + u * self._unit_east + v * self._unit_north
        self.current_ned_m_s = (north, east, -w)
        return self.current_ned_m_s

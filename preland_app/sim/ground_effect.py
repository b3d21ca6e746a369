"""Rotor wash recirculating near the ground (see `GroundEffectSpec`): a horizontal air velocity, NED, m/s."""

from __future__ import annotations

import numpy as np

from .noise import GaussianStream, GaussMarkov
from .spec import GroundEffectSpec


class GroundEffectFlow:
    """The recirculating wash at the vehicle. Off (no draws from its stream) when `sigma_m_s` is 0, so
    turning it on shifts no other source's random values."""

    def __init__(self, *, spec: GroundEffectSpec, rng: np.random.Generator) -> None:
        self.spec = spec
        self.enabled = spec.sigma_m_s > 0
        noise = GaussianStream(rng)
        # Unit processes, scaled by height: stationary whatever the flight does above the ground.
        self._north = GaussMarkov(sigma=1.0, tau_s=spec.tau_s, noise=noise) if self.enabled else None
        self._east = GaussMarkov(sigma=1.0, tau_s=spec.tau_s, noise=noise) if self.enabled else None

    def sigma_at_m_s(self, height_m: float) -> float:
        """The standard deviation of the flow at `height_m` above the ground (m/s)."""
        return self.spec.sigma_m_s * max(0.0, 1.0 - max(height_m, 0.0) / self.spec.height_m)

    def step(self, *, dt_s: float, height_m: float) -> tuple[float, float]:
        """Advance by `dt_s`; the flow (north, east) in m/s at `height_m` above the ground."""
        if not self.enabled:
            return 0.0, 0.0
        north, east = self._north.step(dt_s), self._east.step(dt_s)
        scale = self.sigma_at_m_s(height_m)
        return north * scale, east * scale

"""The land modes preland knows, by the name missions and the CLI use."""

from __future__ import annotations

from collections.abc import Callable

from .base import LandStrategy
from .normal import NormalLanding
from .precision import PrecisionLanding

LAND_MODES: dict[str, Callable[[], LandStrategy]] = {
    "normal": NormalLanding,
    "irlock": lambda: PrecisionLanding("irlock"),
    "marker": lambda: PrecisionLanding("marker"),
    "fused": lambda: PrecisionLanding("fused"),
}


def land_mode_names() -> list[str]:
    return sorted(LAND_MODES)


def create_land_strategy(name: str) -> LandStrategy:
    """A fresh strategy for `name`; raises KeyError naming the known modes."""
    try:
        factory = LAND_MODES[name]
    except KeyError:
        raise KeyError(f"unknown land mode {name!r} (expected one of: {', '.join(land_mode_names())})") from None
    return factory()

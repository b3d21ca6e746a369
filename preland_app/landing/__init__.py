"""Land modes (strategies): normal, the precision modes (irlock, marker, fused) and cautious."""

from .base import LandingContext, LandingReport, LandStrategy, ScoringReference
from .registry import LAND_MODES, create_land_strategy, land_mode_names

__all__ = [
    "LAND_MODES",
    "LandStrategy",
    "LandingContext",
    "LandingReport",
    "ScoringReference",
    "create_land_strategy",
    "land_mode_names",
]

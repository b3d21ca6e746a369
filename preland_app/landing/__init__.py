"""Land modes (strategies): normal now; precision, cautious and the paper's algorithms plug in here."""

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

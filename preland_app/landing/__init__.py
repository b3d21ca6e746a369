"""Land modes (strategies): the built-in ones, the registry that finds plugins, and the contract they share.

A land mode of your own implements `LandStrategy` and gets a `LandingContext`
(see `base.py` for the contract, `boundary.py` for what the context holds).
"""

from .base import LandingContext, LandingReport, LandStrategy, ScoringReference
from .boundary import MarkerFrame
from .plugins import ENTRY_POINT_GROUP
from .registry import LAND_MODES, create_land_strategy, find_land_mode, land_mode_names

__all__ = [
    "ENTRY_POINT_GROUP",
    "LAND_MODES",
    "LandStrategy",
    "LandingContext",
    "LandingReport",
    "MarkerFrame",
    "ScoringReference",
    "create_land_strategy",
    "find_land_mode",
    "land_mode_names",
]

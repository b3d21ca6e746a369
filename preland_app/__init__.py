"""preland: automated precision-landing missions for multirotor drones."""

__version__ = "0.1.0"

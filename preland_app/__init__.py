"""preland: automated precision-landing missions for multirotor drones.

The Python API (`preland_app/api.py`) is re-exported here, loaded on first use:

    from preland_app import fly, load_mission, run_campaign, read_results
"""

from .version import __version__

_API = (
    "CampaignRun", "CampaignSpec", "LandModeRow", "LandStrategy", "LandingContext", "LandingReport", "MarkerFrame",
    "MissionSpec", "Outcome", "PrelandError", "ScoringReference", "SpecError", "TrialOutcome", "fly", "land_modes",
    "load_campaign", "load_mission", "read_results", "run_campaign", "schema",
    "compare_runs", "export_results", "list_campaigns", "read_trial", "summarize_campaign", "write_campaign_report",
)
__all__ = ["__version__", *_API]


def __getattr__(name: str):
    # Lazily, so that `preland --version` and worker processes do not import the whole API up front.
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'preland_app' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(__all__)

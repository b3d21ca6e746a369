"""preland's Python API: load missions and campaigns, fly trials on any runtime, run campaigns, read results.

Everything here is re-exported from `preland_app` (`from preland_app import fly`). Units are in the
names: metres (`_m`), vehicle seconds (`_s`), centimetres for landing errors (`_cm`), degrees (`_deg`).
Bad input raises `SpecError` (file, field, problem), as the CLI reports it; a trial that fails is an
outcome (`TrialOutcome.outcome`), not an exception.

    from preland_app import fly, load_mission
    outcome = fly("missions/thesis_square_land.yaml", land="mypackage.landing:MyLanding",
                  land_params={"gain_per_s": 0.4}, seed=3)
    print(outcome.outcome.value, outcome.landing_error_cm, outcome.landing_time_s)
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from .campaign.spec import CampaignSpec, load_campaign
from .config.mission import MissionSpec, load_mission
from .config.schema import json_schema
from .errors import PrelandError, SpecError
from .landing.base import LandingContext, LandingReport, LandStrategy, ScoringReference
from .landing.boundary import MarkerFrame
from .landing.registry import LandModeRow, catalog
from .outcome import Outcome, TrialOutcome

T = TypeVar("T")


def _blocking(work: Callable[[], T]) -> T:
    """Run `work` here, or in a helper thread when this thread already runs an event loop (a notebook):
    each runtime runs its own loop (the embedded simulator's is a virtual-time loop)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return work()
    with concurrent.futures.ThreadPoolExecutor(max_workers=1) as pool:
        return pool.submit(work).result()


def _mission(mission: MissionSpec | str | os.PathLike) -> MissionSpec:
    return mission if isinstance(mission, MissionSpec) else load_mission(mission)


def fly(mission: MissionSpec | str | os.PathLike, *, seed: int = 1, land: str | None = None,
        land_params: Mapping[str, Any] | None = None, sensor: str | None = None,
        faults: Mapping[str, str] | None = None, takeoff_altitude_m: float | None = None,
        connect: str | None = None, sitl: str | os.PathLike | None = None, sitl_speedup: float = 10.0,
        truth: bool = True, record_trajectory: bool = True) -> TrialOutcome:
    """Fly one trial of `mission` (a MissionSpec or a mission file) and return its outcome.

    Runtime: the embedded simulator (default; virtual time, several hundred times faster than real time),
    `connect=URL` (MAVLink: `udpout://127.0.0.1:14550` for `preland sim serve`, a real drone; `truth=False`
    when it reports no ground truth), or `sitl=PATH` (a fresh ArduPilot SITL `arducopter` process at
    `sitl_speedup`). `land`: a land mode by name or import path `package.module:ClassName`, overriding the
    mission's; `land_params`: its keyword options (checked against its class). `faults`: sensor -> fault
    (`{"marker": "below:3"}`). `takeoff_altitude_m`: above home. Same seed, same outcome (embedded).
    The outcome has `landing_error_cm`, `offset_north_cm`, `offset_east_cm`, `landing_time_s` (from the
    hand-over to the land mode to touchdown), `flight_time_s`, `details`, `events` and, with
    `record_trajectory`, `trajectory` (columns `TRAJECTORY_COLUMNS`: s, m)."""
    from .errors import SpecValueError
    from .runtime.embedded import TrialRequest, run_trial

    if connect is not None and sitl is not None:
        raise ValueError("give at most one of connect= and sitl=")
    spec = _mission(mission)
    request = TrialRequest(mission=spec, seed=seed, land_mode=land, sensor=sensor,
                           faults=dict(faults) if faults is not None else None,
                           takeoff_altitude_rel_m=takeoff_altitude_m, record_trajectory=record_trajectory,
                           land_params=dict(land_params) if land_params is not None else None)
    try:
        request.resolved_mission()
    except SpecValueError as error:  # an override that does not fit: name it as the file's field would be
        raise SpecError(path=spec.source_path or spec.name, field=f"land.{error.field}", problem=error.problem) \
            from None
    if sitl is not None:
        from .runtime.sitl import SitlOptions, resolve_sitl_binary, run_sitl_trial

        options = SitlOptions(binary=resolve_sitl_binary(sitl or None), speedup=sitl_speedup)
        return _blocking(lambda: run_sitl_trial(request, options=options))
    if connect is not None:
        from .runtime.mavlink import run_mavlink_trial

        return _blocking(lambda: run_mavlink_trial(request, url=connect, truth=truth))
    return _blocking(lambda: run_trial(request))


@dataclass(frozen=True, kw_only=True)
class CampaignRun:
    """What `run_campaign` did: the campaign's name, its store, the trials run now and in all."""

    name: str
    db: Path
    ran: int
    total: int


def run_campaign(campaign: CampaignSpec | str | os.PathLike, *, db: str | os.PathLike = "results.db",
                 workers: int | None = None, resume: bool = False, sitl: str | os.PathLike | None = None,
                 sitl_speedup: float = 10.0,
                 progress: Callable[[int, int, Any], None] | None = None) -> CampaignRun:
    """Run a campaign (a CampaignSpec or a campaign file) into the SQLite store `db`, each trial in a
    worker process (`workers`, default one per core; a plugin land mode's module must be importable
    there: on sys.path or PYTHONPATH). `resume=True` finishes a campaign already in the store without
    repeating a trial. `sitl=PATH`: every trial on a fresh ArduPilot SITL process. `progress(done, total,
    record)` is called as trials finish. Read the results back with `read_results`."""
    from .campaign.executor import run_campaign as execute
    from .campaign.store import ResultsStore

    spec = campaign if isinstance(campaign, CampaignSpec) else load_campaign(campaign)
    options = None
    if sitl is not None:
        from .runtime.sitl import SitlOptions, resolve_sitl_binary

        options = SitlOptions(binary=resolve_sitl_binary(sitl or None), speedup=sitl_speedup)
    with ResultsStore(db) as store:
        ran, total = execute(spec, store, workers=workers, resume=resume, progress=progress, sitl=options)
    return CampaignRun(name=spec.name, db=Path(db), ran=ran, total=total)


def read_results(db: str | os.PathLike, *, campaign: str | None = None) -> list[dict[str, Any]]:
    """Every trial stored in `db` (of one campaign, or all), one dict per trial: campaign, scenario,
    trial_index, seed, outcome, message, land_mode, sensor, faults, takeoff_altitude_m,
    landing_error_cm, offset_north_cm, offset_east_cm, landing_time_s, flight_time_s,
    touchdown_speed_m_s, details (a dict: the land mode's LandingReport.details and the runtime's keys),
    runtime, source (sim, sitl, field), wall_time_s, ..."""
    from .campaign.store import ResultsStore

    if not Path(db).exists():
        raise PrelandError(f"{db}: no such results database")
    with ResultsStore(db) as store:
        return store.trials(campaign)


def land_modes() -> list[LandModeRow]:
    """The land modes found by short name (built-in and installed plugins), as `preland modes` lists them."""
    return catalog()


def schema(kind: str) -> dict[str, Any]:
    """The JSON Schema of a mission, campaign or pad file."""
    return json_schema(kind)


__all__ = [
    "CampaignRun",
    "CampaignSpec",
    "LandModeRow",
    "LandStrategy",
    "LandingContext",
    "LandingReport",
    "MarkerFrame",
    "MissionSpec",
    "Outcome",
    "PrelandError",
    "ScoringReference",
    "SpecError",
    "TrialOutcome",
    "fly",
    "land_modes",
    "load_campaign",
    "load_mission",
    "read_results",
    "run_campaign",
    "schema",
]

"""preland's Python API: load missions and campaigns, fly trials on any runtime, run campaigns, read results
(list, one trial in full, per-scenario spread, comparisons, exports, reports).

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


def runtime_url(runtime: str | None = None, *, connect: str | None = None,
                sitl: str | os.PathLike | None = None) -> str | None:
    """The runtime URL from `runtime` or one of its shorthands: `connect=URL` (a MAVLink link, as
    `mavlink+...`) or `sitl=PATH` (`sitl:PATH`; `sitl=""`: $PRELAND_SITL_BINARY). None: the default, `sim:`.
    ValueError when more than one is given."""
    given = [name for name, value in (("runtime", runtime), ("connect", connect), ("sitl", sitl)) if value is not None]
    if len(given) > 1:
        raise ValueError(f"give at most one of {', '.join(given)}")
    if connect is not None:
        from .runtime.base import mavlink_url

        return mavlink_url(connect)
    if sitl is not None:
        return f"sitl:{sitl}"
    return runtime


def trial_request(mission: MissionSpec | str | os.PathLike, *, seed: int = 1, land: str | None = None,
                  land_params: Mapping[str, Any] | None = None, sensor: str | None = None,
                  faults: Mapping[str, str] | None = None, takeoff_altitude_m: float | None = None,
                  record_trajectory: bool = True):
    """One trial of `mission` with its overrides, checked: a `TrialRequest`. An override that does not fit
    raises SpecValueError naming the mission's field (`mode`, `sensor`, `faults.marker`, `params.gain`)."""
    from .runtime.base import TrialRequest

    request = TrialRequest(mission=_mission(mission), seed=seed, land_mode=land, sensor=sensor,
                           faults=dict(faults) if faults is not None else None,
                           takeoff_altitude_rel_m=takeoff_altitude_m, record_trajectory=record_trajectory,
                           land_params=dict(land_params) if land_params is not None else None)
    request.resolved_mission()
    return request


def fly(mission: MissionSpec | str | os.PathLike, *, seed: int = 1, land: str | None = None,
        land_params: Mapping[str, Any] | None = None, sensor: str | None = None,
        faults: Mapping[str, str] | None = None, takeoff_altitude_m: float | None = None,
        runtime: Any = None, options: Mapping[str, Any] | None = None, connect: str | None = None,
        sitl: str | os.PathLike | None = None, sitl_speedup: float | None = None, truth: bool | None = None,
        record_trajectory: bool = True, tlog_name: str | None = None) -> TrialOutcome:
    """Fly one trial of `mission` (a MissionSpec or a mission file) and return its outcome.

    `runtime`: a runtime URL (see `preland_app.runtime.base`), or a Runtime already opened: `sim:` (default; the embedded simulator in
    virtual time, much faster than real time: hundreds of times without a camera, tens of times with one),
    `sitl:PATH` (a fresh ArduPilot SITL `arducopter` process), `mavlink+udpout://127.0.0.1:14550` (`preland
    sim serve`, a SITL already running, a drone). `options`: the runtime's options by name (an option it
    does not take raises RuntimeOptionError). Shorthands: `connect=URL`, `sitl=PATH`, `sitl_speedup` (the
    SITL runtime's `speedup`; None: 2 for land modes that read camera frames, 10 for the others), `truth`
    (the MAVLink runtime's: False for a vehicle that reports no ground truth).
    `land`: a land mode by name or import path `package.module:ClassName`, overriding the mission's;
    `land_params`: its keyword options (checked against its class). `faults`: sensor -> fault
    (`{"marker": "below:3"}`). `takeoff_altitude_m`: above home. Same seed, same outcome (embedded).
    The outcome has `landing_error_cm`, `offset_north_cm`, `offset_east_cm`, `landing_time_s` (from the
    hand-over to the land mode to touchdown), `flight_time_s`, `details`, `events` and, with
    `record_trajectory`, `trajectory` (columns `TRAJECTORY_COLUMNS`: s, m)."""
    from .errors import SpecValueError

    spec = _mission(mission)
    try:
        request = trial_request(spec, seed=seed, land=land, land_params=land_params, sensor=sensor, faults=faults,
                                takeoff_altitude_m=takeoff_altitude_m, record_trajectory=record_trajectory)
    except SpecValueError as error:  # an override that does not fit: name it as the file's field would be
        raise SpecError(path=spec.source_path or spec.name, field=f"land.{error.field}", problem=error.problem) \
            from None
    chosen = _runtime(runtime, connect=connect, sitl=sitl,
                      options=_shorthand_options(options, sitl_speedup=sitl_speedup, truth=truth))
    return _blocking(lambda: chosen.fly(request, tlog_name=tlog_name))


def _runtime(runtime, *, connect, sitl, options: dict[str, Any]):
    """`runtime` as a Runtime: an object already opened (no options then), else the URL it or a shorthand
    names, opened with `options`."""
    from .runtime.base import open_runtime

    if runtime is not None and not isinstance(runtime, str):
        if connect is not None or sitl is not None or options:
            raise ValueError("an opened runtime takes no shorthands or options: give them to open_runtime")
        return runtime
    return open_runtime(runtime_url(runtime, connect=connect, sitl=sitl), options)


def _shorthand_options(options: Mapping[str, Any] | None, *, sitl_speedup: float | None,
                       truth: bool | None) -> dict[str, Any]:
    merged = dict(options or {})
    if sitl_speedup is not None:
        merged["speedup"] = sitl_speedup
    if truth is not None:
        merged["truth"] = truth
    return merged


@dataclass(frozen=True, kw_only=True)
class CampaignRun:
    """What `run_campaign` did: the campaign's name, its store, the trials run now and in all."""

    name: str
    db: Path
    ran: int
    total: int


def run_campaign(campaign: CampaignSpec | str | os.PathLike, *, db: str | os.PathLike = "results.db",
                 workers: int | None = None, resume: bool = False, runtime: Any = None,
                 options: Mapping[str, Any] | None = None, sitl: str | os.PathLike | None = None,
                 sitl_speedup: float | None = None, progress: Callable[[int, int, Any], None] | None = None,
                 executor: str = "local", ray_address: str | None = None, trial_cpus: float = 1.0,
                 outcomes_only: bool = False, operator: Any = None, answers: str | os.PathLike | None = None,
                 measure: str | None = None, order: str | None = None,
                 status: Callable[[Any], None] | None = None) -> CampaignRun:
    """Run a campaign (a CampaignSpec or a campaign file) into the SQLite store `db`.

    `runtime`: where every trial flies, a runtime URL or a Runtime as for `fly` (default: the campaign file's
    `runtime:`, else `sim:`), with `options` (the runtime's, by name); `sitl=PATH` and `sitl_speedup` are
    shorthands. A runtime that flies one vehicle (`mavlink+...`) flies the trials one after another: more
    than one worker, or another executor than `local`, is refused.
    `executor="local"` (default): each trial in a worker process on this machine (`workers`, default one
    per core; a plugin land mode's module must be importable there: on sys.path or PYTHONPATH). With more
    than one worker the workers import the script that runs the campaign: its top-level code goes under
    `if __name__ == "__main__":` (without it, or when the script fails to import, no worker can start and
    the campaign stops with an ExecutorError that says so, storing no trial).
    `executor="ray"`: each trial a task of a Ray cluster (`trial_cpus` CPUs each): the one at `ray_address`
    (`auto`, `ray://host:10001`), else $RAY_ADDRESS, else the one this process already joined, else a local
    Ray instance of `workers` CPUs that is stopped again at the end; the store stays on this machine (a
    SITL trial there finds the binary as the nodes see it; `sitl=""`: each node's $PRELAND_SITL_BINARY).
    `resume=True` finishes a campaign already in the store without repeating a trial; a second driver on the
    same campaign and store is refused (`CampaignBusy`). `outcomes_only=True`: no event logs and
    trajectories in the store. `progress(done, total, record)` is called as trials finish. Read the results
    back with `read_results`.
    On a vehicle (`mavlink+...`) the campaign is a field campaign (`preland_app.field.campaign`): between
    trials the vehicle goes back to the start as the campaign's `field:` block says, each landing is measured
    (`measure`: operator, vehicle or truth; by `operator`, an `Operator`, or from an `answers` file), a low
    battery, a pilot takeover or a lost link pauses it, `order="shuffled"` flies the trials in an order drawn
    from the campaign's seed, and `status(FieldStatus)` is told what it does and waits for. These options are
    refused for the other runtimes."""
    from .campaign.driver import run_campaign as execute
    from .campaign.executors import ExecutorOptions, create_executor, executor_factory
    from .campaign.store import ResultsStore
    from .runtime.base import RuntimeOptionError

    spec = campaign if isinstance(campaign, CampaignSpec) else load_campaign(campaign)
    if runtime is None and sitl is None:
        runtime = spec.runtime
    chosen = _runtime(runtime, connect=None, sitl=sitl,
                      options=_shorthand_options(options, sitl_speedup=sitl_speedup, truth=None))
    if chosen.max_workers is not None:
        if executor != "local":
            raise RuntimeOptionError(option="executor", runtime=chosen.url,
                                     problem=f"{chosen.url} is one vehicle, flown from this machine: "
                                             "use the local executor")
        if workers is not None and workers > chosen.max_workers:
            raise RuntimeOptionError(option="workers", runtime=chosen.url,
                                     problem=f"{chosen.url} is one vehicle: its trials fly one at a time "
                                             f"(at most {chosen.max_workers} worker), got {workers}")
        workers = chosen.max_workers
    field_options = {"operator": operator, "answers": answers, "measure": measure, "order": order,
                     "status": status}
    if getattr(chosen, "flies_a_vehicle", False):
        from .field.campaign import run_field_campaign

        if outcomes_only:
            raise RuntimeOptionError(option="outcomes_only", runtime=chosen.url,
                                     problem="a field campaign keeps every trial in full")
        with ResultsStore(db) as store:
            ran, total = run_field_campaign(spec, store, runtime=chosen, resume=resume, progress=progress,
                                            **{k: v for k, v in field_options.items() if v is not None})
        return CampaignRun(name=spec.name, db=Path(db), ran=ran, total=total)
    for name, value in field_options.items():
        if value is not None:
            raise RuntimeOptionError(option=name, runtime=chosen.url,
                                     problem="only for a field campaign, on a vehicle (mavlink+...)")
    if not getattr(executor_factory(executor), "runs_elsewhere", False):
        chosen = chosen.on_this_machine()  # a missing SITL binary is refused before any trial starts
    trial_executor = create_executor(executor, ExecutorOptions(workers=workers, address=ray_address,
                                                               trial_cpus=trial_cpus))
    with ResultsStore(db) as store:
        ran, total = execute(spec, store, resume=resume, progress=progress, runtime=chosen,
                             executor=trial_executor, outcomes_only=outcomes_only)
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


def _open_existing(db: str | os.PathLike):
    from .campaign.store import ResultsStore

    if not Path(db).exists():
        raise PrelandError(f"{db}: no such results database")
    return ResultsStore(db)


def list_campaigns(db: str | os.PathLike) -> list[Any]:
    """The campaigns in `db`, as `preland campaign list` shows them: `CampaignEntry` (name, source_path,
    created_at, scenarios: `ScenarioCount` with trials per source `counts`, `landed`, `land_mode`,
    `published_source`)."""
    from .campaign.catalog import overview

    with _open_existing(db) as store:
        return overview(store)


def read_trial(db: str | os.PathLike, *, campaign: str, scenario: str, index: int,
               source: str | None = None) -> dict[str, Any]:
    """One trial in full (as `read_results` gives it) plus its `events` (vehicle seconds) and `trajectory`
    ((columns, rows) in s and m, or None). `source` None: the simulated trial of that index, else SITL, else
    field."""
    from .campaign.catalog import find_trial

    with _open_existing(db) as store:
        trial = find_trial(store, campaign, scenario, index, source)
        return {**trial, "events": store.events(trial["id"]), "trajectory": store.trajectory(trial["id"])}


def summarize_campaign(db: str | os.PathLike, campaign: str) -> list[Any]:
    """Per scenario and source, as the report's table: `ScenarioSummary` with `error_spread()` and
    `landing_time_spread()` (`Spread`: n, mean, sd, median, minimum, maximum, ci_low, ci_high; cm and s),
    the published figures (`published_avg_error_cm()`, `published_error_spread()`, ...) and the trials."""
    from .campaign.report import summarize

    with _open_existing(db) as store:
        return summarize(store, campaign)


def compare_runs(before: tuple[str | os.PathLike, str], after: tuple[str | os.PathLike, str], *,
                 measure: str = "landing_error_cm") -> list[Any]:
    """`preland campaign compare`: per scenario, `ScenarioComparison` with `difference` (`Difference`: the
    two `Spread`s, `difference` of the means after - before, its bootstrap 95 % `ci_low`/`ci_high`,
    `significant`, `intervals_overlap`). `before`/`after`: (db, campaign)."""
    from .campaign.compare import compare

    with _open_existing(before[0]) as store_b, _open_existing(after[0]) as store_a:
        return compare((store_b, before[1]), (store_a, after[1]), measure=measure)


def export_results(db: str | os.PathLike, *, table: str = "trials", export_format: str = "csv",
                   campaign: str | None = None, out: str | os.PathLike | None = None) -> str | None:
    """`preland campaign export`: `table` trials, events or trajectories as csv, jsonl or parquet (needs
    pyarrow). Returns the text when `out` is None (csv, jsonl), else writes `out`."""
    from .campaign.export import export

    with _open_existing(db) as store:
        return export(store, table=table, export_format=export_format, campaign=campaign,
                      out=Path(out) if out is not None else None)


def write_campaign_report(db: str | os.PathLike, campaign: str, out_dir: str | os.PathLike, *,
                          figure_format: str = "png", dpi: int | None = None) -> list[Path]:
    """`preland campaign report`: the table (Markdown, CSV) and figures (png at `dpi`, default 300; pdf; svg)
    into `out_dir`; returns the files written."""
    from .campaign.report import write_report

    with _open_existing(db) as store:
        return write_report(store, campaign, Path(out_dir), figure_format=figure_format, dpi=dpi)


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
    "compare_runs",
    "export_results",
    "land_modes",
    "list_campaigns",
    "load_campaign",
    "load_mission",
    "read_results",
    "read_trial",
    "run_campaign",
    "schema",
    "summarize_campaign",
    "write_campaign_report",
]

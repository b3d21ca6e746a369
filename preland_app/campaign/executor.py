"""Runs a campaign's trials in worker processes and commits each one to the store as it finishes.

Seeds come from the base seed and the trial's identity (scenario label and trial
index), never from the order trials run in, so results do not depend on the
number of workers. A trial that fails is stored as that trial's outcome; the
campaign goes on. Ctrl-C or a kill loses only the trials in flight, and
`resume=True` runs only the trials the store does not have yet.
"""

from __future__ import annotations

import ctypes
import hashlib
import math
import multiprocessing
import os
import signal
import time
import traceback
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from ..config.mission import MissionSpec
from ..errors import PrelandError
from ..outcome import TRAJECTORY_COLUMNS, Outcome
from ..runtime.embedded import TrialRequest, run_trial
from ..runtime.sitl import SitlOptions, run_sitl_trial
from .spec import CampaignSpec, ResolvedScenario, resolve_scenarios, spec_hash
from .store import ResultsStore, StoreError, TrialRecord

TRAJECTORY_PERIOD_S = 0.5  # stored trajectories are downsampled to this period


class CampaignInterrupted(PrelandError):
    """The campaign was interrupted (Ctrl-C); what finished is stored."""

    def __init__(self, *, done: int, total: int) -> None:
        self.done = done
        self.total = total
        super().__init__(f"interrupted: {done} of {total} trials stored; run again with --resume to finish")


@dataclass(frozen=True, kw_only=True)
class TrialJob:
    """One trial of a campaign, with everything a worker process needs."""

    campaign: str
    scenario: str
    scenario_index: int
    trial_index: int
    seed: int
    spec_hash: str
    mission: MissionSpec
    takeoff_altitude_rel_m: float
    sitl: SitlOptions | None = None


def derive_seed(base_seed: int, scenario: str, trial_index: int) -> int:
    """A trial's seed from the campaign's base seed and the trial's identity (31 bits)."""
    digest = hashlib.sha256(f"{base_seed}:{scenario}:{trial_index}".encode("utf-8")).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def plan_trials(campaign: CampaignSpec, scenarios: list[ResolvedScenario], *,
                sitl: SitlOptions | None = None) -> list[TrialJob]:
    return [
        TrialJob(campaign=campaign.name, scenario=s.spec.label, scenario_index=s.index, trial_index=i,
                 seed=derive_seed(campaign.base_seed, s.spec.label, i), spec_hash=s.spec_hash, mission=s.mission,
                 takeoff_altitude_rel_m=s.takeoff_altitude_rel_m, sitl=sitl)
        for s in scenarios for i in range(s.trials)
    ]


def _downsample(trajectory) -> tuple[tuple[float, ...], ...]:
    if trajectory is None or len(trajectory) == 0:
        return ()
    rows, next_time = [], -math.inf
    for row in trajectory:
        if row[0] >= next_time:
            rows.append(tuple(round(float(v), 3) if math.isfinite(v) else None for v in row))
            next_time = row[0] + TRAJECTORY_PERIOD_S
    last = tuple(round(float(v), 3) if math.isfinite(v) else None for v in trajectory[-1])
    if rows[-1] != last:
        rows.append(last)
    return tuple(rows)


def run_job(job: TrialJob) -> TrialRecord:
    """Fly one trial (in a worker process). Never raises: a failure becomes an `error` outcome."""
    started = time.perf_counter()
    common = dict(campaign=job.campaign, scenario=job.scenario, scenario_index=job.scenario_index,
                  trial_index=job.trial_index, seed=job.seed, spec_hash=job.spec_hash)
    request = TrialRequest(mission=job.mission, seed=job.seed, takeoff_altitude_rel_m=job.takeoff_altitude_rel_m)
    runtime = "sitl" if job.sitl is not None else "embedded"
    try:
        if job.sitl is not None:
            tlog_name = f"{job.campaign}_s{job.scenario_index}_t{job.trial_index}.tlog"
            outcome = run_sitl_trial(request, options=job.sitl, tlog_name=tlog_name)
        else:
            outcome = run_trial(request)
    except Exception as error:  # a bug in a trial is that trial's outcome; the campaign goes on
        last = traceback.extract_tb(error.__traceback__)[-1] if error.__traceback__ else None
        where = f" at {Path(last.filename).name}:{last.lineno}" if last else ""
        result = {"outcome": Outcome.ERROR.value, "message": f"{type(error).__name__}: {error}{where}",
                  "mission": job.mission.name, "land_mode": job.mission.land.mode, "details": {}}
        return TrialRecord(**common, result=result, runtime=runtime, source="sitl" if job.sitl else "sim",
                           wall_time_s=time.perf_counter() - started)
    data = outcome.to_dict(include_events=True)
    land = job.mission.land
    result = {key: data.get(key) for key in data}
    result["sensor"] = land.precision_sensor
    result["faults"] = ", ".join(f"{s} {f}" for s, f in sorted(land.faults.items())) or "none"
    result["takeoff_altitude_m"] = data["takeoff_altitude_rel_m"]
    return TrialRecord(**common, result=result, events=tuple(data["events"]),
                       trajectory_columns=TRAJECTORY_COLUMNS, trajectory_rows=_downsample(outcome.trajectory),
                       runtime=runtime, source="sitl" if job.sitl else "sim",
                       wall_time_s=time.perf_counter() - started)


def _worker_init() -> None:
    """Workers die with the campaign process (a killed campaign leaves no orphans) and ignore Ctrl-C
    (the campaign process handles it)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except OSError:
        pass  # not Linux: workers still exit when their pipe closes


Progress = Callable[[int, int, TrialRecord | None], None]


def run_campaign(campaign: CampaignSpec, store: ResultsStore, *, workers: int | None = None, resume: bool = False,
                 progress: Progress | None = None, sitl: SitlOptions | None = None) -> tuple[int, int]:
    """Run the campaign's pending trials (on the embedded simulator, or on SITL binaries).
    Returns (trials run now, trials in the campaign)."""
    scenarios = resolve_scenarios(campaign)
    jobs = plan_trials(campaign, scenarios, sitl=sitl)
    source = "sitl" if sitl is not None else "sim"
    done = store.done_keys(campaign.name, source)
    if done and not resume:
        raise StoreError(f"campaign {campaign.name!r} already has {len(done)} trial(s) in {store.path}; "
                         "add --resume to finish it, or use another --db")
    stored_hashes = store.trial_hashes(campaign.name, source)
    for scenario in scenarios:
        hashes = stored_hashes.get(scenario.spec.label, set())
        if hashes and hashes != {scenario.spec_hash}:
            raise StoreError(f"campaign {campaign.name!r}, scenario {scenario.spec.label!r}: its spec changed since "
                             f"the stored trials were run; use another --db or campaign name")
    spec_text = Path(campaign.source_path).read_text(encoding="utf-8") if campaign.source_path else ""
    store.register_campaign(name=campaign.name, spec_hash=spec_hash(campaign), spec_text=spec_text,
                            source_path=str(Path(campaign.source_path).resolve()) if campaign.source_path else "")
    pending = [job for job in jobs if (job.scenario, job.trial_index) not in done]
    total = len(jobs)
    finished = total - len(pending)
    if progress:
        progress(finished, total, None)
    workers = max(1, workers or os.cpu_count() or 1)
    if workers == 1 or len(pending) <= 1:
        try:
            for job in pending:
                record = run_job(job)
                store.add_trial(record)
                finished += 1
                if progress:
                    progress(finished, total, record)
        except KeyboardInterrupt:
            raise CampaignInterrupted(done=finished, total=total) from None
        return len(pending), total
    ran = _run_in_pool(pending, store, workers=workers, progress=progress, finished=finished, total=total)
    return ran, total


def _run_in_pool(pending: list[TrialJob], store: ResultsStore, *, workers: int, progress: Progress | None,
                 finished: int, total: int) -> int:
    queue = list(reversed(pending))
    crashes: dict[tuple[str, int], int] = {}
    ran = 0
    context = multiprocessing.get_context("spawn")
    while queue:
        pool = ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_init)
        in_flight: dict[Future, TrialJob] = {}
        try:
            while queue or in_flight:
                while queue and len(in_flight) < workers * 2:
                    job = queue.pop()
                    in_flight[pool.submit(run_job, job)] = job
                completed, _ = wait(in_flight, return_when=FIRST_COMPLETED)
                for future in completed:
                    job = in_flight.pop(future)
                    try:
                        record = future.result()
                    except BrokenProcessPool:
                        raise
                    except Exception as error:  # pickling or the like: still this trial's outcome
                        record = _error_record(job, f"{type(error).__name__}: {error}")
                    store.add_trial(record)
                    ran += 1
                    finished += 1
                    if progress:
                        progress(finished, total, record)
        except BrokenProcessPool:
            # A worker died (killed, out of memory). Every trial in flight is retried once in a new pool;
            # one that was in flight at two such deaths is recorded as an error, so the campaign goes on.
            for future, job in in_flight.items():
                if future.done() and not future.cancelled() and future.exception() is None:
                    record = future.result()
                else:
                    key = (job.scenario, job.trial_index)
                    crashes[key] = crashes.get(key, 0) + 1
                    if crashes[key] < 2:
                        queue.append(job)
                        continue
                    record = _error_record(job, "the worker process running this trial died")
                store.add_trial(record)
                ran += 1
                finished += 1
                if progress:
                    progress(finished, total, record)
            pool.shutdown(wait=False, cancel_futures=True)
            continue
        except KeyboardInterrupt:
            _kill_pool(pool)
            raise CampaignInterrupted(done=finished, total=total) from None
        pool.shutdown(wait=True)
    return ran


def _kill_pool(pool: ProcessPoolExecutor) -> None:
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.kill()
    for process in processes:
        process.join(timeout=5)


def _error_record(job: TrialJob, message: str) -> TrialRecord:
    return TrialRecord(campaign=job.campaign, scenario=job.scenario, scenario_index=job.scenario_index,
                       trial_index=job.trial_index, seed=job.seed, spec_hash=job.spec_hash,
                       result={"outcome": Outcome.ERROR.value, "message": message, "mission": job.mission.name,
                               "land_mode": job.mission.land.mode, "details": {}})

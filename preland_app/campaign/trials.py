"""A campaign's trials: what each one flies (`TrialJob`), its seed, and how one runs into a `TrialRecord`.

`run_job` is what every executor runs, in a worker process on this machine or
in a task on a cluster node: it never raises, so a failure is that trial's
outcome. Seeds come from the base seed and the trial's identity (scenario
label and trial index), never from the order trials run in, so results do not
depend on the executor or the number of workers.
"""

from __future__ import annotations

import hashlib
import math
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from ..config.mission import MissionSpec
from ..outcome import TRAJECTORY_COLUMNS, Outcome, TrialOutcome
from ..runtime.base import Runtime, TrialRequest
from ..runtime.embedded import EmbeddedRuntime
from .spec import CampaignSpec, ResolvedScenario
from .store import TrialRecord

TRAJECTORY_PERIOD_S = 0.5  # stored trajectories are downsampled to this period


@dataclass(frozen=True, kw_only=True)
class TrialJob:
    """One trial of a campaign, with everything a worker needs. `outcomes_only`: the record carries no
    event log and no trajectory (the trial then does not record one either)."""

    campaign: str
    scenario: str
    scenario_index: int
    trial_index: int
    seed: int
    spec_hash: str
    mission: MissionSpec
    takeoff_altitude_rel_m: float
    runtime: Runtime = EmbeddedRuntime()
    outcomes_only: bool = False

    @property
    def key(self) -> tuple[str, int]:
        return self.scenario, self.trial_index

    @property
    def source(self) -> str:
        return self.runtime.source


def derive_seed(base_seed: int, scenario: str, trial_index: int) -> int:
    """A trial's seed from the campaign's base seed and the trial's identity (31 bits)."""
    digest = hashlib.sha256(f"{base_seed}:{scenario}:{trial_index}".encode("utf-8")).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


def plan_trials(campaign: CampaignSpec, scenarios: list[ResolvedScenario], *, runtime: Runtime = EmbeddedRuntime(),
                outcomes_only: bool = False) -> Iterator[TrialJob]:
    """Every trial of the campaign, scenario by scenario (made one at a time: a campaign of 100,000 trials
    is never held as 100,000 jobs)."""
    for s in scenarios:
        for i in range(s.trials):
            yield TrialJob(campaign=campaign.name, scenario=s.spec.label, scenario_index=s.index, trial_index=i,
                           seed=derive_seed(campaign.base_seed, s.spec.label, i), spec_hash=s.spec_hash,
                           mission=s.mission, takeoff_altitude_rel_m=s.takeoff_altitude_rel_m, runtime=runtime,
                           outcomes_only=outcomes_only)


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
    """Fly one trial on the job's runtime (in a worker process or a cluster task). Never raises: a failure
    becomes an `error` outcome. A SITL trial without a binary of its own uses $PRELAND_SITL_BINARY of the
    machine it runs on."""
    started = time.perf_counter()
    outcome = fly_job(job)
    if isinstance(outcome, str):
        return error_record(job, outcome, wall_time_s=time.perf_counter() - started)
    return outcome_record(job, outcome, wall_time_s=time.perf_counter() - started)


def fly_job(job: TrialJob) -> TrialOutcome | str:
    """Fly one trial on the job's runtime: its outcome, or the message of the error that stopped it (a bug
    in a trial is that trial's outcome; the campaign goes on)."""
    request = TrialRequest(mission=job.mission, seed=job.seed, takeoff_altitude_rel_m=job.takeoff_altitude_rel_m,
                           record_trajectory=not job.outcomes_only)
    try:
        # A runtime sent without a binary of its own finds it on the machine the trial runs on.
        return job.runtime.on_this_machine().fly(
            request, tlog_name=f"{job.campaign}_s{job.scenario_index}_t{job.trial_index}.tlog")
    except Exception as error:
        last = traceback.extract_tb(error.__traceback__)[-1] if error.__traceback__ else None
        where = f" at {Path(last.filename).name}:{last.lineno}" if last else ""
        return f"{type(error).__name__}: {error}{where}"


def outcome_record(job: TrialJob, outcome: TrialOutcome, *, wall_time_s: float | None,
                   source: str | None = None) -> TrialRecord:
    """The record of a flown trial (`source`: what its figures are, default the runtime's)."""
    common = dict(campaign=job.campaign, scenario=job.scenario, scenario_index=job.scenario_index,
                  trial_index=job.trial_index, seed=job.seed, spec_hash=job.spec_hash, runtime=job.runtime.name,
                  source=source or job.source, wall_time_s=wall_time_s)
    data = outcome.to_dict(include_events=not job.outcomes_only)
    land = job.mission.land
    result = {key: data.get(key) for key in data if key != "events"}
    result["sensor"] = land.precision_sensor
    result["faults"] = ", ".join(f"{s} {f}" for s, f in sorted(land.faults.items())) or "none"
    result["takeoff_altitude_m"] = data["takeoff_altitude_rel_m"]
    if job.outcomes_only:
        return TrialRecord(**common, result=result)
    return TrialRecord(**common, result=result, events=tuple(data["events"]),
                       trajectory_columns=TRAJECTORY_COLUMNS, trajectory_rows=_downsample(outcome.trajectory))


def error_record(job: TrialJob, message: str, *, wall_time_s: float | None = None,
                 source: str | None = None) -> TrialRecord:
    """The record of a trial that could not give an outcome of its own (`source` as for `outcome_record`)."""
    return TrialRecord(campaign=job.campaign, scenario=job.scenario, scenario_index=job.scenario_index,
                       trial_index=job.trial_index, seed=job.seed, spec_hash=job.spec_hash,
                       result={"outcome": Outcome.ERROR.value, "message": message, "mission": job.mission.name,
                               "land_mode": job.mission.land.mode, "details": {}},
                       runtime=job.runtime.name, source=source or job.source,
                       wall_time_s=wall_time_s)

"""Calibration: fit declared parameters of the simulator to recorded field trials, and score held-out ones.

For a candidate set of values, every fitted scenario of the campaign is flown
`trials_per_scenario` times on the campaign's own executors (`executors/`,
`trials.run_job`), with the candidate as the simulation profile (the
mission's and scenarios' own overrides still on top, as in any campaign). The
trial seeds are the campaign's (`trials.derive_seed`) and the same at every
evaluation (common random numbers), so two candidates differ only by their
values and the objective is smooth enough for a small budget. The objective is
the mean over fitted scenarios of

    W1(sim errors, field errors) / field mean error
    + time_weight * W1(sim times, field times) / field mean time
    + the fraction of simulated trials that did not land with an error

(W1: Wasserstein-1, `fidelity.py`; relative, so that a GPS-only scenario
missing by a metre does not drown a precision one missing by centimetres).

The optimizer is scipy's differential evolution: seeded, its initial population
a Latin hypercube with the starting values as its first member, the whole
population evaluated in one batch (all its trials in flight at once), no
polishing, at most `budget` evaluations. The best values are then flown again
on `fresh_seed_sets` other sets of seeds (the campaign's with its base seed
plus 1, 2, ...): the objective there against the objective on the fit's own
seeds tells how much of the fit is the seeds' luck. Last they are scored on
every scenario with field trials, fitted and held out, with `score_trials`
trials each, and written as a profile with its provenance.
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..version import __version__
from ..config.loader import deep_merge
from ..config.mission import MissionSpec, load_mission
from ..errors import PrelandError
from ..sim.calibratable import CalibratableParameter, find_calibratable, section_and_path
from ..sim.profile import OptimizerRecord, ProfileSpec, Provenance, ScenarioScore, load_profile, \
    overrides_of, resolve_profile_path
from .executors import ExecutorOptions, TrialExecutor, create_executor
from .field_data import FieldTrials
from .fidelity import score_scenario, wasserstein
from .field_records import now_utc
from .spec import CampaignSpec, ResolvedScenario, resolve_scenarios
from .store import TrialRecord
from .trials import TrialJob, plan_trials

MIN_POPULATION = 5  # differential evolution needs at least 5 members
DEFAULT_BUDGET = 20
DEFAULT_TRIALS_PER_SCENARIO = 6
DEFAULT_SCORE_TRIALS = 10
DEFAULT_TIME_WEIGHT = 0.25
DEFAULT_FRESH_SEED_SETS = 2
POLL_S = 1.0

Progress = Callable[[int, int], None]


class CalibrationError(PrelandError):
    """A calibration cannot run as asked (the message names the option or file)."""


@dataclass(frozen=True, kw_only=True)
class CalibrationRequest:
    """What to fit: the campaign (which scenario is which), the field trials per scenario label, the
    parameters to fit, the labels held out, and the optimizer's settings."""

    campaign: CampaignSpec
    field: dict[str, FieldTrials]
    data: str
    params: tuple[str, ...]
    holdout: tuple[str, ...] = ()
    budget: int = DEFAULT_BUDGET
    seed: int = 0
    trials_per_scenario: int = DEFAULT_TRIALS_PER_SCENARIO
    score_trials: int = DEFAULT_SCORE_TRIALS
    time_weight: float = DEFAULT_TIME_WEIGHT
    fresh_seed_sets: int = DEFAULT_FRESH_SEED_SETS
    start: dict[str, float] | None = None
    name: str = "fitted"


@dataclass(frozen=True, kw_only=True)
class CalibrationResult:
    profile: ProfileSpec
    best: dict[str, float]
    objective: float
    evaluations: int
    scores: tuple[ScenarioScore, ...]
    wall_time_s: float
    fresh_seed_objectives: tuple[float, ...] = ()


def check_request(request: CalibrationRequest) -> tuple[list[CalibratableParameter], list[str], list[str]]:
    """The declared parameters, the fitted and held-out labels; CalibrationError naming the option."""
    try:
        parameters = [find_calibratable(name) for name in request.params]
    except PrelandError as error:
        raise CalibrationError(f"--params: {error}") from None
    if not parameters:
        raise CalibrationError("--params: name at least one parameter to fit")
    if len(set(request.params)) != len(request.params):
        raise CalibrationError("--params: a parameter is named twice")
    labels = [s.label for s in request.campaign.scenarios]
    for label in request.holdout:
        if label not in labels:
            raise CalibrationError(f"--holdout: {label!r} is not a scenario of {request.campaign.source_path} "
                                   f"(scenarios: {', '.join(labels)})")
    fitted = [label for label in labels if label not in request.holdout and label in request.field]
    held_out = [label for label in labels if label in request.holdout and label in request.field]
    if not fitted:
        raise CalibrationError(f"no scenario left to fit: none outside --holdout has field trials in {request.data}")
    if request.budget < MIN_POPULATION:
        raise CalibrationError(f"--budget: must be >= {MIN_POPULATION} evaluations, got {request.budget}")
    if request.trials_per_scenario < 1 or request.score_trials < 1:
        raise CalibrationError("--trials-per-scenario: must be >= 1")
    if request.fresh_seed_sets < 0:
        raise CalibrationError(f"--fresh-seed-sets: must be >= 0, got {request.fresh_seed_sets}")
    if not request.time_weight >= 0:
        raise CalibrationError(f"--time-weight: must be >= 0, got {request.time_weight:g}")
    for parameter in parameters:
        value = (request.start or {}).get(parameter.name, parameter.default())
        if not parameter.contains(value):
            raise CalibrationError(f"{parameter.name}: the starting value {value:g} is outside its range "
                                   f"{parameter.low:g}..{parameter.high:g}")
    return parameters, fitted, held_out


class Flyer:
    """Flies a campaign's scenarios under candidate values: the campaign's profile (or the mission's), the
    candidate on top, the mission's and the scenarios' own overrides on top of that."""

    def __init__(self, campaign: CampaignSpec) -> None:
        self.campaign = campaign
        mission_path = Path(campaign.mission)
        self.mission_path = mission_path if mission_path.is_absolute() else campaign.base_dir / mission_path
        self.base = self._base_profile()

    def _base_profile(self) -> ProfileSpec:
        if self.campaign.sim_profile is not None:
            return load_profile(resolve_profile_path(self.campaign.sim_profile, relative_to=self.campaign.base_dir))
        named = load_mission(self.mission_path).sim_profile
        return load_profile(named) if named else ProfileSpec(name="defaults")

    def profile(self, values: dict[str, float]) -> ProfileSpec:
        sections = overrides_of(values)
        return replace(self.base, environment=deep_merge(self.base.environment, sections["environment"]),
                       sensors=deep_merge(self.base.sensors, sections["sensors"]))

    def scenarios(self, values: dict[str, float], labels: Sequence[str], trials: int) -> list[ResolvedScenario]:
        mission = load_mission(self.mission_path, profile=self.profile(values))
        return [replace(s, trials=trials) for s in resolve_scenarios(self.campaign, mission=mission)
                if s.spec.label in labels]


def value_in(mission: MissionSpec, name: str) -> float:
    section, parts = section_and_path(name)
    value = getattr(mission, section)
    for part in parts:
        value = getattr(value, part)
    return float(value)


def check_effective(flyer: Flyer, parameters: list[CalibratableParameter], fitted: list[str]) -> None:
    """Refuse a parameter that every fitted scenario (or the mission) overrides itself: fitting it would
    change nothing."""
    probe = {p.name: (p.low + p.high) / 2 for p in parameters}
    scenarios = flyer.scenarios(probe, fitted, 1)
    for parameter in parameters:
        if all(value_in(s.mission, parameter.name) != probe[parameter.name] for s in scenarios):
            raise CalibrationError(f"--params: {parameter.name} is set by the mission or by every fitted "
                                   "scenario's own environment/sensors, so a profile cannot change it")


def run_jobs(executor: TrialExecutor, jobs: list[TrialJob], on_record: Callable[[TrialRecord], None]) -> None:
    """Run `jobs` on a started executor, a window of them in flight at a time, handing each record over."""
    from .driver import run_windowed

    run_windowed(executor, iter(jobs), on_record=on_record, poll_s=POLL_S)


def _outcomes(records: list[TrialRecord]) -> tuple[list[float], list[float], int]:
    errors = [r.result["landing_error_cm"] for r in records
              if r.result.get("outcome") == "landed" and r.result.get("landing_error_cm") is not None]
    times = [r.result["landing_time_s"] for r in records
             if r.result.get("outcome") == "landed" and r.result.get("landing_time_s") is not None]
    return errors, times, len(records) - len(errors)


def scenario_term(records: list[TrialRecord], field: FieldTrials, time_weight: float) -> float:
    """One scenario's part of the objective (dimensionless, see the module)."""
    errors, times, failed = _outcomes(records)
    term = failed / max(1, len(records))
    if not errors:
        return term + 1.0 + time_weight
    term += wasserstein(errors, field.errors_cm) / max(field.mean_cm, 1.0)
    if time_weight and times and field.times_s:
        term += time_weight * wasserstein(times, field.times_s) / max(statistics.fmean(field.times_s), 1.0)
    return term


class Evaluator:
    """Evaluates batches of candidates: all their trials in flight together on one executor."""

    def __init__(self, *, request: CalibrationRequest, flyer: Flyer, parameters: list[CalibratableParameter],
                 fitted: list[str], executor: TrialExecutor, progress: Progress | None, total_trials: int) -> None:
        self.request, self.flyer, self.parameters, self.fitted = request, flyer, parameters, fitted
        self.executor, self.progress, self.total_trials = executor, progress, total_trials
        self.history: list[tuple[dict[str, float], float]] = []
        self.trials_done = 0

    def values(self, x: Sequence[float]) -> dict[str, float]:
        return {p.name: float(v) for p, v in zip(self.parameters, x)}

    def fly(self, candidates: list[dict[str, float]], labels: Sequence[str], trials: int, *,
            base_seed: int | None = None) -> list[dict[str, list[TrialRecord]]]:
        """Each candidate's records per scenario label; the campaign's seeds, or those of `base_seed`."""
        jobs: list[TrialJob] = []
        for number, values in enumerate(candidates):
            scenarios = self.flyer.scenarios(values, labels, trials)
            # The candidate's number rides in the campaign name; seeds stay the campaign's (common random numbers).
            campaign = replace(self.request.campaign, name=f"{number}")
            if base_seed is not None:
                campaign = replace(campaign, base_seed=base_seed)
            jobs.extend(plan_trials(campaign, scenarios, outcomes_only=True))
        results: list[dict[str, list[TrialRecord]]] = [{label: [] for label in labels} for _ in candidates]

        def on_record(record: TrialRecord) -> None:
            results[int(record.campaign)][record.scenario].append(record)
            self.trials_done += 1
            if self.progress:
                self.progress(self.trials_done, self.total_trials)

        run_jobs(self.executor, jobs, on_record)
        return results

    def __call__(self, population: np.ndarray) -> np.ndarray:
        """scipy's vectorized objective: `population` is (parameters, candidates)."""
        candidates = [self.values(population[:, i]) for i in range(population.shape[1])]
        flown = self.fly(candidates, self.fitted, self.request.trials_per_scenario)
        scores = []
        for values, by_label in zip(candidates, flown):
            score = self.objective(by_label)
            self.history.append((values, score))
            scores.append(score)
        return np.array(scores)

    def objective(self, by_label: dict[str, list[TrialRecord]]) -> float:
        """The mean over fitted scenarios of their terms (see the module)."""
        return statistics.fmean(scenario_term(by_label[label], self.request.field[label], self.request.time_weight)
                                for label in self.fitted)

    def fresh_seed_objectives(self, values: dict[str, float]) -> tuple[list[int], list[float]]:
        """`values` flown on the fitted scenarios with the campaign's base seed plus 1, 2, ... (as many as
        the request's fresh seed sets): those base seeds and the objective on each."""
        base_seeds = [self.request.campaign.base_seed + k for k in range(1, self.request.fresh_seed_sets + 1)]
        objectives = []
        for base_seed in base_seeds:
            (flown,) = self.fly([values], self.fitted, self.request.trials_per_scenario, base_seed=base_seed)
            objectives.append(self.objective(flown))
        return base_seeds, objectives


def population_plan(budget: int, dimensions: int) -> tuple[int, int]:
    """(population size, generations after the first): at most `budget` evaluations, at least 3 generations
    when the budget allows."""
    size = max(MIN_POPULATION, min(10 * dimensions, budget // 3))
    return size, max(0, budget // size - 1)


def calibrate(request: CalibrationRequest, *, workers: int | None = None, executor: str = "local",
              progress: Progress | None = None) -> CalibrationResult:
    """Fit `request.params` and score every scenario with field trials (see the module)."""
    from scipy.optimize import differential_evolution
    from scipy.stats import qmc

    started = time.perf_counter()
    parameters, fitted, held_out = check_request(request)
    flyer = Flyer(request.campaign)
    check_effective(flyer, parameters, fitted)
    start = [(request.start or {}).get(p.name, p.default()) for p in parameters]
    size, generations = population_plan(request.budget, len(parameters))
    rng = np.random.default_rng(request.seed)
    unit = qmc.LatinHypercube(d=len(parameters), rng=rng).random(size)
    low = np.array([p.low for p in parameters])
    high = np.array([p.high for p in parameters])
    init = low + unit * (high - low)
    init[0] = start
    total_trials = ((size * (generations + 1) + request.fresh_seed_sets) * len(fitted) * request.trials_per_scenario
                    + (len(fitted) + len(held_out)) * request.score_trials)
    with create_executor(executor, ExecutorOptions(workers=workers)) as trial_executor:
        evaluator = Evaluator(request=request, flyer=flyer, parameters=parameters, fitted=fitted,
                              executor=trial_executor, progress=progress, total_trials=total_trials)
        result = differential_evolution(evaluator, bounds=list(zip(low, high)), init=init, maxiter=generations,
                                        polish=False, rng=rng, vectorized=True, updating="deferred", tol=0.0)
        best = {name: rounded(value) for name, value in evaluator.values(result.x).items()}
        objective = float(result.fun)
        fresh_base_seeds, fresh_objectives = evaluator.fresh_seed_objectives(best)
        labels = fitted + held_out
        (flown,) = evaluator.fly([best], labels, request.score_trials)
    scores = []
    for label in labels:
        errors, times, _ = _outcomes(flown[label])
        score = score_scenario(label=label, role="fitted" if label in fitted else "held_out", sim_errors_cm=errors,
                               sim_times_s=times, field_errors_cm=request.field[label].errors_cm,
                               field_times_s=request.field[label].times_s)
        if score is not None:
            scores.append(score)
    wall_time_s = time.perf_counter() - started
    profile = flyer.profile(best)
    provenance = Provenance(
        data=request.data, campaign=request.campaign.source_path, fitted=best, held_out=tuple(held_out),
        scores=tuple(scores), created=now_utc(), preland_version=__version__,
        start={p.name: float(v) for p, v in zip(parameters, start)},
        optimizer=OptimizerRecord(method="scipy.optimize.differential_evolution (best1bin, Latin hypercube "
                                         "start, no polish)", budget=request.budget,
                                  evaluations=len(evaluator.history), seed=request.seed,
                                  trials_per_scenario=request.trials_per_scenario, time_weight=request.time_weight,
                                  objective=objective, wall_time_s=round(wall_time_s, 1),
                                  fresh_base_seeds=tuple(fresh_base_seeds),
                                  fresh_seed_objectives=tuple(fresh_objectives)))
    profile = replace(profile, name=request.name, provenance=provenance,
                      description=profile.description or f"fitted on {request.data}")
    return CalibrationResult(profile=profile, best=best, objective=objective, evaluations=len(evaluator.history),
                             scores=tuple(scores), wall_time_s=wall_time_s,
                             fresh_seed_objectives=tuple(fresh_objectives))


def rounded(value: float) -> float:
    """A fitted value as written (4 significant digits: the fit is not more precise than that)."""
    return float(f"{value:.4g}") if value and math.isfinite(value) else value

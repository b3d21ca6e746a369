"""Field campaigns: a campaign's trials flown back to back on one vehicle over MAVLink.

`run_field_campaign` flies the pending trials one at a time, in the
campaign's order or shuffled with the campaign's seed (conditions drift over a
field day: a shuffled order spreads the drift over the scenarios). Around each
flight it does what a field team does by hand:

* before it, the vehicle goes back to the campaign's start (`between_trials`:
  `reposition` flies it back, `operator` asks for it to be carried back);
  the start is where the vehicle stood when the campaign first ran;
* the preflight checks run before every take-off; a refusal pauses the
  campaign with its line (the trial is flown once the operator goes on);
* after the landing the result is measured: asked of the operator (a tape
  measure; `redo`, `skip`, `abort`), taken from the vehicle's RTK position
  against the pad's surveyed position (`vehicle`), or, on a simulated vehicle,
  from its ground truth (`truth`);
* a battery below the swap threshold pauses the campaign until the vehicle
  comes back with a charged one; a pilot takeover or a lost link ends that
  trial with its outcome and pauses.

A pause the operator does not go on from (and every pause of a
`ScriptedOperator`) stops the campaign with `FieldCampaignPaused`: what is
recorded is kept and `--resume` continues with the next unflown trial.
Every flight is written to the campaign's journal (`field_log`) as it starts,
so a campaign killed mid-flight knows which flight it lost: on resume that
trial is flown again and its record says so (`details.reflown_after`).
"""

from __future__ import annotations

import asyncio
import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ..campaign.driver import check_store
from ..campaign.field_spec import BetweenTrials
from ..campaign.lease import DriverLease
from ..campaign.spec import CampaignSpec, resolve_scenarios
from ..campaign.store import ResultsStore, TrialRecord
from ..campaign.trials import TrialJob, error_record, fly_job, outcome_record, plan_trials
from ..errors import PrelandError
from ..geo import GeoPoint, LocalTangentPlane
from ..outcome import Outcome, TrialOutcome
from ..vehicle.mavlink_backend import MavlinkVehicle
from .operator import Measurement, Operator, Pause, Verdict
from .reposition import located, reposition

FIELD_SOURCE = "field"
RECONNECT_RETRY_S = 2.0  # wall seconds between tries to reach a vehicle coming back from a swap
LOCATE_TIMEOUT_S = 30.0  # vehicle seconds for a connected vehicle to report its position between flights


class Measure(enum.Enum):
    """Where a field trial's landing error comes from."""

    OPERATOR = "operator"  # asked of the operator (tape measure), or read from an answers file
    VEHICLE = "vehicle"  # the vehicle's final position (RTK) minus the pad's surveyed position
    TRUTH = "truth"  # a simulated vehicle's ground truth (sim serve, SITL): a rehearsal scored as simulated


class Order(enum.Enum):
    """The order of a field campaign's trials."""

    CAMPAIGN = "campaign"  # scenario by scenario, as the campaign file lists them
    SHUFFLED = "shuffled"  # a permutation drawn from the campaign's base seed (the same on every resume)


class FieldCampaignError(PrelandError):
    """A field campaign cannot run as asked."""


class FieldCampaignPaused(PrelandError):
    """The campaign stopped at a pause; what is recorded is kept and `--resume` continues it."""

    def __init__(self, message: str, *, done: int, total: int) -> None:
        self.done, self.total = done, total
        super().__init__(f"{message}; {done} of {total} trials stored: run again with --resume to go on")


@dataclass(frozen=True, kw_only=True)
class FieldStatus:
    """What the progress display shows: trials stored (`done` of `total`), the trial at hand (scenario and
    index), what the campaign is doing or waiting for, and the vehicle's battery (%, None until known)."""

    done: int
    total: int
    scenario: str | None
    trial_index: int | None
    doing: str
    battery_pct: float | None = None

    def line(self) -> str:
        where = f"{self.scenario} #{self.trial_index}" if self.scenario is not None else "campaign"
        battery = "" if self.battery_pct is None or self.battery_pct < 0 else f" · battery {self.battery_pct:.0f} %"
        return f"[{self.done}/{self.total}] {where} · {self.doing}{battery}"


def measure_source(measure: Measure, *, runtime_source: str) -> str:
    """What a field campaign's trials are stored as: `field`, measured on the vehicle or by hand, or the
    runtime's own source when the simulated vehicle's truth scores them."""
    return runtime_source if measure is Measure.TRUTH else FIELD_SOURCE


def trial_order(jobs: list[TrialJob], *, order: Order, seed: int) -> list[TrialJob]:
    """`jobs` in the campaign's order, or permuted by a generator seeded from the campaign's base seed
    (the whole plan is permuted, so a resumed campaign keeps the order it started with)."""
    if order is Order.CAMPAIGN:
        return list(jobs)
    permutation = np.random.default_rng(seed).permutation(len(jobs))
    return [jobs[int(i)] for i in permutation]


class FieldCampaign:
    """One field campaign on one store and one vehicle (see the module's docstring); `run()` flies it."""

    def __init__(self, *, campaign: CampaignSpec, store: ResultsStore, runtime, operator: Operator,
                 measure: Measure, order: Order = Order.CAMPAIGN, resume: bool = False,
                 status: Callable[[FieldStatus], None] | None = None,
                 progress: Callable[[int, int, TrialRecord | None], None] | None = None) -> None:
        if measure is Measure.TRUTH and not runtime.options.truth:
            raise FieldCampaignError("--measure truth: the vehicle reports no ground truth (a real drone): "
                                     "measure by operator or vehicle")
        if measure is Measure.VEHICLE and campaign.field.pad is None:
            raise FieldCampaignError(f"{campaign.source_path or campaign.name}, field.pad: --measure vehicle needs "
                                     "the pad's surveyed position (latitude_deg, longitude_deg)")
        if not runtime.options.truth:
            _check_sensors_without_truth(campaign, camera=runtime.options.camera_source is not None)
        self.campaign, self.store, self.runtime, self.operator = campaign, store, runtime, operator
        self.measure, self.order, self.resume = measure, order, resume
        self.spec = campaign.field
        self.source = measure_source(measure, runtime_source=runtime.source)
        self._status, self._progress = status, progress
        self.done = self.total = 0
        self.battery_pct: float | None = None
        self.start: GeoPoint | None = None

    # ---------------------------------------------------------------- the run

    def run(self) -> tuple[int, int]:
        """Fly every pending trial; returns (trials stored now, trials in the campaign). Raises
        FieldCampaignPaused where the operator stopped it."""
        campaign, store = self.campaign, self.store
        scenarios = resolve_scenarios(campaign)
        self.total = sum(s.trials for s in scenarios)
        lease = DriverLease(store, campaign=campaign.name, source=self.source, executor="field")
        lease.acquire()
        try:
            done_keys = check_store(campaign, scenarios, store, source=self.source, resume=self.resume)
            self.done = len(done_keys)
            plan = trial_order(list(plan_trials(campaign, scenarios, runtime=self.runtime)), order=self.order,
                               seed=campaign.base_seed)
            pending = [job for job in plan if job.key not in done_keys]
            if self._progress:
                self._progress(self.done, self.total, None)
            if not pending:
                return 0, self.total
            interrupted = self._note_interrupted(done_keys)
            self._session_start()
            ran = 0
            for number, job in enumerate(pending):
                lease.refresh()
                if number > 0 or self.resume:
                    self._ensure_landed(job)
                    self._back_to_start(job)
                self._fly_until_recorded(job, reflown_after=interrupted.get(job.key, []),
                                         last=number == len(pending) - 1)
                ran += 1
                lease.refresh(force=True)
            return ran, self.total
        finally:
            lease.release()

    def _say(self, doing: str, job: TrialJob | None = None) -> None:
        if self._status is not None:
            self._status(FieldStatus(done=self.done, total=self.total, scenario=job.scenario if job else None,
                                     trial_index=job.trial_index if job else None, doing=doing,
                                     battery_pct=self.battery_pct))

    def _pause(self, pause: Pause, message: str, job: TrialJob | None = None) -> None:
        """Wait for the operator; FieldCampaignPaused when they (or a script) stop here."""
        self._say(f"waiting for: {pause.value}", job)
        self.store.log_field(self.campaign.name, "paused", scenario=job.scenario if job else None,
                             trial_index=job.trial_index if job else None,
                             data={"pause": pause.name.lower(), "message": message})
        if not self.operator.confirm(pause, message):
            raise FieldCampaignPaused(f"paused: {message}", done=self.done, total=self.total)
        self.store.log_field(self.campaign.name, "resumed", scenario=job.scenario if job else None,
                             trial_index=job.trial_index if job else None, data={"pause": pause.name.lower()})

    # ---------------------------------------------------------------- the journal

    def _note_interrupted(self, done_keys: set[tuple[str, int]]) -> dict[tuple[str, int], list[str]]:
        """Why each unstored trial with a flight in the journal is flown again: a flight started and never
        ended (the campaign was killed mid-flight) gets an `interrupted` entry, once; a trial whose last entry
        is a `redo` was stopped before it was flown again. A flight that a preflight check refused is none."""
        last: dict[tuple[str, int], tuple[str, int]] = {}  # key -> (kind, attempt) of its newest entry
        for entry in self.store.field_log(self.campaign.name):
            if entry["kind"] in ("flight", "redo", "interrupted", "refused"):
                last[(entry["scenario"], entry["trial_index"])] = (entry["kind"], entry["data"].get("attempt", 1))
        reasons: dict[tuple[str, int], list[str]] = {}
        for key, (kind, attempt) in last.items():
            if key in done_keys or kind == "refused":
                continue
            if kind == "flight":
                self.store.log_field(self.campaign.name, "interrupted", scenario=key[0], trial_index=key[1],
                                     data={"attempt": attempt})
            reasons[key] = ["redo"] if kind == "redo" else ["interrupted"]
        return reasons

    def _attempts(self, job: TrialJob) -> int:
        """Flights of `job` so far, not counting take-offs a preflight check refused."""
        kinds = [entry["kind"] for entry in self.store.field_log(self.campaign.name)
                 if (entry["scenario"], entry["trial_index"]) == job.key]
        return kinds.count("flight") - kinds.count("refused")

    # ---------------------------------------------------------------- the vehicle between flights

    def _session_start(self) -> None:
        """The campaign's start (the vehicle's position when it first ran, kept in the journal), and a
        vehicle found armed is landed first."""
        for entry in self.store.field_log(self.campaign.name):
            if entry["kind"] == "start":
                data = entry["data"]
                self.start = GeoPoint(data["latitude_deg"], data["longitude_deg"], data["altitude_amsl_m"])
        telemetry = self._ensure_landed(None)
        if self.start is None:
            position = telemetry.global_position
            self.start = GeoPoint(position.latitude_deg, position.longitude_deg, position.altitude_amsl_m)
            self.store.log_field(self.campaign.name, "start", data={
                "latitude_deg": position.latitude_deg, "longitude_deg": position.longitude_deg,
                "altitude_amsl_m": position.altitude_amsl_m})

    def _ensure_landed(self, job: TrialJob | None):
        """The vehicle's telemetry once it is disarmed: one found armed (after a takeover, a kill mid-flight)
        pauses the campaign until the operator has landed it."""
        while True:
            telemetry = self._read_vehicle()
            if not telemetry.armed:
                return telemetry
            self._pause(Pause.VEHICLE_AWAY, f"the vehicle is armed ({telemetry.mode.name}, "
                                            f"{telemetry.altitude_rel_m:.1f} m up): land and disarm it", job)

    def _vehicle(self) -> MavlinkVehicle:
        options = self.runtime.options
        return MavlinkVehicle(url=self.runtime.url, link_timeout_s=options.link_timeout_s, paced=options.paced)

    def _read_vehicle(self):
        """Connect, read one telemetry sample, disconnect (the vehicle's state between flights)."""

        async def read():
            vehicle = self._vehicle()
            try:
                await vehicle.connect()
                return await located(vehicle, timeout_s=LOCATE_TIMEOUT_S)
            finally:
                await vehicle.close()

        telemetry = asyncio.run(read())
        self.battery_pct = telemetry.battery.remaining_pct
        return telemetry

    def _back_to_start(self, job: TrialJob) -> None:
        between = self.spec.between_trials
        if between is BetweenTrials.OPERATOR:
            self._pause(Pause.CARRY_BACK, f"carry the vehicle back to the start for {job.scenario} "
                                          f"#{job.trial_index}", job)
        elif between is BetweenTrials.REPOSITION:
            self._say("repositioning to the start", job)
            try:
                hop = asyncio.run(self._hop(job))
            except PrelandError as error:
                self._pause(Pause.VEHICLE_AWAY, f"reposition failed ({error}): bring the vehicle back to the "
                                                "start and land it", job)
                return
            self.store.log_field(self.campaign.name, "reposition", scenario=job.scenario,
                                 trial_index=job.trial_index,
                                 data={"before_m": round(hop.before_m, 2), "after_m": round(hop.after_m, 2),
                                       "flown": hop.flown})

    async def _hop(self, job: TrialJob):
        vehicle = self._vehicle()
        try:
            await vehicle.connect()
            return await reposition(vehicle=vehicle, start=self.start, mission=job.mission,
                                    altitude_m=self.spec.reposition_altitude_m,
                                    tolerance_m=self.spec.reposition_tolerance_m)
        finally:
            await vehicle.close()

    def _wait_for_charged_battery(self, job: TrialJob) -> None:
        """After a swap: wait (wall seconds, `reconnect_timeout_s`) for the vehicle to answer again with a
        battery above the swap threshold; pause again if it does not."""
        threshold = self.spec.battery_swap_pct
        deadline = time.monotonic() + self.spec.reconnect_timeout_s
        while True:
            self._say("waiting for: the vehicle to come back", job)
            try:
                telemetry = self._read_vehicle()
            except PrelandError as error:
                if time.monotonic() < deadline:
                    time.sleep(RECONNECT_RETRY_S)  # a link that fails at once (no route yet) is not hammered
                    continue
                self._pause(Pause.BATTERY, f"the vehicle did not come back within "
                                           f"{self.spec.reconnect_timeout_s:g} s ({error})", job)
                deadline = time.monotonic() + self.spec.reconnect_timeout_s
                continue
            charge = telemetry.battery.remaining_pct
            if charge < 0 or charge >= threshold:
                return
            self._pause(Pause.BATTERY, f"battery {charge:.0f} % is still below {threshold:g} %: swap it", job)

    # ---------------------------------------------------------------- one trial

    def _fly_until_recorded(self, job: TrialJob, *, reflown_after: list[str], last: bool) -> None:
        """Fly `job` until a record of it is stored (a preflight refusal or a `redo` flies it again); unless
        it is the `last` to fly, a low battery then pauses for a swap."""
        while True:
            attempt = self._attempts(job) + 1
            self.store.log_field(self.campaign.name, "flight", scenario=job.scenario, trial_index=job.trial_index,
                                 data={"attempt": attempt})
            self._say("flying", job)
            started = time.perf_counter()
            outcome = fly_job(job)
            wall_time_s = time.perf_counter() - started
            if isinstance(outcome, str):
                record = error_record(job, outcome, wall_time_s=wall_time_s, source=self.source)
                self._store(job, record, attempt=attempt, reflown_after=reflown_after)
                return
            self.battery_pct = outcome.details.get("battery_remaining_pct", self.battery_pct)
            failures = outcome.details.get("preflight_failures")
            if failures:
                self.store.log_field(self.campaign.name, "refused", scenario=job.scenario,
                                     trial_index=job.trial_index, data={"attempt": attempt, "failures": failures})
                self._pause(Pause.PREFLIGHT, f"preflight: {'; '.join(failures)}", job)
                continue
            record = outcome_record(job, outcome, wall_time_s=wall_time_s, source=self.source)
            if outcome.outcome is Outcome.LANDED:
                self._say("waiting for: measurement", job)
                answer = self._measurement(job, outcome)
                if answer.verdict is Verdict.REDO:
                    self.store.log_field(self.campaign.name, "redo", scenario=job.scenario,
                                         trial_index=job.trial_index,
                                         data={"attempt": attempt, "record": _plain(record)})
                    reflown_after = [*reflown_after, "redo"]
                    self._back_to_start(job)
                    continue
                record = _measured(record, answer, measure=self.measure, truth=outcome)
                self._store(job, record, attempt=attempt, reflown_after=reflown_after)
                if answer.verdict is Verdict.ABORT:
                    raise FieldCampaignPaused("aborted by the operator after the landing (stored as not measured)",
                                              done=self.done, total=self.total)
            else:
                self._store(job, record, attempt=attempt, reflown_after=reflown_after)
                if outcome.outcome in (Outcome.PILOT_TAKEOVER, Outcome.LINK_LOST):
                    pause = Pause.TAKEOVER if outcome.outcome is Outcome.PILOT_TAKEOVER else Pause.LINK_LOST
                    self._pause(pause, f"{outcome.outcome.value} ({outcome.message}): land the vehicle and "
                                       "disarm it", job)
            if not last:
                self._check_battery(job)
            return

    def _store(self, job: TrialJob, record: TrialRecord, *, attempt: int, reflown_after: list[str]) -> None:
        details = dict(record.result.get("details") or {})
        details["attempt"] = attempt
        if reflown_after:
            details["reflown_after"] = reflown_after
        record = replace(record, result={**record.result, "details": details})
        self.store.add_trial(record)
        self.done += 1
        if self._progress:
            self._progress(self.done, self.total, record)
        self._say(f"stored: {record.result.get('outcome')}"
                  + (f", {record.result['landing_error_cm']:.1f} cm"
                     if record.result.get("landing_error_cm") is not None else ""), job)

    def _check_battery(self, job: TrialJob) -> None:
        charge, threshold = self.battery_pct, self.spec.battery_swap_pct
        if charge is None or charge < 0 or charge >= threshold:
            return
        self._pause(Pause.BATTERY, f"battery {charge:.0f} % is below the swap threshold {threshold:g} %: swap it",
                    job)
        self._wait_for_charged_battery(job)

    def _measurement(self, job: TrialJob, outcome: TrialOutcome) -> Measurement:
        if self.measure is Measure.OPERATOR:
            return self.operator.measure(scenario=job.scenario, trial_index=job.trial_index)
        if self.measure is Measure.TRUTH:
            return Measurement(verdict=Verdict.MEASURED, error_cm=outcome.landing_error_cm,
                               x_cm=outcome.offset_north_cm, y_cm=outcome.offset_east_cm)
        return vehicle_measurement(outcome, pad=self.spec.pad)


def _check_sensors_without_truth(campaign: CampaignSpec, *, camera: bool) -> None:
    """On a vehicle without ground truth the simulated sensors have nothing to see: a scenario whose land
    mode reads preland's IR-LOCK model, or the virtual camera without a real one (`--camera`), is refused
    before anything flies."""
    for scenario in resolve_scenarios(campaign):
        strategy = scenario.mission.land.strategy()
        where = f"{campaign.source_path or campaign.name}, scenario {scenario.spec.label!r}"
        if strategy.uses_irlock:
            raise FieldCampaignError(f"{where}: land mode {strategy.name!r} reads preland's IR-LOCK model, which "
                                     "needs a simulated vehicle's ground truth (fly its marker scenarios on a "
                                     "drone)")
        if strategy.uses_marker and not camera:
            raise FieldCampaignError(f"{where}: land mode {strategy.name!r} reads camera frames: give the "
                                     "drone's camera with --camera")


def vehicle_measurement(outcome: TrialOutcome, *, pad) -> Measurement:
    """The landing error from the vehicle's final reported position (an RTK fix) against the pad's surveyed
    position: north and east offsets in cm. SKIP when the vehicle reported no position."""
    latitude, longitude = outcome.details.get("final_latitude_deg"), outcome.details.get("final_longitude_deg")
    if latitude is None or longitude is None:
        return Measurement(verdict=Verdict.SKIP)
    north_m, east_m, _ = LocalTangentPlane(GeoPoint(pad.latitude_deg, pad.longitude_deg, 0.0)).to_ned(
        GeoPoint(latitude, longitude, 0.0))
    return Measurement(verdict=Verdict.MEASURED, error_cm=100 * math.hypot(north_m, east_m), x_cm=100 * north_m,
                       y_cm=100 * east_m)


def _measured(record: TrialRecord, answer: Measurement, *, measure: Measure, truth: TrialOutcome) -> TrialRecord:
    """The record with the measured error in place of the runtime's score; the runtime's own score (a
    simulated vehicle's truth) kept as `details.truth_error_cm`."""
    result = dict(record.result)
    details = dict(result.get("details") or {})
    details["measured_by"] = measure.value
    if truth.landing_error_cm is not None and measure is not Measure.TRUTH:
        details["truth_error_cm"] = round(truth.landing_error_cm, 2)
    measured = answer.verdict is Verdict.MEASURED
    details["measured"] = measured
    if answer.verdict is Verdict.ABORT:
        details["not_measured_because"] = "aborted"
    result.update(landing_error_cm=answer.error_cm if measured else None,
                  offset_north_cm=answer.x_cm if measured else None,
                  offset_east_cm=answer.y_cm if measured else None, details=details)
    return replace(record, result=result)


def _plain(record: TrialRecord) -> dict:
    """A record's outcome row (no events, no trajectory), as kept in the journal for a redone flight."""
    return {"seed": record.seed, "runtime": record.runtime, "source": record.source,
            "wall_time_s": record.wall_time_s, **record.result}


def run_field_campaign(campaign: CampaignSpec, store: ResultsStore, *, runtime, operator: Operator | None = None,
                       answers: str | None = None, measure: str | Measure | None = None,
                       order: str | Order = Order.CAMPAIGN, resume: bool = False,
                       status: Callable[[FieldStatus], None] | None = None,
                       progress: Callable[[int, int, TrialRecord | None], None] | None = None) -> tuple[int, int]:
    """Fly `campaign` on the one vehicle `runtime` flies (see the module's docstring). `measure`: operator,
    vehicle or truth (default: operator when answers are given or the vehicle reports no truth, else truth);
    `answers`: an answers file (a `ScriptedOperator`); `operator`: who is asked to measure and to act on
    pauses (default, without answers: nobody, so a pause stops the campaign). Returns (trials stored now,
    trials in all)."""
    from .operator import ScriptedOperator, load_answers

    try:
        measure = Measure(measure) if measure is not None else (
            Measure.OPERATOR if answers is not None or not runtime.options.truth else Measure.TRUTH)
    except ValueError:
        raise FieldCampaignError(f"--measure: {measure!r} is not one of "
                                 f"{', '.join(m.value for m in Measure)}") from None
    try:
        order = Order(order)
    except ValueError:
        raise FieldCampaignError(f"--order: {order!r} is not one of {', '.join(o.value for o in Order)}") from None
    if answers is not None:
        if operator is not None:
            raise FieldCampaignError("--answers: the answers file is the operator; give one or the other")
        if measure is not Measure.OPERATOR:
            raise FieldCampaignError(f"--answers: answers are the operator's measurements, not with --measure "
                                     f"{measure.value}")
        trials = {s.spec.label: s.trials for s in resolve_scenarios(campaign)}
        operator = ScriptedOperator(load_answers(answers, trials=trials), source=str(answers))
    if operator is None:
        if measure is Measure.OPERATOR:
            raise FieldCampaignError("--answers: needed to measure by operator with nobody to ask (no terminal)")
        operator = ScriptedOperator({}, source="no operator")
    return FieldCampaign(campaign=campaign, store=store, runtime=runtime, operator=operator, measure=measure,
                         order=order, resume=resume, status=status, progress=progress).run()

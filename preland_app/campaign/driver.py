"""The campaign driver: runs a campaign's pending trials on an executor and commits each one as it arrives.

One loop for every executor (`executors/`): it holds the campaign's lease on
the store (`lease.py`: a second driver is refused), keeps a window of trials in
flight (a few per slot, so a campaign of 100,000 trials never holds 100,000
tasks), stores each finished trial in its own transaction, reports progress,
and on Ctrl-C cancels what is in flight and raises CampaignInterrupted: only the
trials in flight are lost, and `resume=True` runs only the trials the store
does not have yet.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path

from ..errors import PrelandError
from ..runtime.base import Runtime
from ..runtime.embedded import EmbeddedRuntime
from .executors import ExecutorOptions, TrialExecutor, create_executor
from .executors.local import refuse_while_a_worker_starts
from .lease import HEARTBEAT_PERIOD_S, DriverLease
from .spec import CampaignSpec, resolve_scenarios, spec_hash
from .store import DuplicateTrial, ResultsStore, StoreError, TrialRecord
from .trials import TrialJob, plan_trials

WINDOW_PER_SLOT = 2  # trials in flight per slot: enough to keep every worker busy while results come back

Progress = Callable[[int, int, TrialRecord | None], None]


class CampaignInterrupted(PrelandError):
    """The campaign was interrupted (Ctrl-C); what finished is stored."""

    def __init__(self, *, done: int, total: int) -> None:
        self.done = done
        self.total = total
        super().__init__(f"interrupted: {done} of {total} trials stored; run again with --resume to finish")


def run_campaign(campaign: CampaignSpec, store: ResultsStore, *, workers: int | None = None, resume: bool = False,
                 progress: Progress | None = None, runtime: Runtime = EmbeddedRuntime(),
                 executor: str | TrialExecutor = "local", options: ExecutorOptions | None = None,
                 outcomes_only: bool = False) -> tuple[int, int]:
    """Run the campaign's pending trials on `runtime` (default: the embedded simulator) on `executor`
    (a registered name, `options` for it, or an executor object), storing each as it finishes; with
    `outcomes_only`, without event logs and trajectories. `workers` is `options.workers` when no options are
    given. Returns (trials run now, trials in the campaign)."""
    refuse_while_a_worker_starts("run_campaign")
    if isinstance(executor, str):
        executor = create_executor(executor, options or ExecutorOptions(workers=workers))
    scenarios = resolve_scenarios(campaign)
    source = runtime.source
    lease = DriverLease(store, campaign=campaign.name, source=source, executor=executor.name or "custom")
    total = sum(scenario.trials for scenario in scenarios)
    finished = 0
    try:
        lease.acquire()
        try:
            done = check_store(campaign, scenarios, store, source=source, resume=resume)
            pending = (job for job in plan_trials(campaign, scenarios, runtime=runtime, outcomes_only=outcomes_only)
                       if job.key not in done)
            finished = sum(1 for s in scenarios for i in range(s.trials) if (s.spec.label, i) in done)
            if progress:
                progress(finished, total, None)
            if finished == total:
                return 0, total
            with executor:
                ran = _drive(pending, executor, store, lease, finished=finished, total=total, progress=progress)
            return ran, total
        finally:
            lease.release()
    except KeyboardInterrupt:  # before any trial ran (starting the executor, say): nothing to lose
        raise CampaignInterrupted(done=finished, total=total) from None


def check_store(campaign: CampaignSpec, scenarios, store: ResultsStore, *, source: str,
                 resume: bool) -> set[tuple[str, int]]:
    """The trials already stored; StoreError when the campaign may not run on this store as asked."""
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
    return done


def run_windowed(executor: TrialExecutor, jobs: Iterator[TrialJob], *, on_record: Callable[[TrialRecord], None],
                 poll_s: float, on_poll: Callable[[], None] | None = None) -> None:
    """Run `jobs` on a started executor, WINDOW_PER_SLOT per slot in flight at a time, handing each record to
    `on_record` as it arrives; `on_poll` runs after every wait of at most `poll_s` seconds for results."""
    in_flight, more = 0, True
    while more or in_flight:
        while more and in_flight < WINDOW_PER_SLOT * executor.slots():
            job = next(jobs, None)
            if job is None:
                more = False
                break
            executor.submit(job)
            in_flight += 1
        for record in executor.completed(timeout_s=poll_s):
            in_flight -= 1
            on_record(record)
        if on_poll is not None:
            on_poll()


def _drive(pending: Iterator[TrialJob], executor: TrialExecutor, store: ResultsStore, lease: DriverLease, *,
           finished: int, total: int, progress: Progress | None) -> int:
    ran = 0

    def commit(record: TrialRecord) -> None:
        nonlocal ran, finished
        try:
            store.add_trial(record)
        except DuplicateTrial:
            lease.refresh(force=True)  # another driver took the campaign over: that names it
            raise
        ran += 1
        finished += 1
        if progress:
            progress(finished, total, record)

    try:
        run_windowed(executor, pending, on_record=commit, poll_s=HEARTBEAT_PERIOD_S, on_poll=lease.refresh)
    except KeyboardInterrupt:
        executor.cancel()
        raise CampaignInterrupted(done=finished, total=total) from None
    except BaseException:
        executor.cancel()
        raise
    return ran

"""The executor interface: where a campaign's trials run, behind one small contract.

The campaign driver (`campaign/driver.py`) owns everything else: the store, the
window of trials in flight, progress, Ctrl-C, resume. An executor only runs
`run_job` on each job it is given, somewhere, and hands back one `TrialRecord`
per job, exactly once: the trial's own record, or an `error` record when the
trial could not give one (its worker died again after a retry, the task was
lost). Executors are found by name in `registry.py`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

from ...errors import PrelandError
from ..store import TrialRecord
from ..trials import TrialJob

WORKER_DEATH_RETRIES = 1  # a trial whose worker process dies is run once more; dying again is its outcome
WORKER_DIED_MESSAGE = "the worker process running this trial died"


class ExecutorError(PrelandError):
    """An executor cannot be used as asked (unknown name, missing package, unreachable cluster)."""


@dataclass(frozen=True, kw_only=True)
class ExecutorOptions:
    """What an executor may be told.

    `workers`: worker processes on this machine (local), or the CPUs of the local cluster an executor starts
    when it joins none (ray); None: one per core. `address`: the cluster to join (ray: `auto`,
    `ray://host:10001`, `host:6379`; None: $RAY_ADDRESS, else a local cluster). `trial_cpus`: CPUs each trial
    asks of a cluster scheduler. `sitl_resource`: the custom resource a SITL trial asks for, which nodes able
    to run the SITL binary advertise."""

    workers: int | None = None
    address: str | None = None
    trial_cpus: float = 1.0
    sitl_resource: str = "sitl"

    def __post_init__(self) -> None:
        if self.workers is not None and self.workers < 1:
            raise ExecutorError(f"workers: must be >= 1, got {self.workers}")
        if not self.trial_cpus > 0:
            raise ExecutorError(f"trial_cpus: must be > 0, got {self.trial_cpus}")


class TrialExecutor(ABC):
    """Runs trials somewhere. Used as a context manager: entering starts it (worker pool, cluster
    connection), leaving stops everything it started."""

    name: str = ""
    runs_elsewhere: bool = False
    """True when trials may run on other machines (files such as a SITL binary are then looked up there)."""

    def __enter__(self) -> "TrialExecutor":
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    @abstractmethod
    def start(self) -> None:
        """Start workers or join the cluster."""

    @abstractmethod
    def slots(self) -> int:
        """How many trials can run at once now (the driver keeps a few times this many in flight)."""

    @abstractmethod
    def submit(self, job: TrialJob) -> None:
        """Start one trial."""

    @abstractmethod
    def completed(self, timeout_s: float) -> list[TrialRecord]:
        """Records of trials finished since the last call, waiting at most `timeout_s` for the first one
        (an empty list when none finished in time). Every submitted job comes back exactly once."""

    @abstractmethod
    def cancel(self) -> None:
        """Stop every trial in flight at once (Ctrl-C); their records are never handed back."""

    @abstractmethod
    def close(self) -> None:
        """Stop what `start` started. Safe to call twice."""

"""Trials in worker processes on this machine (the default executor).

Workers start from a fork server (multiprocessing's `forkserver`): a clean process,
started once per driver process, that has imported what a trial needs, forks each
worker. A worker then starts in milliseconds instead of importing numpy, OpenCV and
preland again (about 0.4 CPU s each as a spawned process), and still inherits no
state of the driver: nothing leaks between campaigns. Each worker takes the
driver's environment of the moment its pool starts, as a spawned one would. Workers
ignore Ctrl-C (the driver handles it) and exit when the driver does, even when it is
killed: each watches the driver's process (a pidfd), and asks for SIGKILL when its
parent ends (PR_SET_PDEATHSIG). The fork server ends once the driver and every
worker have. Elsewhere (no fork server, no /proc) workers are spawned. A worker that dies
breaks the whole pool: every trial then in flight is run again in a new pool,
and one that was in flight at two such deaths is recorded as an error. A pool
none of whose workers got ready (the script that runs the campaign, which each
worker imports, fails there) stops the campaign instead, recording nothing. With one
worker, trials run in the driver's own process, one per `completed` call, with
OpenCV on one thread as in a pool's worker: one worker is one core.
"""

from __future__ import annotations

import ctypes
import multiprocessing
import os
import select
import signal
import sys
import threading
from collections import deque
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

from ..lease import parent_pid
from ..store import TrialRecord
from ..trials import TrialJob, error_record, run_job
from .base import WORKER_DEATH_RETRIES, WORKER_DIED_MESSAGE, ExecutorError, ExecutorOptions, TrialExecutor


# What a worker imports to fly a trial, imported once by the fork server instead of by every worker. Not the
# driver's main script: each worker imports that itself as it starts (to unpickle what it defines, as a
# spawned worker does), and its top-level code must not run in the server.
FORK_SERVER_PRELOAD = ("preland_app.campaign.trials", "cv2")
# What a script that runs a campaign on more than one worker needs, since each worker imports it.
MAIN_GUARD = "its top-level code must be under `if __name__ == \"__main__\":`"


def refuse_while_a_worker_starts(operation: str) -> None:
    """End this process (exit status 1) with one line on stderr saying why, when called while it starts as a
    campaign worker and imports the script that runs the campaign (multiprocessing's `_inheriting`, as its
    own check of a missing main guard reads): that script's top-level code runs again in every worker. One
    line, written at once, not a traceback: the pool's workers fail together, and a traceback is printed a
    piece at a time, so theirs interleave into lines that none of them wrote."""
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        # Imported as `__mp_main__` in the worker.
        sys.stderr.write(f"preland: {operation} was called while a campaign worker imported "
                         f"{_script(sys.modules.get('__mp_main__'))}: with more than one worker, each worker "
                         f"imports the script that runs the campaign, so {MAIN_GUARD}\n")
        sys.stderr.flush()
        raise SystemExit(1)


def _script(module) -> str:
    path = getattr(module, "__file__", None)
    return path if path else "the script that runs the campaign"


def _worker_init(campaign_pid: int, environment: dict[str, str] | None = None, started=None) -> None:
    """Workers die with the campaign process (a killed campaign leaves no orphans) and ignore Ctrl-C
    (the campaign process handles it). OpenCV runs on the worker's own thread: the pool already has a
    process per core, and OpenCV's thread pool on top would make them compete. `environment`: the
    campaign process's, when its pool started (the fork server holds the one it was started with).
    `started` (an Event of the pool's): set once the worker is ready, which a worker that fails while it
    imports the campaign's script never is."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG: the parent, which is the fork server for a forked worker
    except OSError:
        pass  # not Linux: workers still exit when their pipe closes
    try:
        campaign = os.pidfd_open(campaign_pid)
    except ProcessLookupError:
        os._exit(1)  # the campaign is gone already
    except (AttributeError, OSError):
        campaign = None  # no pidfd (not Linux, or older than 5.3): the parent's signal alone
    parent = os.getppid()
    # The campaign process is the parent (a spawned worker) or the fork server's parent (a forked one).
    if campaign_pid not in (parent, parent_pid(parent)):
        # The campaign died while this worker started, before the signal was asked for, which then never
        # comes; and the worker, holding its own end of the call queue, would wait on it for ever.
        os._exit(1)
    if campaign is not None:
        # A forked worker's parent is the fork server, which outlives a killed campaign while any worker does
        # (each holds the server's liveness pipe): so the worker watches the campaign itself.
        threading.Thread(target=_exit_when_readable, args=(campaign,), name="preland-campaign-watch",
                         daemon=True).start()
    if environment is not None:
        os.environ.clear()
        os.environ.update(environment)
    import cv2

    cv2.setNumThreads(1)
    if started is not None:
        started.set()


def _exit_when_readable(pidfd: int) -> None:
    """Exit this process when the process of `pidfd` ends (its pidfd turns readable)."""
    select.select([pidfd], [], [])
    os._exit(1)


def _pool_context() -> multiprocessing.context.BaseContext:
    """The fork server's context on Linux, with what a trial imports preloaded (the preload counts only
    before the server first starts, and is the same each time); spawn elsewhere."""
    if "forkserver" not in multiprocessing.get_all_start_methods() or not os.path.isdir("/proc"):
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(FORK_SERVER_PRELOAD))
    return context


class LocalExecutor(TrialExecutor):
    """`workers` processes on this machine (default: one per core)."""

    name = "local"

    def __init__(self, options: ExecutorOptions) -> None:
        if options.address is not None:
            raise ExecutorError("the local executor joins no cluster: an address needs another executor (ray)")
        self.workers = max(1, options.workers or os.cpu_count() or 1)
        self._pool: ProcessPoolExecutor | None = None
        self._in_flight: dict[Future, TrialJob] = {}
        self._inline: deque[TrialJob] = deque()
        self._deaths: dict[tuple[str, int], int] = {}
        self._opencv_threads: int | None = None
        self._worker_started = None  # the pool's Event: a worker of it got ready

    def start(self) -> None:
        if self.workers > 1:
            self._pool = self._new_pool()
        else:
            # OpenCV's own thread pool would take every core for one worker: measured on thesis_table3
            # on 2 cores, 30 to 34 CPU s for 22 to 26 wall s, against 25 to 28 CPU s for as many wall s
            # on one thread. The driver's setting is given back on close.
            import cv2

            self._opencv_threads = cv2.getNumThreads()
            cv2.setNumThreads(1)

    def _new_pool(self) -> ProcessPoolExecutor:
        context = _pool_context()
        self._worker_started = context.Event()
        return ProcessPoolExecutor(max_workers=self.workers, mp_context=context, initializer=_worker_init,
                                   initargs=(os.getpid(), dict(os.environ), self._worker_started))

    def slots(self) -> int:
        return self.workers

    def submit(self, job: TrialJob) -> None:
        if self._pool is None:
            self._inline.append(job)
        else:
            self._in_flight[self._pool.submit(run_job, job)] = job

    def completed(self, timeout_s: float) -> list[TrialRecord]:
        if self._pool is None:
            return [run_job(self._inline.popleft())] if self._inline else []
        if not self._in_flight:
            return []
        done, _ = wait(self._in_flight, timeout=timeout_s, return_when=FIRST_COMPLETED)
        records, broken = [], False
        for future in done:
            try:
                records.append(future.result())
            except BrokenProcessPool:
                broken = True
                continue
            except Exception as error:  # pickling or the like: still this trial's outcome
                records.append(error_record(self._in_flight[future], f"{type(error).__name__}: {error}"))
            del self._in_flight[future]
        if broken:
            records.extend(self._replace_broken_pool())
        return records

    def _replace_broken_pool(self) -> list[TrialRecord]:
        """A worker died (killed, out of memory): run every trial then in flight again in a new pool. When no
        worker of the pool ever got ready, none can start (the script that runs the campaign fails as the
        workers import it): the campaign stops, its trials are not recorded as errors."""
        if not self._worker_started.is_set():
            self._in_flight.clear()
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
            raise ExecutorError(f"no campaign worker could start (their errors are printed above): each imports "
                                f"{_script(sys.modules.get('__main__'))}, which must import without errors, and "
                                f"{MAIN_GUARD}")
        records, again = [], []
        for future, job in self._in_flight.items():
            if future.done() and not future.cancelled() and future.exception() is None:
                records.append(future.result())
                continue
            self._deaths[job.key] = self._deaths.get(job.key, 0) + 1
            if self._deaths[job.key] > WORKER_DEATH_RETRIES:
                records.append(error_record(job, WORKER_DIED_MESSAGE))
            else:
                again.append(job)
        self._in_flight.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        self._pool = self._new_pool()
        for job in again:
            self.submit(job)
        return records

    def _restore_opencv_threads(self) -> None:
        if self._opencv_threads is not None:
            import cv2

            cv2.setNumThreads(self._opencv_threads)
            self._opencv_threads = None

    def cancel(self) -> None:
        self._inline.clear()
        self._restore_opencv_threads()
        if self._pool is None:
            return
        processes = list(getattr(self._pool, "_processes", {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            if process.is_alive():
                process.kill()
        for process in processes:
            process.join(timeout=5)
        self._pool = None
        self._in_flight.clear()

    def close(self) -> None:
        self._restore_opencv_threads()
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

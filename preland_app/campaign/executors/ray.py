"""Trials as Ray tasks: on a local Ray instance, a `ray start` cluster, a `ray up` cluster or KubeRay.

Each trial is one task running `run_job` (`trial_cpus` CPUs, default 1). A
task whose worker process dies (killed, out of memory, its node lost) is run
again by Ray (`max_retries`); dying again is recorded as that trial's error. A
SITL trial also asks for one unit of a custom resource (`sitl`) that only nodes
able to run the SITL binary advertise (`ray start --resources '{"sitl": 4}'`),
and finds the binary there through $PRELAND_SITL_BINARY unless given one.

The driver (preland's process) joins the cluster at `address`, or $RAY_ADDRESS,
or starts a local Ray instance of `workers` CPUs that it stops again when the
campaign ends or is interrupted. Results come back to the driver, which alone
writes the store.
"""

from __future__ import annotations

import logging
import os
import socket
import time

from ..store import TrialRecord
from ..trials import TrialJob, error_record, run_job
from .base import WORKER_DEATH_RETRIES, WORKER_DIED_MESSAGE, ExecutorError, ExecutorOptions, TrialExecutor

# Ray waits a fixed 30 s for a local node's raylet to register (ray/_private/node.py, not configurable), and the
# raylet waits a fixed time for its Python agents to start before it aborts ("Timed out waiting for file
# .../metrics_agent_port_..." in raylet.out; 18 s after it started them, in one run of the test suite here).
# On a loaded machine the agents' imports can take longer; a next try often starts. A start that timed out so
# is tried again, up to this many tries in all.
LOCAL_START_TRIES = 5
_STARTUP_TIMED_OUT = "timed out during startup"
# Ray starts its workers at nice 15 (its `worker_niceness`), so that they yield to Ray's own daemons. Trials
# are the work: at nice 15 beside any other busy process they get a few per cent of a core (a 12-trial campaign
# took 136 s beside four CPU-bound loops on 2 cores, 8.3 s at nice 0, 2.8 s idle). A local instance preland
# starts runs them at this niceness, as the local executor's processes run; a cluster started by `ray start`
# keeps its own (RAY_worker_niceness=0 in the environment of `ray start` sets the same).
LOCAL_WORKER_NICENESS = 0
CAPACITY_REFRESH_S = 10.0  # how often the cluster's CPUs are read again (an autoscaling cluster grows)
REACH_TIMEOUT_S = 10.0  # how long a cluster address may take to accept a connection (Ray itself retries forever)


def check_reachable(address: str, *, timeout_s: float = REACH_TIMEOUT_S) -> None:
    """ExecutorError unless `address` (`host:port` or `ray://host:port`) accepts a TCP connection within
    `timeout_s`; `auto` and other forms are left to Ray, which fails fast on them."""
    host, _, port = address.removeprefix("ray://").rpartition(":")
    if not host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except OSError as error:
        reason = (f"no answer within {timeout_s:g} s" if isinstance(error, TimeoutError)
                  else (error.strerror or str(error)).lower())
        raise ExecutorError(f"cannot reach a Ray cluster at {address}: {reason}") from None


def start_local_ray(ray, **init) -> None:
    """`ray.init(address="local", **init)` with workers at LOCAL_WORKER_NICENESS (unless `init`'s
    `_system_config` sets one), tried again (up to LOCAL_START_TRIES in all) when the node timed out during
    startup; anything else is raised at once. Whatever part of the instance had started is stopped before
    each new try."""
    init["_system_config"] = {"worker_niceness": LOCAL_WORKER_NICENESS, **init.get("_system_config", {})}
    for attempt in range(1, LOCAL_START_TRIES + 1):
        try:
            ray.init(address="local", **init)
            return
        except Exception as error:
            ray.shutdown()
            if _STARTUP_TIMED_OUT not in str(error) or attempt == LOCAL_START_TRIES:
                raise


def run_job_in_ray_worker(job: TrialJob, opencv_threads: int = 1) -> TrialRecord:
    """`run_job` in a Ray worker, with OpenCV's thread pool sized to the CPUs the task asked for: Ray sizes
    OMP_NUM_THREADS to them but not OpenCV's own pool, which would otherwise take every core of the node
    and compete with the node's other trials."""
    import cv2

    cv2.setNumThreads(max(1, opencv_threads))
    return run_job(job)


def _ray():
    try:
        import ray
    except ImportError:
        raise ExecutorError("the ray executor needs Ray: pip install 'preland[ray]'") from None
    return ray


class RayExecutor(TrialExecutor):
    """Trials as tasks of a Ray cluster."""

    name = "ray"
    runs_elsewhere = True

    def __init__(self, options: ExecutorOptions) -> None:
        self.options = options
        self._ray = _ray()
        self._started_ray = False
        self._refs: dict[object, TrialJob] = {}
        self._task = None
        self._sitl_checked = False
        self._cpus = 0.0
        self._cpus_read_at = -float("inf")

    def start(self) -> None:
        ray = self._ray
        if self.options.address is not None:
            check_reachable(self.options.address)  # an address asked for is checked, whatever this process joined
        if ray.is_initialized():  # a caller (a notebook, a test) already joined a cluster: use it, leave it up
            self._task = ray.remote(run_job_in_ray_worker)
            self._check_trial_cpus()
            return
        address = self.options.address or os.environ.get("RAY_ADDRESS") or None
        quiet = dict(logging_level=logging.WARNING, log_to_driver=False)
        if address is not None and self.options.address is None:
            check_reachable(address)
        try:
            if address is None:
                start_local_ray(ray, num_cpus=self.options.workers or os.cpu_count() or 1, include_dashboard=False,
                                **quiet)
            else:
                ray.init(address=address, **quiet)
        except KeyboardInterrupt:
            ray.shutdown()  # stops whatever part of a local instance had started
            raise
        except Exception as error:  # Ray raises ConnectionError, ValueError, RuntimeError... for a bad address
            ray.shutdown()
            where = f"Ray cluster at {address}" if address else "a local Ray instance"
            raise ExecutorError(f"cannot start or join {where}: {type(error).__name__}: "
                                f"{str(error).strip().splitlines()[0] if str(error).strip() else ''}") from None
        self._started_ray = True
        self._task = ray.remote(run_job_in_ray_worker)
        try:
            self._check_trial_cpus()
        except ExecutorError:
            self.close()  # the caller's `with` never reaches its exit when entering fails
            raise

    def _check_trial_cpus(self) -> None:
        """A trial that no node has the CPUs for would wait forever: refuse it at once."""
        largest = max((node.get("Resources", {}).get("CPU", 0.0) for node in self._ray.nodes() if node.get("Alive")),
                      default=0.0)
        if self.options.trial_cpus > largest:
            raise ExecutorError(f"no node of the Ray cluster has {self.options.trial_cpus:g} CPUs for one trial "
                                f"(the largest has {largest:g}); lower --trial-cpus")

    def slots(self) -> int:
        now = time.monotonic()
        if now - self._cpus_read_at > CAPACITY_REFRESH_S:
            self._cpus = float(self._ray.cluster_resources().get("CPU", 0.0))
            self._cpus_read_at = now
        return max(1, int(self._cpus // self.options.trial_cpus))

    def _check_sitl_nodes(self) -> None:
        resource = self.options.sitl_resource
        if self._ray.cluster_resources().get(resource, 0.0) <= 0:
            raise ExecutorError(f"no node of the Ray cluster advertises the {resource!r} resource that SITL trials "
                                f"ask for: start SITL nodes with ray start --resources '{{\"{resource}\": N}}'")
        self._sitl_checked = True

    def submit(self, job: TrialJob) -> None:
        resources = {}
        if job.runtime.cluster_resource is not None:
            if not self._sitl_checked:
                self._check_sitl_nodes()
            resources = {self.options.sitl_resource: 1}
        ref = self._task.options(num_cpus=self.options.trial_cpus, resources=resources,
                                 max_retries=WORKER_DEATH_RETRIES, retry_exceptions=False).remote(
            job, opencv_threads=max(1, int(self.options.trial_cpus)))
        self._refs[ref] = job

    def completed(self, timeout_s: float) -> list[TrialRecord]:
        ray = self._ray
        if not self._refs:
            return []
        refs = list(self._refs)
        ready, _ = ray.wait(refs, num_returns=1, timeout=timeout_s)
        if not ready:
            return []
        ready, _ = ray.wait(refs, num_returns=len(refs), timeout=0)
        records = []
        for ref in ready:
            job = self._refs.pop(ref)
            try:
                records.append(ray.get(ref))
            except ray.exceptions.WorkerCrashedError:
                records.append(error_record(job, WORKER_DIED_MESSAGE))
            except ray.exceptions.RayError as error:  # a lost node, a task that could not be sent...
                message = str(error).strip().splitlines()[0] if str(error).strip() else ""
                records.append(error_record(job, f"{type(error).__name__}: {message}"))
        return records

    def cancel(self) -> None:
        if self._started_ray:
            # Our own local instance: shutting it down stops its tasks. Cancelling first races Ctrl-C,
            # which reaches Ray's workers too: a worker's reply to a task already cancelled trips a fatal
            # check in Ray's core worker (task_manager.cc "Tried to complete task that was not pending",
            # Ray 2.60), killing the driver with exit 1 and leaving Ray's agents behind.
            self._refs.clear()
            return
        for ref in list(self._refs):
            try:
                self._ray.cancel(ref, force=True)
            except Exception:  # already finished or gone: nothing left to stop
                pass
        self._refs.clear()

    def close(self) -> None:
        if self._started_ray:
            self._ray.shutdown()
            self._started_ray = False

"""A local Ray instance for a test module, and the processes Ray and preland's Ray drivers start.

`make test` hands each module to one xdist worker (--dist loadfile): the modules that use `cluster` each start
one Ray instance (2 CPUs, one `sitl` slot) for their tests, and each waits for its drivers on its own worker."""

import logging
import os
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from preland_app.campaign.executors.ray import start_local_ray
from preland_app.runtime.sitl import SITL_ENV

from .conftest import ROOT
from .procs import alive, cmdline, descendants, identified
from .waiting import until

NODE_SITL = "/bin/false"  # the SITL binary the Ray node advertises: one that exits before its vehicle answers
# The bound on a driver's waits is for one that hangs, not a speed target: a Ray driver on a loaded 2-core
# machine takes minutes to start and run a few trials.
DRIVER_HANG_S = 600.0
# How long the module's instance may take to have its workers up (a bound for one that never does).
WORKERS_UP_S = 300.0


def ray_processes(pid: int) -> dict[int, int]:
    """Ray's processes under `pid`: its servers (a program or script of Ray's package) and its workers
    ("ray::..."), each pid with the ticks it started at (`alive`)."""
    # The start time first (`identified`), then the command line: a pid given to another process in between
    # then counts as gone (the Ray process that had it is), where one read after the command line could be
    # the newcomer's.
    return {child: ticks for child, ticks in identified(descendants(pid)).items()
            if _is_ray(cmdline(child))}


def _is_ray(command: str) -> bool:
    """A Ray server runs a program of Ray's package, or Python on a script of it (`python -u .../agent.py`):
    the path is in the first words. Further on, Ray's folder is only an argument: the local executor's fork
    server, started after Ray was imported, is given a sys.path that holds Ray's `thirdparty_files`."""
    return command.startswith("ray::") or any("site-packages/ray/" in word for word in command.split(" ")[:3])


def wait_gone(processes: dict[int, int], timeout_s: float = 60.0) -> list[str]:
    """Wait until none of `processes` (from `ray_processes`) runs; those still running after `timeout_s`."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and any(alive(pid, ticks) for pid, ticks in processes.items()):
        time.sleep(0.2)
    return [f"{pid} {cmdline(pid)[:80]}" for pid, ticks in processes.items() if alive(pid, ticks)]


@pytest.fixture(scope="module")
def cluster():
    """A local Ray instance with 2 CPUs and one `sitl` slot, whose nodes' $PRELAND_SITL_BINARY is NODE_SITL;
    stopped after the module's last test (its daemons and idle workers would otherwise take CPU from the
    tests that follow on that worker), leaving no Ray process behind. Yields its GCS address."""
    import ray  # here, not at the top: every xdist worker imports this module to collect the tests

    previous = os.environ.get(SITL_ENV)
    os.environ[SITL_ENV] = NODE_SITL  # what Ray's processes inherit: the node's environment
    try:
        start_local_ray(ray, num_cpus=2, resources={"sitl": 1}, include_dashboard=False,
                        logging_level=logging.WARNING, log_to_driver=False)
    finally:
        if previous is None:
            os.environ.pop(SITL_ENV)
        else:
            os.environ[SITL_ENV] = previous
    address = ray.get_runtime_context().gcs_address
    # Ray starts the node's workers as the node comes up, and `init` can return while they still start (each
    # imports Ray). Waited for here, so that their start is over before the module's first test starts a
    # driver's Ray instance of its own (whose raylet gives its agents a fixed time to start).
    try:
        until(lambda: sum(cmdline(child).startswith("ray::IDLE") for child in ray_processes(os.getpid())) >= 2,
              timeout_s=WORKERS_UP_S, what="the 2 workers of the module's Ray instance to be up (titled ray::IDLE)",
              poll_s=0.2)  # each look walks /proc: not every 10 ms beside the start it waits for
    except AssertionError:
        ray.shutdown()  # no Ray process left behind by a module that could not start
        raise
    yield address
    started = ray_processes(os.getpid())
    ray.shutdown()
    assert started, "no process of the module's Ray instance was found under this process at its end"
    left = wait_gone(started)
    assert left == [], f"{len(left)} of the module's {len(started)} Ray processes still run 60 s after shutdown"


def stored_trials(db: Path) -> int:
    try:
        with sqlite3.connect(db) as connection:
            return connection.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


def stopped_and_said(process: subprocess.Popen) -> str:
    """Stop `process` if it still runs; the end of what it wrote to stderr."""
    if process.poll() is None:
        process.terminate()
    return process.communicate(timeout=60)[1].decode(errors="replace")[-2000:]


def wait_stored(db: Path, count: int, process: subprocess.Popen, timeout_s: float = DRIVER_HANG_S) -> int:
    """Wait until `db` holds `count` trials while `process` runs."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and process.poll() is None:
        stored = stored_trials(db)
        if stored >= count:
            return stored
        time.sleep(0.05)
    running = process.poll() is None
    said = stopped_and_said(process)
    raise AssertionError(f"{count} trials were not stored ({stored_trials(db)} were) "
                         f"{f'within {timeout_s:g} s' if running else 'before the driver ended'}: {said}")


def finished(db: Path, process: subprocess.Popen, timeout_s: float = DRIVER_HANG_S) -> str:
    """Wait until the driver `process` ends; its stderr. One that has not ended within the bound is stopped,
    and the failure says how many trials `db` holds."""
    try:
        return process.communicate(timeout=timeout_s)[1].decode(errors="replace")
    except subprocess.TimeoutExpired:
        said = stopped_and_said(process)
        raise AssertionError(f"the driver did not end within {timeout_s:g} s ({stored_trials(db)} trials stored): "
                             f"{said}") from None


def driver_process(args: list[str], **kwargs) -> subprocess.Popen:
    """`preland campaign run ARGS --quiet` in a process of its own, not given this process's Ray address."""
    env = {key: value for key, value in os.environ.items() if key != "RAY_ADDRESS"}
    return subprocess.Popen([sys.executable, "-m", "preland_app.cli", "campaign", "run", *args, "--quiet"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)

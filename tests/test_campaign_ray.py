"""Campaigns on Ray. Drivers in processes of their own: Ctrl-C, one SIGKILLed and resumed, two at once; no Ray
process left behind. In this process: the same rows as local processes, a trial that raises, a retried worker,
SITL nodes, the Python API, OpenCV's threads and a Ray address checked. One local Ray instance (2 CPUs) serves
the module (`ray_support.cluster`): the drivers join it or must not. The longest tests first: xdist hands this
worker its next file once two tests are left."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.executors import ExecutorError, ExecutorOptions, create_executor
from preland_app.campaign.executors.ray import LOCAL_WORKER_NICENESS, RayExecutor
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app
from preland_app.runtime.sitl import SITL_ENV, SitlOptions, SitlRuntime

from .conftest import ROOT
from .procs import alive, cmdline, descendants, started_ticks
from .ray_support import (NODE_SITL, cluster, driver_process, finished, ray_processes,  # noqa: F401 (cluster)
                          wait_gone, wait_stored)
from .test_campaign import QUICK, comparable, write_campaign
from .tools.terminal import as_from_a_terminal

pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc to find Ray's processes")

ROW = ("scenario", "trial_index", "seed", "outcome", "message")


def test_ctrl_c_stops_a_ray_campaign_with_130_and_a_resumed_one_ends_leaving_no_ray_process(cluster, tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 5"))
    db = tmp_path / "interrupted.db"
    args = [str(path), "--db", str(db), "--executor", "ray", "--workers", "1"]
    driver = driver_process(args, start_new_session=True, preexec_fn=as_from_a_terminal)
    wait_stored(db, 1, driver)
    started = ray_processes(driver.pid)
    assert any("raylet" in cmdline(pid) for pid in started), "the driver starts a local Ray instance of its own"
    # Its trials run at the driver's own niceness (Ray's default adds 15, which starves them beside any other
    # busy process): Ray adds its worker niceness to the one its workers inherit, here this process's.
    workers = [pid for pid in started if cmdline(pid).startswith("ray::")]
    inherited = min(19, os.getpriority(os.PRIO_PROCESS, 0) + LOCAL_WORKER_NICENESS)
    assert workers and {os.getpriority(os.PRIO_PROCESS, pid) for pid in workers} == {inherited}
    os.killpg(driver.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the whole foreground process group
    _, stderr = driver.communicate(timeout=60)
    assert driver.returncode == 130, stderr
    assert "interrupted:" in stderr.decode() and "Traceback" not in stderr.decode()
    assert wait_gone(started) == []
    with ResultsStore(db) as store:
        assert 1 <= len(store.trials("quick")) < 10

    resumed = driver_process([*args, "--resume"])
    wait_stored(db, 9, resumed)
    started = ray_processes(resumed.pid)
    stderr = finished(db, resumed)
    assert resumed.returncode == 0, stderr
    assert started and wait_gone(started) == []
    with ResultsStore(db) as store:
        keys = [(t["scenario"], t["trial_index"]) for t in store.trials("quick")]
        assert len(keys) == 10 and len(set(keys)) == 10


def test_a_sigkilled_ray_driver_resumes_to_the_rows_of_an_uninterrupted_run(cluster, tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 5"))
    db = tmp_path / "killed.db"
    first = driver_process([str(path), "--db", str(db), "--executor", "ray", "--ray-address", cluster])
    assert 2 <= wait_stored(db, 2, first) < 10
    first.kill()
    first.wait(timeout=10)
    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(db), "--resume", "--quiet",
                                      "--executor", "ray"])
    assert result.exit_code == 0, result.output
    with ResultsStore(db) as resumed, ResultsStore(":memory:") as straight:
        run_campaign(load_campaign(path), straight, workers=1)
        keys = [(t["scenario"], t["trial_index"]) for t in resumed.trials("quick")]
        assert len(keys) == 10 and len(set(keys)) == 10
        assert comparable(resumed, "quick") == comparable(straight, "quick")


def test_two_ray_drivers_at_once_one_is_refused_and_every_trial_is_stored_once(cluster, tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 6"))
    db = tmp_path / "busy.db"
    first = driver_process([str(path), "--db", str(db), "--executor", "ray", "--ray-address", cluster])
    wait_stored(db, 1, first)
    second = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(db), "--resume", "--quiet",
                                      "--executor", "ray"])
    assert first.poll() is None, "the first driver should still be running"
    assert second.exit_code == 1 and "Traceback" not in second.output, second.output
    assert len(second.stderr.strip().splitlines()) == 1
    assert f"being run by another driver (pid {first.pid} on host" in second.stderr and "ray executor" in second.stderr
    stderr = finished(db, first)
    assert first.returncode == 0, stderr
    with ResultsStore(db) as store:
        keys = [(t["scenario"], t["trial_index"]) for t in store.trials("quick")]
        assert len(keys) == 12 and len(set(keys)) == 12


def test_smoke_gives_the_same_rows_on_ray_as_on_local_processes(cluster, tmp_path):
    campaign = load_campaign(ROOT / "campaigns" / "smoke.yaml")
    rows = {}
    for executor in ("local", "ray"):
        with ResultsStore(tmp_path / f"{executor}.db") as store:
            assert run_campaign(campaign, store, executor=executor, options=ExecutorOptions(workers=2)) == (6, 6)
            rows[executor] = store.trials("smoke")
    assert [tuple(r[c] for c in ROW) for r in rows["ray"]] == [tuple(r[c] for c in ROW) for r in rows["local"]]
    for on_ray, local in zip(rows["ray"], rows["local"]):
        assert on_ray["landing_error_cm"] == pytest.approx(local["landing_error_cm"], abs=1e-6)
        assert on_ray["details"] == local["details"] and on_ray["landing_time_s"] == local["landing_time_s"]
    assert {r["outcome"] for r in rows["ray"]} == {"landed"}


def test_a_trial_that_raises_is_an_error_and_the_campaign_goes_on_on_both_executors(cluster, tmp_path):
    pad = tmp_path / "pad.yaml"
    pad.write_text("name: p\ndictionary: DICT_4X4_50\nmarkers: [{id: 16, side_m: 0.6}]\n")
    campaign = load_campaign(write_campaign(tmp_path, f"name: fragile\ntrials: 2\npad: {pad}\nscenarios:\n"
                                                      "  - {label: marker, land: marker}\n"
                                                      "  - {label: gps, land: normal}\n"))
    pad.unlink()  # gone once the campaign was checked: every marker trial raises
    results = []
    for executor in ("local", "ray"):
        with ResultsStore(":memory:") as store:
            assert run_campaign(campaign, store, executor=executor, options=ExecutorOptions(workers=2)) == (4, 4)
            results.append(comparable(store, "fragile"))
            assert [(t["scenario"], t["outcome"]) for t in store.trials("fragile")] == [
                ("marker", "error"), ("marker", "error"), ("gps", "landed"), ("gps", "landed")]
            assert all("pad.yaml" in t["message"] for t in store.trials("fragile") if t["outcome"] == "error")
    assert results[0] == results[1]


class KillingRayExecutor(RayExecutor):
    """Ray's executor, SIGKILLing the worker process of one running trial once two trials are in flight."""

    def __init__(self, options: ExecutorOptions) -> None:
        super().__init__(options)
        self.submitted = 0
        self.killed: list[int] = []

    def submit(self, job) -> None:
        super().submit(job)
        self.submitted += 1
        if self.submitted != 2:
            return
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:  # a worker running a trial carries Ray's title "ray::run_job"
            running = [pid for pid in descendants(os.getpid()) if cmdline(pid).startswith("ray::run_job")]
            if running:
                os.kill(running[0], signal.SIGKILL)
                self.killed.append(running[0])
                return
            time.sleep(0.01)


def test_a_ray_worker_killed_mid_trial_is_retried_and_every_trial_stored_once(cluster, tmp_path):
    campaign = load_campaign(write_campaign(tmp_path, "name: killed\ntrials: 3\nbase_seed: 5\nscenarios:\n"
                                                      "  - {label: marker, land: marker, initial_height_m: 6}\n"))
    executor = KillingRayExecutor(ExecutorOptions())
    with ResultsStore(tmp_path / "k.db") as store:
        assert run_campaign(campaign, store, executor=executor) == (3, 3)
        trials = store.trials("killed")
    assert len(executor.killed) == 1 and not alive(executor.killed[0])
    assert [t["trial_index"] for t in trials] == [0, 1, 2]
    # The killed trial ran again (else it would be stored as "the worker process running this trial died").
    assert [t["outcome"] for t in trials] == ["landed"] * 3, [t["message"] for t in trials]


def test_sitl_trials_need_sitl_nodes_and_use_their_binary_and_a_trial_must_fit_a_node(cluster, tmp_path, monkeypatch):
    monkeypatch.delenv(SITL_ENV, raising=False)  # the driver has no SITL binary: the node has
    campaign = load_campaign(write_campaign(tmp_path, "name: on_sitl\ntrials: 1\n"
                                                      "scenarios: [{label: gps, land: normal}]\n"))
    with ResultsStore(":memory:") as store:
        assert run_campaign(campaign, store, executor="ray", runtime=SitlRuntime(options=SitlOptions(binary=None))) == (1, 1)
        (trial,) = store.trials("on_sitl")
    assert trial["source"] == "sitl" and trial["outcome"] == "error"
    assert f"{NODE_SITL} exited with code 1 before its vehicle answered" in trial["message"]
    with ResultsStore(":memory:") as store, pytest.raises(ExecutorError, match="has 4 CPUs for one trial"):
        run_campaign(campaign, store, executor=create_executor("ray", ExecutorOptions(trial_cpus=4)))
    with ResultsStore(":memory:") as store, pytest.raises(ExecutorError, match="advertises the 'sitl_x86' resource"):
        run_campaign(campaign, store, runtime=SitlRuntime(options=SitlOptions(binary=None)),
                     executor=create_executor("ray", ExecutorOptions(sitl_resource="sitl_x86")))


def test_the_python_api_runs_a_campaign_on_ray(cluster, tmp_path):
    import preland_app as preland

    path = write_campaign(tmp_path, "name: api_ray\ntrials: 2\nbase_seed: 3\nscenarios: [{label: gps, land: normal}]\n")
    on_ray = preland.run_campaign(path, db=tmp_path / "ray.db", executor="ray", outcomes_only=True)
    local = preland.run_campaign(path, db=tmp_path / "local.db", workers=1)
    assert (on_ray.ran, on_ray.total) == (local.ran, local.total) == (2, 2)
    ray_rows, local_rows = (preland.read_results(run.db, campaign="api_ray") for run in (on_ray, local))
    assert [(r["seed"], r["outcome"], r["landing_error_cm"]) for r in ray_rows] == \
        [(r["seed"], r["outcome"], r["landing_error_cm"]) for r in local_rows]
    assert {r["outcome"] for r in local_rows} == {"landed"}


def test_a_ray_trial_runs_opencv_on_as_many_threads_as_cpus_it_asked_for(cluster):
    """Ray sizes OMP_NUM_THREADS to a task's CPUs but not OpenCV's own pool, which would take the node's
    every core; the task sets it before the trial."""
    import ray

    from preland_app.campaign.executors.ray import run_job_in_ray_worker
    from preland_app.campaign.spec import resolve_scenarios
    from preland_app.campaign.trials import plan_trials

    campaign = load_campaign(ROOT / "campaigns" / "smoke.yaml")
    job = next(plan_trials(campaign, resolve_scenarios(campaign), outcomes_only=True))

    @ray.remote(num_cpus=1)
    def trial_then_threads(job, threads):
        import cv2

        cv2.setNumThreads(8)  # what a fresh worker might have
        record = run_job_in_ray_worker(job, opencv_threads=threads)
        return record.result["outcome"], cv2.getNumThreads()

    assert ray.get(trial_then_threads.remote(job, 1), timeout=120) == ("landed", 1)
    assert ray.get(trial_then_threads.remote(job, 2), timeout=120) == ("landed", 2)


def test_an_address_asked_for_is_checked_even_when_this_process_joined_a_cluster(cluster, tmp_path):
    import socket

    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]  # nothing listens there once the socket is closed
    import ray

    assert ray.is_initialized()  # the module's cluster: joined, and not the address asked for
    path = write_campaign(tmp_path, "name: elsewhere\ntrials: 1\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db"), "--quiet",
                                      "--executor", "ray", "--ray-address", f"127.0.0.1:{port}"])
    assert result.exit_code == 2, result.output
    assert result.stderr.strip() == (f"preland: error: --executor ray: cannot reach a Ray cluster at 127.0.0.1:{port}: "
                                     "connection refused")


class _SlowToStartRay:
    """A stand-in for the `ray` module whose local node times out during startup `failures` times, as Ray's
    node.py words it."""

    def __init__(self, failures: int, error: str = "The current node timed out during startup. This could "
                                                   "happen because some of the raylet failed to startup or the "
                                                   "GCS has become overloaded.") -> None:
        self.failures, self.error = failures, error
        self.calls: list[str] = []

    def init(self, **kwargs):
        self.calls.append(f"init {kwargs['address']} {kwargs['num_cpus']}")
        if self.failures:
            self.failures -= 1
            raise Exception(self.error)

    def shutdown(self):
        self.calls.append("shutdown")


def test_a_local_ray_that_times_out_during_startup_is_started_again():
    from preland_app.campaign.executors.ray import LOCAL_START_TRIES, start_local_ray

    slow = _SlowToStartRay(failures=LOCAL_START_TRIES - 1)
    start_local_ray(slow, num_cpus=2)
    assert slow.calls == ["init local 2", "shutdown"] * (LOCAL_START_TRIES - 1) + ["init local 2"]

    never = _SlowToStartRay(failures=LOCAL_START_TRIES)
    with pytest.raises(Exception, match="timed out during startup"):
        start_local_ray(never, num_cpus=2)
    assert never.calls.count("init local 2") == LOCAL_START_TRIES and never.calls[-1] == "shutdown"

    other = _SlowToStartRay(failures=1, error="some other failure")  # not retried
    with pytest.raises(Exception, match="some other failure"):
        start_local_ray(other, num_cpus=2)
    assert other.calls == ["init local 2", "shutdown"]


def test_a_pid_another_process_was_given_counts_as_gone():
    """The checks that Ray's processes are gone look at each pid's start time too: a pid Linux gave to a new
    process since is not the Ray process that had it."""
    program = "import sys; print('up', flush=True); sys.stdin.read()"
    child = subprocess.Popen([sys.executable, "-c", program], stdin=subprocess.PIPE, stdout=subprocess.PIPE)
    try:
        # Once it says so, the child runs its own program (Popen returns during the exec, when /proc may
        # still show no command line).
        assert child.stdout.readline() == b"up\n"
        ticks = started_ticks(child.pid)
        assert ticks is not None and alive(child.pid, ticks) and alive(child.pid)
        assert not alive(child.pid, ticks - 1)  # the same pid, started at another time: another process
        assert wait_gone({child.pid: ticks - 1}, timeout_s=0.0) == []
        assert cmdline(child.pid).endswith(f" -c {program} ")
        assert wait_gone({child.pid: ticks}, timeout_s=0.0) == [f"{child.pid} {cmdline(child.pid)[:80]}"]
    finally:
        child.communicate(timeout=60)
    assert started_ticks(child.pid) is None and not alive(child.pid, ticks)

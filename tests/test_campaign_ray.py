"""Campaigns on Ray: the same rows as local processes, retried workers, killed and concurrent drivers,
Ctrl-C, SITL nodes, and no Ray process left behind. One local Ray instance (2 CPUs) serves the module."""

import logging
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
import ray

from .tools.terminal import as_from_a_terminal
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.executors import ExecutorError, ExecutorOptions, create_executor
from preland_app.campaign.executors.ray import RayExecutor
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app
from preland_app.runtime.sitl import SITL_ENV, SitlOptions, SitlRuntime

from .conftest import ROOT
from .test_campaign import QUICK, comparable, write_campaign

# One local Ray instance for the whole session: `make test` hands each module to one xdist worker
# (--dist loadfile), so this module's tests share it (a start costs about 15 s).
pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc to find Ray's processes")

ROW = ("scenario", "trial_index", "seed", "outcome", "message")
NODE_SITL = "/bin/false"  # the SITL binary this test's Ray node advertises: one that exits at once


def _descendants(pid: int) -> set[int]:
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    found, stack = set(), [pid]
    while stack:
        for child in children.get(stack.pop(), []):
            found.add(child)
            stack.append(child)
    return found


def _alive(pid: int) -> bool:
    try:
        return "State:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _ray_processes(pid: int) -> set[int]:
    """Ray's processes under `pid`: its servers (from Ray's package) and its workers ("ray::...")."""
    return {child for child in _descendants(pid)
            if "site-packages/ray/" in _cmdline(child) or _cmdline(child).startswith("ray::")}


def _wait_gone(pids: set[int], timeout_s: float = 60.0) -> list[str]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and any(_alive(pid) for pid in pids):
        time.sleep(0.2)
    return [_cmdline(pid)[:80] for pid in pids if _alive(pid)]


@pytest.fixture(scope="session")
def cluster():
    """A local Ray instance with 2 CPUs and one `sitl` slot, whose nodes' $PRELAND_SITL_BINARY is NODE_SITL;
    stopped at the end of the session, leaving no Ray process behind."""
    previous = os.environ.get(SITL_ENV)
    os.environ[SITL_ENV] = NODE_SITL  # what Ray's processes inherit: the node's environment
    try:
        ray.init(address="local", num_cpus=2, resources={"sitl": 1}, include_dashboard=False,
                 logging_level=logging.WARNING, log_to_driver=False)
    finally:
        if previous is None:
            os.environ.pop(SITL_ENV)
        else:
            os.environ[SITL_ENV] = previous
    address = ray.get_runtime_context().gcs_address
    yield address
    started = _ray_processes(os.getpid())
    ray.shutdown()
    assert started and _wait_gone(started) == []


def _stored(db: Path) -> int:
    try:
        with sqlite3.connect(db) as connection:
            return connection.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
    except sqlite3.OperationalError:
        return 0


# The bound on a driver's waits is for one that hangs, not a speed target: a Ray driver on a loaded 2-core
# machine takes minutes to start and run a few trials.
DRIVER_HANG_S = 600.0


def _stopped_and_said(process: subprocess.Popen) -> str:
    """Stop `process` if it still runs; the end of what it wrote to stderr."""
    if process.poll() is None:
        process.terminate()
    return process.communicate(timeout=60)[1].decode(errors="replace")[-2000:]


def _wait_stored(db: Path, count: int, process: subprocess.Popen, timeout_s: float = DRIVER_HANG_S) -> int:
    """Wait until `db` holds `count` trials while `process` runs."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and process.poll() is None:
        stored = _stored(db)
        if stored >= count:
            return stored
        time.sleep(0.05)
    running = process.poll() is None
    said = _stopped_and_said(process)
    raise AssertionError(f"{count} trials were not stored ({_stored(db)} were) "
                         f"{f'within {timeout_s:g} s' if running else 'before the driver ended'}: {said}")


def _finished(db: Path, process: subprocess.Popen, timeout_s: float = DRIVER_HANG_S) -> str:
    """Wait until the driver `process` ends; its stderr. One that has not ended within the bound is stopped,
    and the failure says how many trials `db` holds."""
    try:
        return process.communicate(timeout=timeout_s)[1].decode(errors="replace")
    except subprocess.TimeoutExpired:
        said = _stopped_and_said(process)
        raise AssertionError(f"the driver did not end within {timeout_s:g} s ({_stored(db)} trials stored): "
                             f"{said}") from None


def _driver(args: list[str], **kwargs) -> subprocess.Popen:
    env = {key: value for key, value in os.environ.items() if key != "RAY_ADDRESS"}
    return subprocess.Popen([sys.executable, "-m", "preland_app.cli", "campaign", "run", *args, "--quiet"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kwargs)


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
            running = [pid for pid in _descendants(os.getpid()) if _cmdline(pid).startswith("ray::run_job")]
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
    assert len(executor.killed) == 1 and not _alive(executor.killed[0])
    assert [t["trial_index"] for t in trials] == [0, 1, 2]
    # The killed trial ran again (else it would be stored as "the worker process running this trial died").
    assert [t["outcome"] for t in trials] == ["landed"] * 3, [t["message"] for t in trials]


def test_a_sigkilled_ray_driver_resumes_to_the_rows_of_an_uninterrupted_run(cluster, tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 5"))
    db = tmp_path / "killed.db"
    first = _driver([str(path), "--db", str(db), "--executor", "ray", "--ray-address", cluster])
    assert 2 <= _wait_stored(db, 2, first) < 10
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
    first = _driver([str(path), "--db", str(db), "--executor", "ray", "--ray-address", cluster])
    _wait_stored(db, 1, first)
    second = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(db), "--resume", "--quiet",
                                      "--executor", "ray"])
    assert first.poll() is None, "the first driver should still be running"
    assert second.exit_code == 1 and "Traceback" not in second.output, second.output
    assert len(second.stderr.strip().splitlines()) == 1
    assert f"being run by another driver (pid {first.pid} on host" in second.stderr and "ray executor" in second.stderr
    stderr = _finished(db, first)
    assert first.returncode == 0, stderr
    with ResultsStore(db) as store:
        keys = [(t["scenario"], t["trial_index"]) for t in store.trials("quick")]
        assert len(keys) == 12 and len(set(keys)) == 12


def test_ctrl_c_stops_a_ray_campaign_with_130_and_a_resumed_one_ends_leaving_no_ray_process(cluster, tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 5"))
    db = tmp_path / "interrupted.db"
    args = [str(path), "--db", str(db), "--executor", "ray", "--workers", "1"]
    driver = _driver(args, start_new_session=True, preexec_fn=as_from_a_terminal)
    _wait_stored(db, 1, driver)
    started = _ray_processes(driver.pid)
    assert any("raylet" in _cmdline(pid) for pid in started), "the driver starts a local Ray instance of its own"
    os.killpg(driver.pid, signal.SIGINT)  # as Ctrl-C in a terminal: the whole foreground process group
    _, stderr = driver.communicate(timeout=60)
    assert driver.returncode == 130, stderr
    assert "interrupted:" in stderr.decode() and "Traceback" not in stderr.decode()
    assert _wait_gone(started) == []
    with ResultsStore(db) as store:
        assert 1 <= len(store.trials("quick")) < 10

    resumed = _driver([*args, "--resume"])
    _wait_stored(db, 9, resumed)
    started = _ray_processes(resumed.pid)
    stderr = _finished(db, resumed)
    assert resumed.returncode == 0, stderr
    assert started and _wait_gone(started) == []
    with ResultsStore(db) as store:
        keys = [(t["scenario"], t["trial_index"]) for t in store.trials("quick")]
        assert len(keys) == 10 and len(set(keys)) == 10


def test_sitl_trials_need_sitl_nodes_and_use_their_binary_and_a_trial_must_fit_a_node(cluster, tmp_path, monkeypatch):
    monkeypatch.delenv(SITL_ENV, raising=False)  # the driver has no SITL binary: the node has
    campaign = load_campaign(write_campaign(tmp_path, "name: on_sitl\ntrials: 1\n"
                                                      "scenarios: [{label: gps, land: normal}]\n"))
    with ResultsStore(":memory:") as store:
        assert run_campaign(campaign, store, executor="ray", runtime=SitlRuntime(options=SitlOptions(binary=None))) == (1, 1)
        (trial,) = store.trials("on_sitl")
    assert trial["source"] == "sitl" and trial["outcome"] == "error"
    assert f"{NODE_SITL} exited at once" in trial["message"]
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
    assert ray.is_initialized()  # the module's cluster: joined, and not the address asked for
    path = write_campaign(tmp_path, "name: elsewhere\ntrials: 1\nscenarios: [{label: gps, land: normal}]\n")
    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db"), "--quiet",
                                      "--executor", "ray", "--ray-address", f"127.0.0.1:{port}"])
    assert result.exit_code == 2, result.output
    assert result.stderr.strip() == (f"preland: error: --executor ray: cannot reach a Ray cluster at 127.0.0.1:{port}: "
                                     "connection refused")

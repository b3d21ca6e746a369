"""Campaign drivers: the lease (one driver per campaign and store), executors by name, outcomes-only stores."""

import concurrent.futures
import os
import socket
import sqlite3
import subprocess
import sys
import time

import pytest
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.executors import (ExecutorError, ExecutorOptions, TrialExecutor, create_executor,
                                            executor_names, register_executor)
from preland_app.campaign.executors import registry
from preland_app.campaign.lease import STALE_AFTER_S, CampaignBusy, DriverLease
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import ResultsStore
from preland_app.campaign.trials import run_job
from preland_app.cli import app

from .conftest import ROOT
from .test_campaign import (QUICK, comparable, quick_run, quick_store,  # noqa: F401 (quick_run: a fixture)
                            write_campaign)


def _lease(store, **kwargs) -> DriverLease:
    return DriverLease(store, campaign="quick", source="sim", executor="local", **kwargs)


def test_a_second_driver_is_refused_naming_the_first(tmp_path):
    with ResultsStore(tmp_path / "r.db") as first_store, ResultsStore(tmp_path / "r.db") as second_store:
        first = _lease(first_store)
        first.acquire()
        with pytest.raises(CampaignBusy) as refused:
            _lease(second_store).acquire()
        message = str(refused.value)
        assert f"pid {os.getpid()} on host {socket.gethostname()}, local executor" in message
        assert "quick" in message and "\n" not in message
        first.release()
        _lease(second_store).acquire()  # free again once released


def test_the_lease_of_a_dead_driver_is_taken_over(tmp_path):
    with ResultsStore(tmp_path / "r.db") as store:
        ended = subprocess.Popen([sys.executable, "-c", "pass"])
        ended.wait()  # gone, as a SIGKILLed driver is
        dead = _lease(store)
        dead.pid = ended.pid
        dead.acquire()
        row = store.db.execute("SELECT pid FROM campaign_drivers").fetchone()
        assert row["pid"] == dead.pid
        taker = _lease(store)
        taker.acquire()
        assert store.db.execute("SELECT pid, token FROM campaign_drivers").fetchone()[1] == taker.token
        with pytest.raises(CampaignBusy, match="taken over by another driver"):
            dead.refresh(force=True)


def test_a_lease_from_another_host_goes_stale_without_heartbeat(tmp_path):
    clock = [1_000_000.0]
    with ResultsStore(tmp_path / "r.db") as store:
        remote = _lease(store, now_s=lambda: clock[0])
        remote.host = "other-host"
        remote.acquire()
        store.db.execute("UPDATE campaign_drivers SET host = 'other-host'")
        store.db.commit()
        clock[0] += STALE_AFTER_S - 1
        with pytest.raises(CampaignBusy, match="on host other-host"):
            _lease(store, now_s=lambda: clock[0]).acquire()
        clock[0] += 2
        _lease(store, now_s=lambda: clock[0]).acquire()


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc")
def test_two_drivers_at_once_one_is_refused_in_one_line_and_every_trial_is_stored_once(tmp_path):
    path = write_campaign(tmp_path, QUICK.replace("trials: 3", "trials: 8"))
    db = tmp_path / "busy.db"
    first = subprocess.Popen([sys.executable, "-m", "preland_app.cli", "campaign", "run", str(path), "--db", str(db),
                              "--workers", "1", "--quiet"], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            with sqlite3.connect(db) as connection:
                if connection.execute("SELECT COUNT(*) FROM trials").fetchone()[0] >= 1:
                    break
        except sqlite3.OperationalError:
            pass
        time.sleep(0.05)
    second = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(db), "--resume", "--quiet",
                                      "--workers", "1"])
    assert first.poll() is None, "the first driver should still be running"
    assert second.exit_code == 1, second.output
    assert "Traceback" not in second.output and len(second.stderr.strip().splitlines()) == 1
    assert f"being run by another driver (pid {first.pid} on host" in second.stderr
    _, stderr = first.communicate(timeout=120)
    assert first.returncode == 0, stderr
    with ResultsStore(db) as store:
        keys = [(t["scenario"], t["trial_index"]) for t in store.trials("quick")]
        assert len(keys) == 16 and len(set(keys)) == 16
        assert store.db.execute("SELECT COUNT(*) FROM campaign_drivers").fetchone()[0] == 0  # released


class ThreadExecutor(TrialExecutor):
    """An executor of the test's own (threads): the driver needs nothing more than the interface."""

    name = "threads"

    def __init__(self, options: ExecutorOptions) -> None:
        self.workers = options.workers or 2
        self.futures: dict[concurrent.futures.Future, object] = {}
        self.submitted = 0

    def start(self) -> None:
        self.pool = concurrent.futures.ThreadPoolExecutor(max_workers=self.workers)

    def slots(self) -> int:
        return self.workers

    def submit(self, job) -> None:
        self.submitted += 1
        assert len(self.futures) < 2 * self.workers, "the driver keeps a window of trials in flight"
        self.futures[self.pool.submit(run_job, job)] = job

    def completed(self, timeout_s: float):
        done, _ = concurrent.futures.wait(self.futures, timeout=timeout_s,
                                          return_when=concurrent.futures.FIRST_COMPLETED)
        for future in done:
            del self.futures[future]
        return [future.result() for future in done]

    def cancel(self) -> None:
        self.pool.shutdown(wait=False, cancel_futures=True)

    def close(self) -> None:
        self.pool.shutdown(wait=True)


def test_an_executor_registered_by_name_runs_the_same_campaign(tmp_path, monkeypatch, quick_run):
    monkeypatch.setattr(registry, "_EXECUTORS", dict(registry._EXECUTORS))
    register_executor("threads", ThreadExecutor)
    assert executor_names() == ["local", "ray", "threads"]
    campaign = load_campaign(write_campaign(tmp_path, QUICK))
    with ResultsStore(":memory:") as threads:
        executor = create_executor("threads", ExecutorOptions(workers=1))
        assert run_campaign(campaign, threads, executor=executor) == (6, 6)
        assert executor.submitted == 6
        assert quick_run.ran == (6, 6)  # the local executor, one worker
        assert comparable(threads, "quick") == quick_run.trials
    with pytest.raises(ExecutorError, match=r"unknown executor 'dask' \(known: local, ray, threads\)"):
        create_executor("dask", ExecutorOptions())


def test_one_local_worker_runs_its_trials_with_opencv_on_one_thread_and_gives_the_setting_back(tmp_path,
                                                                                               monkeypatch):
    import cv2

    from preland_app.campaign.executors import local

    seen = []

    def observed(job):
        seen.append(cv2.getNumThreads())
        return run_job(job)

    monkeypatch.setattr(local, "run_job", observed)
    before = cv2.getNumThreads()
    cv2.setNumThreads(3)
    try:
        campaign = load_campaign(write_campaign(tmp_path, QUICK))
        with ResultsStore(":memory:") as store:
            assert run_campaign(campaign, store, workers=1) == (6, 6)
        assert seen == [1] * 6
        assert cv2.getNumThreads() == 3
    finally:
        cv2.setNumThreads(before)


def test_bad_executor_options_give_one_line(tmp_path):
    path = write_campaign(tmp_path, QUICK)
    runner = CliRunner()
    for args, expected in ((["--executor", "dask"], "--executor: unknown executor 'dask' (expected one of: local, ray)"),
                           (["--ray-address", "auto"], "--ray-address: needs --executor ray"),
                           (["--executor", "ray", "--trial-cpus", "0"], "--trial-cpus: must be > 0, got 0")):
        result = runner.invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db"), *args])
        assert result.exit_code == 2, result.output
        assert result.stderr.strip() == f"preland: error: {expected}"
    assert not (tmp_path / "r.db").exists()


def test_an_unreachable_ray_cluster_gives_one_line(tmp_path):
    with socket.socket() as closed:
        closed.bind(("127.0.0.1", 0))
        port = closed.getsockname()[1]  # nothing listens there once the socket is closed
    path = write_campaign(tmp_path, QUICK)
    for address in (f"127.0.0.1:{port}", f"ray://127.0.0.1:{port}"):
        result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db"), "--quiet",
                                          "--executor", "ray", "--ray-address", address])
        assert result.exit_code == 2, result.output
        assert result.stderr.strip() == (f"preland: error: --executor ray: cannot reach a Ray cluster at {address}: "
                                         "connection refused")


def test_outcomes_only_keeps_the_same_outcomes_without_events_or_trajectories(tmp_path, quick_run):
    path, full_db = quick_store(tmp_path, quick_run, "full.db")  # QUICK has run into it, in full
    campaign = load_campaign(path)
    with ResultsStore(full_db) as full, ResultsStore(tmp_path / "lean.db") as lean:
        run_campaign(campaign, lean, workers=1, outcomes_only=True)
        assert comparable(lean, "quick") == comparable(full, "quick")
        for store, events, trajectories in ((full, True, True), (lean, False, False)):
            counts = [store.db.execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0]
                      for table in ("events", "trajectories")]
            assert (counts[0] > 0, counts[1] > 0) == (events, trajectories)
    result = CliRunner().invoke(app, ["campaign", "run", str(write_campaign(tmp_path, QUICK)), "--db",
                                      str(tmp_path / "cli.db"), "--outcomes-only", "--quiet", "--workers", "1"])
    assert result.exit_code == 0, result.output
    with ResultsStore(tmp_path / "cli.db") as store:
        assert len(store.trials("quick")) == 6 and store.trajectory(store.trials("quick")[0]["id"]) is None

"""Ray drivers in processes of their own: one SIGKILLed and resumed, two at once, Ctrl-C; no Ray process left
behind. The module's local Ray instance (`ray_support.cluster`) is the one the drivers join or must not."""

import os
import signal
from pathlib import Path

import pytest
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.executors.ray import LOCAL_WORKER_NICENESS
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import ResultsStore
from preland_app.cli import app

from .ray_support import (cluster, cmdline, driver_process, finished, ray_processes,  # noqa: F401 (a fixture)
                          wait_gone, wait_stored)
from .test_campaign import QUICK, comparable, write_campaign
from .tools.terminal import as_from_a_terminal

pytestmark = pytest.mark.skipif(not Path("/proc").is_dir(), reason="needs /proc to find Ray's processes")

# The longest test first: xdist hands this worker its next file once two tests are left.


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

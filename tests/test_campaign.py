"""Campaigns: spec validation, the store, workers, kill and resume, failing trials, reports."""

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from contextlib import closing
from pathlib import Path
from typing import NamedTuple

import pytest
from typer.testing import CliRunner

from preland_app.campaign.driver import run_campaign
from preland_app.campaign.export import export_csv
from preland_app.campaign.report import summarize, write_report
from preland_app.campaign.trials import derive_seed
from preland_app.campaign.spec import load_campaign
from preland_app.campaign.store import DuplicateTrial, ResultsStore, TrialRecord
from preland_app.cli import app

from .conftest import ROOT
from .procs import alive, descendants, identified
from .waiting import until

MISSION = ROOT / "missions" / "thesis_square_land.yaml"
COMPARED = ("scenario", "trial_index", "seed", "outcome", "message", "landing_error_cm", "offset_north_cm",
            "offset_east_cm", "landing_time_s", "flight_time_s", "touchdown_speed_m_s", "details", "spec_hash")


def write_campaign(tmp_path: Path, body: str, name: str = "campaign.yaml") -> Path:
    path = tmp_path / name
    path.write_text(f"mission: {MISSION}\n" + body)
    return path


QUICK = """name: quick
trials: 3
base_seed: 7
scenarios:
  - {label: gps, land: normal, environment: {wind: {speed_m_s: 0.0}},
     reference: {avg_error_cm: 67.15, max_error_cm: 180.0, source: "thesis Table 3"}}
  - {label: irlock, land: irlock, faults: {irlock: "random:0.5"}, initial_height_m: 8}
"""


def comparable(store: ResultsStore, campaign: str) -> list[tuple]:
    return [tuple(str(t[c]) for c in COMPARED) for t in store.trials(campaign)]


class QuickRun(NamedTuple):
    db: Path
    ran: tuple[int, int]
    trials: list[tuple]


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory) -> QuickRun:
    """QUICK run once with one worker: the tests that start from its stored trials share it (each test that
    writes to a store takes a copy, quick_store) instead of flying the same six trials again."""
    folder = tmp_path_factory.mktemp("quick")
    with ResultsStore(folder / "quick.db") as store:
        ran = run_campaign(load_campaign(write_campaign(folder, QUICK)), store, workers=1)
        trials = comparable(store, "quick")
    return QuickRun(folder / "quick.db", ran, trials)


def quick_store(tmp_path: Path, run: QuickRun, name: str = "r.db") -> tuple[Path, Path]:
    """QUICK's campaign file in tmp_path and a copy of the shared store: what running it there would have left
    (the store names the campaign file it ran from, so the copy names this one)."""
    path = write_campaign(tmp_path, QUICK)
    db = tmp_path / name
    shutil.copyfile(run.db, db)  # one file: the store's WAL is folded in when it closes
    with closing(sqlite3.connect(db)) as connection, connection:
        connection.execute("UPDATE campaigns SET source_path = ?", (str(path.resolve()),))
    return path, db


def test_store_round_trip_in_memory():
    store = ResultsStore(":memory:")
    record = TrialRecord(campaign="c", scenario="s", scenario_index=0, trial_index=3, seed=11,
                         result={"outcome": "landed", "message": "ok", "landing_error_cm": 4.5,
                                 "details": {"attempts": 2}},
                         spec_hash="abc", events=({"time_s": 1.0, "kind": "armed", "message": "armed", "x": 1},),
                         trajectory_columns=("time_s", "v"), trajectory_rows=((0.0, 1.0), (0.5, 2.0)))
    trial_id = store.add_trial(record)
    (row,) = store.trials("c")
    assert row["landing_error_cm"] == 4.5 and row["details"] == {"attempts": 2} and row["source"] == "sim"
    assert store.done_keys("c") == {("s", 3)}
    assert store.events(trial_id) == [{"time_s": 1.0, "kind": "armed", "message": "armed", "data": {"x": 1}}]
    assert store.trajectory(trial_id) == (["time_s", "v"], [[0.0, 1.0], [0.5, 2.0]])
    with pytest.raises(DuplicateTrial, match="trial 3 \\(sim\\) is already in"):
        store.add_trial(record)  # a trial is never stored twice
    assert len(store.trials("c")) == 1


def test_seeds_come_from_the_trial_identity():
    assert derive_seed(7, "gps", 0) == derive_seed(7, "gps", 0)
    assert len({derive_seed(7, "gps", i) for i in range(50)}) == 50
    assert derive_seed(7, "gps", 0) != derive_seed(8, "gps", 0) != derive_seed(7, "irlock", 0)


def test_one_and_two_workers_give_identical_trials(tmp_path, quick_run):
    campaign = load_campaign(write_campaign(tmp_path, QUICK))
    assert quick_run.ran == (6, 6)  # one worker: the shared run
    with ResultsStore(tmp_path / "w2.db") as store:
        assert run_campaign(campaign, store, workers=2) == (6, 6)
        two = comparable(store, "quick")
    assert quick_run.trials == two
    assert {r[3] for r in quick_run.trials} == {"landed"}


def test_a_failing_trial_is_recorded_and_the_campaign_goes_on(tmp_path):
    pad = tmp_path / "pad.yaml"
    pad.write_text("name: p\ndictionary: DICT_4X4_50\nmarkers: [{id: 16, side_m: 0.6}]\n")
    body = f"""name: fragile
trials: 2
scenarios:
  - {{label: gps, land: normal}}
  - {{label: marker, land: marker}}
pad: {pad}
"""
    campaign = load_campaign(write_campaign(tmp_path, body))
    pad.unlink()  # the pad file disappears after the campaign was checked
    with ResultsStore(":memory:") as store:
        assert run_campaign(campaign, store, workers=1) == (4, 4)
        outcomes = {(t["scenario"], t["outcome"]) for t in store.trials("fragile")}
        assert outcomes == {("gps", "landed"), ("marker", "error")}
        message = next(t["message"] for t in store.trials("fragile") if t["outcome"] == "error")
        assert "pad.yaml" in message


def test_running_again_needs_resume_and_resume_repeats_nothing(tmp_path, quick_run):
    path, db = quick_store(tmp_path, quick_run)  # QUICK has run into it
    campaign = load_campaign(path)
    with ResultsStore(db) as store:
        with pytest.raises(Exception, match="--resume"):
            run_campaign(campaign, store, workers=1)
        assert run_campaign(campaign, store, workers=1, resume=True) == (0, 6)
        assert len(store.trials("quick")) == 6


def test_resume_refuses_a_changed_scenario(tmp_path, quick_run):
    path, db = quick_store(tmp_path, quick_run)  # QUICK has run into it
    with ResultsStore(db) as store:
        path.write_text(path.read_text().replace("speed_m_s: 0.0", "speed_m_s: 2.0"))
        with pytest.raises(Exception, match="spec changed"):
            run_campaign(load_campaign(path), store, workers=1, resume=True)


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc to find worker processes")
def test_a_killed_campaign_resumes_to_the_same_results(tmp_path):
    body = QUICK.replace("trials: 3", "trials: 6")
    path = write_campaign(tmp_path, body)
    db = tmp_path / "killed.db"
    command = [sys.executable, "-m", "preland_app.cli", "campaign", "run", str(path), "--db", str(db),
               "--workers", "2", "--quiet"]
    process = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    stored = 0
    workers: dict[int, int] = {}  # pid: the tick it started at (a pid Linux gives another since is not one)
    while time.monotonic() < deadline:
        workers = workers or identified(descendants(process.pid))  # the fork server and the workers it forked
        if db.exists():
            try:
                with sqlite3.connect(db) as connection:
                    stored = connection.execute("SELECT COUNT(*) FROM trials").fetchone()[0]
            except sqlite3.OperationalError:
                stored = 0
        if stored >= 3:
            break
        time.sleep(0.05)
    workers |= identified(descendants(process.pid))  # a worker started since is one too
    os.kill(process.pid, signal.SIGKILL)
    process.wait(timeout=10)
    assert 3 <= stored < 12, "the campaign should be killed part way"

    def orphans() -> list[int]:
        return [pid for pid, started in workers.items() if alive(pid, started)]

    # The workers notice their parent has gone and exit: bounded, not a fixed sleep.
    until(lambda: not orphans(), timeout_s=30, what="the orphaned workers to exit")

    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(db), "--resume", "--quiet",
                                      "--workers", "2"])
    assert result.exit_code == 0, result.output
    with ResultsStore(db) as resumed, ResultsStore(tmp_path / "straight.db") as straight:
        run_campaign(load_campaign(path), straight, workers=1)
        assert len(resumed.trials("quick")) == 12
        assert len({(t["scenario"], t["trial_index"]) for t in resumed.trials("quick")}) == 12
        assert comparable(resumed, "quick") == comparable(straight, "quick")


def test_a_worker_whose_campaign_died_while_it_started_exits_instead_of_waiting_for_ever():
    """A worker asks to die with the campaign process as it starts; one whose campaign was killed before it
    asked (the signal then never comes) exits by itself, and one whose campaign lives goes on: spawned by the
    campaign, or forked by a fork server the campaign started."""
    code = ("import sys\nfrom preland_app.campaign.executors.local import _worker_init\n"
            "_worker_init(int(sys.argv[1]))\nprint('went on')\n")
    alive = subprocess.run([sys.executable, "-c", code, str(os.getpid())], cwd=ROOT, capture_output=True,
                           text=True, timeout=120)
    assert (alive.returncode, alive.stdout) == (0, "went on\n"), alive.stderr
    # A grandchild, as a worker of the fork server is.
    server = ("import subprocess, sys\n"
              "result = subprocess.run([sys.executable, '-c', sys.argv[1], sys.argv[2]], capture_output=True, "
              "text=True, timeout=120)\nprint(result.returncode, result.stdout.strip())\n")
    forked = subprocess.run([sys.executable, "-c", server, code, str(os.getpid())], cwd=ROOT,
                            capture_output=True, text=True, timeout=240)
    assert (forked.returncode, forked.stdout) == (0, "0 went on\n"), forked.stderr
    # The pid the worker was started for is neither its parent's nor its grandparent's: that campaign is gone.
    orphaned = subprocess.run([sys.executable, "-c", code, str(os.getpid() + 1)], cwd=ROOT, capture_output=True,
                              text=True, timeout=120)
    assert (orphaned.returncode, orphaned.stdout) == (1, ""), orphaned.stderr


def test_a_pool_forks_its_workers_from_a_server_with_the_campaigns_environment_of_the_moment(monkeypatch):
    """The local executor's workers are forked by a fork server this process started (their grandparent),
    which has imported what a trial needs; each pool's workers see the environment the campaign process had
    when the pool started, not the one the server was started with."""
    from preland_app.campaign.executors.base import ExecutorOptions
    from preland_app.campaign.executors.local import LocalExecutor
    from preland_app.campaign.lease import parent_pid

    seen = []
    for value in ("first", "second"):
        monkeypatch.setenv("PRELAND_WORKER_PROBE", value)
        executor = LocalExecutor(ExecutorOptions(workers=2))
        executor.start()
        try:
            pool = executor._pool
            parent = pool.submit(os.getppid).result(timeout=120)
            seen.append((pool.submit(os.getenv, "PRELAND_WORKER_PROBE").result(timeout=120),
                         parent != os.getpid(), parent_pid(parent) == os.getpid(),
                         "/cv2" in Path(f"/proc/{parent}/maps").read_text()))  # the server has OpenCV loaded
        finally:
            executor.close()
    assert seen == [("first", True, True, True), ("second", True, True, True)]


def test_a_script_without_a_main_guard_stops_with_why_and_records_no_trial(tmp_path):
    """With more than one worker, each worker imports the script that runs the campaign: one without
    `if __name__ == "__main__":` runs the campaign again as each worker starts. The campaign stops saying so,
    and no trial is stored as an error (before, every trial was, as a worker that died, after tracebacks
    saying that another driver held the campaign)."""
    campaign = write_campaign(tmp_path, QUICK)
    db = tmp_path / "runs.db"
    script = tmp_path / "unguarded.py"
    script.write_text("from preland_app.api import run_campaign\n"
                      f"run_campaign({str(campaign)!r}, db={str(db)!r}, workers=2)\n"
                      "print('after the campaign')\n")
    ran = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert ran.returncode == 1 and "after the campaign" not in ran.stdout, ran.stderr[-3000:]
    last = ran.stderr.strip().splitlines()[-1]
    assert last == ("preland_app.campaign.executors.base.ExecutorError: no campaign worker could start (their "
                    f"errors are printed above): each imports {script}, which must import without errors, and "
                    'its top-level code must be under `if __name__ == "__main__":`'), ran.stderr[-3000:]
    # Each worker that got as far as the script says what it did, in one line of its own and no traceback
    # (two tracebacks printed at once interleave). At least one did: the pool broke when the first one ended.
    worker_line = (f"preland: run_campaign was called while a campaign worker imported {script}: with more than "
                   "one worker, each worker imports the script that runs the campaign, so its top-level code must "
                   'be under `if __name__ == "__main__":`')
    lines = ran.stderr.splitlines()
    assert 1 <= lines.count(worker_line) <= 2, ran.stderr
    assert "forkserver.py" not in ran.stderr and "another driver" not in ran.stderr, ran.stderr
    with ResultsStore(db) as store:
        assert store.trials("quick") == []


BAD = {
    "unknown mission": ("name: x\nmission: nowhere.yaml\nscenarios: [{label: a, land: normal}]\n", "mission",
                        "unknown mission"),
    "unknown land mode": ("name: x\nscenarios: [{label: a, land: teleport}]\n", "scenarios[0].land",
                          "unknown land mode"),
    "bad fault syntax": ("name: x\nscenarios: [{label: a, land: marker, faults: {marker: 'below:'}}]\n",
                         "scenarios[0].faults.marker", "fault"),
    "zero trials": ("name: x\ntrials: 0\nscenarios: [{label: a, land: normal}]\n", "trials", "must be > 0"),
    "duplicate labels": ("name: x\nscenarios: [{label: a, land: normal}, {label: a, land: irlock}]\n",
                         "scenarios[1].label", "duplicate label"),
    "malformed yaml": ("name: x\nscenarios: [{label: a, land: normal\n", "", "malformed YAML"),
    "unknown key": ("name: x\ntrails: 3\nscenarios: [{label: a, land: normal}]\n", "trails", "unknown key"),
    "bad environment": ("name: x\nscenarios: [{label: a, land: normal, environment: {wind: {speed: 3}}}]\n",
                        "scenarios[0].environment.wind.speed", "unknown key"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_campaign_files_give_one_clear_line(tmp_path, case):
    body, field, problem = BAD[case]
    if "mission:" in body:
        path = tmp_path / "c.yaml"
        path.write_text(body)
    else:
        path = write_campaign(tmp_path, body, "c.yaml")
    result = CliRunner().invoke(app, ["campaign", "run", str(path), "--db", str(tmp_path / "r.db"), "--quiet"])
    assert result.exit_code == 2, result.output
    message = result.stderr.strip()
    assert len(message.splitlines()) == 1 and "Traceback" not in result.output
    assert str(path) in message and field in message and problem in message


def test_report_and_export(tmp_path, quick_run):
    _, db = quick_store(tmp_path, quick_run)  # QUICK has run into it
    with ResultsStore(db) as store:
        summaries = summarize(store, "quick")
        assert [s.label for s in summaries] == ["gps", "irlock"]
        assert summaries[0].reference.avg_error_cm == 67.15 and summaries[1].reference is None
        assert summaries[1].initial_height_m == 8 and summaries[1].failures == "irlock random:0.5"
        files = write_report(store, "quick", tmp_path / "report")
        text = (tmp_path / "report" / "quick.md").read_text()
        assert "| gps | 10 | normal | none | none |" in text and "| 67.15 |" in text
        assert "| irlock | 8 | irlock | irlock | irlock random:0.5 |" in text
        pngs = [f for f in files if f.suffix == ".png"]
        assert len(pngs) == 3 and all(f.read_bytes()[:4] == b"\x89PNG" and f.stat().st_size > 10_000 for f in pngs)
        lines = export_csv(store, "quick").strip().splitlines()
        assert len(lines) == 7 and lines[0].startswith("trial_id,campaign,scenario")

    result = CliRunner().invoke(app, ["campaign", "export", str(tmp_path / "r.db"), "--format", "csv"])
    assert result.exit_code == 0 and len(result.stdout.strip().splitlines()) == 7
    result = CliRunner().invoke(app, ["campaign", "report", str(tmp_path / "r.db"), "--out", str(tmp_path / "rep2")])
    assert result.exit_code == 0 and (tmp_path / "rep2" / "quick_errors.png").exists()
    result = CliRunner().invoke(app, ["campaign", "report", str(tmp_path / "missing.db")])
    assert result.exit_code == 2 and "no such results database" in result.stderr


@pytest.mark.parametrize("name", ["thesis_table3", "thesis_table4", "thesis_table5", "thesis_field_fit", "paper_comparison", "smoke"])
def test_shipped_campaign_files_load(name):
    campaign = load_campaign(ROOT / "campaigns" / f"{name}.yaml")
    assert campaign.name == name and campaign.scenarios


def test_field_trials_sit_beside_simulated_ones_in_the_report(tmp_path, quick_run):
    path, db = quick_store(tmp_path, quick_run)  # QUICK has run into it
    campaign = load_campaign(path)
    runner = CliRunner()
    for error, x, y in ((12.5, 10.0, -7.5), (30.0, -20.0, 22.4)):
        result = runner.invoke(app, ["trial", "record", str(db), "quick", "gps",
                                     "--error-cm", str(error), "--x-cm", str(x), "--y-cm", str(y)])
        assert result.exit_code == 0, result.output
    with ResultsStore(db) as store:
        summaries = summarize(store, "quick")
        assert [s.label for s in summaries] == ["gps", "gps [field]", "irlock"]
        field = summaries[1]
        assert field.avg_error_cm() == pytest.approx(21.25) and field.land_mode == "normal"
        assert all(t["source"] == "field" and t["runtime"] == "field" for t in field.trials)
        # Resuming the simulated campaign is not confused by the field trials.
        assert run_campaign(campaign, store, workers=1, resume=True) == (0, 6)
    result = runner.invoke(app, ["campaign", "report", str(db), "--out", str(tmp_path / "rep")])
    assert result.exit_code == 0 and "| gps [field] |" in result.stdout
    result = runner.invoke(app, ["trial", "record", str(db), "quick", "gps",
                                 "--error-cm", "-1"])
    assert result.exit_code == 2 and "--error-cm" in result.stderr

"""Defects of results and field tools: each test failed before its fix."""

import dataclasses

import numpy as np
import pytest

from preland_app.clock import run_virtual
from preland_app.errors import WaitTimeout
from preland_app.landing.paper import PaperLanding
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial

from .ports import free_udp_port
from .tools.paper_fake import paper_context_over_fake


def test_a_timed_out_landing_names_the_land_timeout_and_logs_it(thesis_mission):
    mission = dataclasses.replace(thesis_mission, timeouts=dataclasses.replace(thesis_mission.timeouts, land_s=20.0))
    outcome = run_trial(TrialRequest(mission=mission, seed=3, land_mode="paper_adaptive", record_trajectory=False))
    assert outcome.outcome is Outcome.TIMED_OUT
    assert "land: not done after 20 s" in outcome.message
    (timed_out,) = [e for e in outcome.events if e.kind == "timed_out"]
    handover = next(e for e in outcome.events if e.kind == "land_handover")
    assert timed_out.time_s - handover.time_s == pytest.approx(20.0, abs=0.11)
    assert timed_out.data == {"operation": "land", "timeout_s": 20.0}
    assert outcome.events[-1] is timed_out  # nothing logged after it


def test_the_paper_landing_reports_its_whole_timeout_not_the_remainder():
    """Run on its own (no mission watchdog), the land mode's own deadline must name the land timeout."""

    async def main():
        vehicle, context = await paper_context_over_fake(pad_at_ned_m=(0.5, 0.0), timeout_s=4.0)
        with pytest.raises(WaitTimeout) as raised:
            await PaperLanding(adaptive=True).land(context)
        return raised.value

    error = run_virtual(main())
    assert error.timeout_s == 4.0 and "not done after 4 s" in str(error)


def _quick_store(tmp_path):
    from preland_app.campaign.driver import run_campaign
    from preland_app.campaign.spec import load_campaign
    from preland_app.campaign.store import ResultsStore

    from .conftest import THESIS_MISSION

    path = tmp_path / "quick.yaml"
    path.write_text(f"mission: {THESIS_MISSION}\nname: quick\ntrials: 2\nbase_seed: 5\nscenarios:\n"
                    "  - {label: gps, land: normal}\n")
    db = tmp_path / "r.db"
    with ResultsStore(db) as store:
        run_campaign(load_campaign(path), store, workers=1)
    return db


def test_the_report_works_after_a_field_trial_without_offsets(tmp_path):
    from typer.testing import CliRunner

    from preland_app.cli import app

    db = _quick_store(tmp_path)
    runner = CliRunner()
    result = runner.invoke(app, ["trial", "record", str(db), "quick", "gps", "--error-cm", "42"])
    assert result.exit_code == 0, result.output
    result = runner.invoke(app, ["campaign", "report", str(db), "--out", str(tmp_path / "rep")])
    assert result.exit_code == 0, result.output
    assert "| gps [field] |" in result.stdout and (tmp_path / "rep" / "quick_positions.png").exists()


def test_export_of_an_unknown_campaign_is_refused_as_report_refuses_it(tmp_path):
    from typer.testing import CliRunner

    from preland_app.cli import app

    db = _quick_store(tmp_path)
    result = CliRunner().invoke(app, ["campaign", "export", str(db), "--campaign", "nope"])
    assert result.exit_code == 2 and result.stdout == ""
    assert "nope" in result.stderr and "quick" in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_detect_refuses_an_output_it_cannot_write_as_video(tmp_path):
    import cv2
    from typer.testing import CliRunner

    from preland_app.cli import app
    from preland_app.sensing.capture import VideoRecorder

    video = tmp_path / "in.mkv"
    recorder = VideoRecorder(path=video, frame_rate_hz=30.0, size=(64, 48))
    for _ in range(3):
        recorder.write(np.zeros((48, 64), np.uint8))
    recorder.close()
    out = tmp_path / "ann.png"
    result = CliRunner().invoke(app, ["detect", "--video", str(video), "--out", str(out)])
    assert result.exit_code == 2 and "--out" in result.stderr and ".mkv" in result.stderr
    assert "wrote" not in result.stdout and not out.exists()
    out = tmp_path / "ann.avi"
    result = CliRunner().invoke(app, ["detect", "--video", str(video), "--out", str(out)])
    assert result.exit_code == 0, result.output
    capture = cv2.VideoCapture(str(out))
    assert capture.read()[0]
    capture.release()


def test_fault_send_to_a_port_nobody_listens_on_fails():
    from typer.testing import CliRunner

    from preland_app.cli import app

    port = free_udp_port()  # a free port, closed again
    result = CliRunner().invoke(app, ["fault", "send", "--connect", f"udp://127.0.0.1:{port}", "--target", "marker",
                                      "--r-drop", "1.0", "--ack-timeout-s", "0.3"])
    assert result.exit_code == 1 and "sent" not in result.stdout
    assert f"127.0.0.1:{port}" in result.stderr and "--fault-listen" in result.stderr


def test_fault_send_is_acknowledged_by_a_listener():
    import asyncio

    from typer.testing import CliRunner

    from preland_app.cli import app
    from preland_app.mavlink.fault_message import listen

    port = free_udp_port()
    received = []

    async def main():
        transport = await listen(f"udp://127.0.0.1:{port}", lambda command: received.append(command) or True)
        try:
            return await asyncio.to_thread(CliRunner().invoke, app, [
                "fault", "send", "--connect", f"udp://127.0.0.1:{port}", "--target", "irlock", "--r-drop", "0.5"])
        finally:
            transport.close()

    result = asyncio.run(main())
    assert result.exit_code == 0, result.output
    assert "the companion applied it" in result.stdout and received[0].r_drop == 0.5


def test_help_texts_name_values_as_click_does_without_python_types():
    import typer
    from typer.testing import CliRunner

    from preland_app.cli import app

    runner = CliRunner()
    root = typer.main.get_command(app)

    def commands(group, path):
        for name, command in group.commands.items():
            if hasattr(command, "commands"):  # a group (typer's own click)
                yield from commands(command, [*path, name])
            else:
                yield [*path, name]

    checked = 0
    for path in commands(root, []):
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "200"})
        assert result.exit_code == 0, path
        for leak in ("<bool>", "<list[", "<path>", "<int>", "<float>", "<str>"):
            assert leak not in result.stdout, (path, leak)
        checked += 1
    assert checked >= 18
    help_text = runner.invoke(app, ["campaign", "run", "--help"], env={"COLUMNS": "200"}).stdout
    assert "--sitl-defaults        PATH" in help_text


def test_a_refused_campaign_run_shows_no_progress_bar(tmp_path):
    from typer.testing import CliRunner

    from preland_app.cli import app

    db = _quick_store(tmp_path)  # the campaign already has its trials
    result = CliRunner().invoke(app, ["campaign", "run", str(tmp_path / "quick.yaml"), "--db", str(db),
                                      "--workers", "1"])
    assert result.exit_code == 2
    assert result.stderr.strip().splitlines() == [line for line in result.stderr.strip().splitlines()
                                                  if line.startswith("preland: error:")]
    assert "trials" not in result.stderr.replace("trial(s)", "") and "ETA" not in result.stderr

"""The SITL runtime's failures, on the stand-in `arducopter` (tests/tools/fake_sitl.py), with either
physics: an interrupted campaign, a SITL killed or stopped mid-trial; no process or bridge is left."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest
from preland_app.runtime.sitl import SitlOptions, run_sitl_trial

from .conftest import ROOT, THESIS_MISSION
from .test_sitl import (_answers, _bridge_threads, _launches, _run_in_thread, _running, _wait_airborne,
                        _wait_dead, _wait_for_launch, fake_sitl)
from .tools.terminal import as_from_a_terminal
from .waiting import until

__all__ = ["fake_sitl"]  # the fixture, shared with test_sitl.py


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
def test_an_interrupted_sitl_campaign_leaves_no_sitl_process(fake_sitl, tmp_path):
    script, logs = fake_sitl
    campaign = tmp_path / "c.yaml"
    campaign.write_text(f"name: sitl_orphans\nmission: {THESIS_MISSION}\ntrials: 4\n"
                        "scenarios: [{label: gps, land: normal}]\n")
    process = subprocess.Popen(
        [sys.executable, "-m", "preland_app.cli", "campaign", "run", str(campaign), "--db", str(tmp_path / "r.db"),
         "--workers", "2", "--quiet", "--sitl", str(script), "--sitl-speedup", "2"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env={**os.environ},
        preexec_fn=as_from_a_terminal)
    until(lambda: len(_launches(logs)) >= 2 or process.poll() is not None, timeout_s=60,
          what="two SITL processes to be running")
    assert len(_launches(logs)) >= 2, "two SITL processes should be running"
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 130, stderr
    for launch in _launches(logs):
        _wait_dead(launch)


def _signalled_in_flight(script, logs, mission, *, physics: str, signal_number: int) -> tuple:
    """One trial on the stand-in, sent `signal_number` once its vehicle is airborne: (outcome, the launch,
    wall seconds from the signal to the trial's end)."""
    pool, future = _run_in_thread(lambda: run_sitl_trial(TrialRequest(mission=mission, seed=2),
                                                         options=SitlOptions(binary=script, speedup=3.0,
                                                                             physics=physics)))
    launch = _wait_for_launch(logs)
    _wait_airborne(logs, launch)  # stopped in flight
    os.kill(launch["pid"], signal_number)
    signalled_at = time.monotonic()
    outcome = future.result(timeout=60)
    elapsed_s = time.monotonic() - signalled_at
    pool.shutdown()
    return outcome, launch, elapsed_s


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
@pytest.mark.parametrize("physics", ["ardupilot", "preland"])
def test_sitl_killed_mid_trial_ends_the_trial_as_error_naming_the_exit(fake_sitl, thesis_mission, physics):
    script, logs = fake_sitl
    outcome, launch, _ = _signalled_in_flight(script, logs, thesis_mission, physics=physics,
                                              signal_number=signal.SIGKILL)
    assert outcome.outcome is Outcome.ERROR
    assert "killed by SIGKILL" in outcome.message and "SitlExited" in outcome.message
    assert any(e.kind == "armed" for e in outcome.events)  # what it recorded before is kept
    assert not _running(launch)
    assert _bridge_threads() == []  # the bridge stopped with its trial
    if physics == "preland":
        assert _answers(logs, launch) > 0


@pytest.mark.skipif(not Path("/proc").exists(), reason="needs /proc")
@pytest.mark.parametrize("physics", ["ardupilot", "preland"])
def test_sitl_that_stops_answering_ends_as_link_lost_in_bounded_time(fake_sitl, thesis_mission, physics):
    """A stopped SITL sends no servo packets either: the bridge, still waiting for one, does not hold the
    trial, which the lost link ends; the bridge then stops with it."""
    script, logs = fake_sitl
    outcome, launch, elapsed_s = _signalled_in_flight(script, logs, thesis_mission, physics=physics,
                                                      signal_number=signal.SIGSTOP)
    assert outcome.outcome is Outcome.LINK_LOST, outcome.message
    assert elapsed_s < 20.0
    _wait_dead(launch)
    assert _bridge_threads() == []


def test_a_sitl_that_exits_during_a_trial_is_told_with_its_last_line_on_stderr(tmp_path):
    """Its exit code alone says little: the last line SITL wrote to stderr goes with it."""
    import asyncio

    from preland_app.runtime.sitl import SitlInstance

    flag = tmp_path / "exit-now"
    binary = tmp_path / "arducopter"
    # Answers --help at once (as arducopter does); launched, it runs until the test says, then fails.
    binary.write_text(f"#!/bin/sh\n[ \"$1\" = --help ] && exit 0\necho starting >&2\n"
                      f"while [ ! -e {flag} ]; do sleep 0.05; done\necho 'bind failed: Address in use' >&2\nexit 3\n")
    binary.chmod(0o755)

    async def main() -> str | None:
        async with SitlInstance(options=SitlOptions(binary=binary, speedup=1.0), params={}) as sitl:
            assert sitl.exit_description() is None
            flag.touch()
            await asyncio.get_running_loop().run_in_executor(
                None, lambda: until(lambda: sitl.exit_description() is not None, timeout_s=30,
                                    what="the stand-in SITL to exit"))
            return sitl.exit_description()

    assert asyncio.run(main()) == "exited with code 3 (its last line on stderr: bind failed: Address in use)"


def _python_stand_in(folder: Path, body: str) -> Path:
    """An executable `arducopter` in `folder`: answers --help as a 4.5+ SITL, else runs `body` with `host` and
    `port` (its --serial0 udpclient address) and `socket`, `sys` imported."""
    binary = folder / "arducopter"
    binary.write_text(f"""#!{sys.executable}
import socket, sys
if "--help" in sys.argv:
    print("--serial0")
    sys.exit(0)
host, port = sys.argv[sys.argv.index("--serial0") + 1].split(":")[1:]
{body}""")
    binary.chmod(0o755)
    return binary


def test_a_sitl_keeps_its_companions_port_from_other_trials_before_the_companion_binds_and_while_stopping(
        tmp_path, monkeypatch):
    """SITL sends to the companion's port from its start, before the companion binds it, and until it has
    exited, after the companion let the port go: the port stays held meanwhile, so no other trial is handed it
    and reads this vehicle's messages as its own."""
    import asyncio
    import errno
    import socket

    from preland_app.runtime import sitl as sitl_runtime
    from preland_app.runtime.sitl import SitlInstance

    told_to_stop = tmp_path / "told-to-stop"
    # Sends to its --serial0 udpclient address once, then stays until a datagram tells it to exit, after its
    # SIGTERM too (as a SITL goes on running, and sending, while it stops).
    binary = _python_stand_in(tmp_path, f"""import pathlib, signal
signal.signal(signal.SIGTERM, lambda *_: pathlib.Path({str(told_to_stop)!r}).touch())
out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
out.settimeout(60)
out.sendto(b"vehicle", (host, int(port)))
out.recv(16)
""")
    monkeypatch.setattr(sitl_runtime, "STOP_GRACE_S", 60.0)  # the stand-in exits when the check is done

    def bind_while_stopping(port: int, stand_in: tuple[str, int]) -> str:
        try:
            until(told_to_stop.exists, timeout_s=60, what="the stand-in SITL's SIGTERM")
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
                other.bind(("127.0.0.1", port))
            return "bound"
        except OSError as error:
            return errno.errorcode[error.errno]
        finally:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as teller:
                teller.sendto(b"exit", stand_in)

    async def main() -> tuple[int, str, str | None]:
        sitl = SitlInstance(options=SitlOptions(binary=binary, speedup=1.0), params={})
        # Chosen, the port is held until the companion binds it: no other program can be handed it first.
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
            with pytest.raises(OSError) as before_companion:
                other.bind(("127.0.0.1", sitl.port))
        assert before_companion.value.errno == errno.EADDRINUSE
        # The companion listens before SITL starts here, so its port takes SITL's first datagram.
        sitl.hand_port_to_companion()
        companion = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        companion.bind(("127.0.0.1", sitl.port))
        companion.settimeout(60)
        async with sitl:
            try:
                datagram, stand_in = companion.recvfrom(64)
            finally:
                companion.close()
            assert datagram == b"vehicle"
            # The companion has closed: another trial binding the port now would read this SITL.
            other = asyncio.get_running_loop().run_in_executor(None, bind_while_stopping, sitl.port, stand_in)
        return sitl.port, await other, sitl.exit_description()

    port, while_stopping, ended = asyncio.run(main())
    assert while_stopping == "EADDRINUSE"
    assert ended is not None  # stopped before the port was let go
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as after:
        after.bind(("127.0.0.1", port))


def test_a_sitl_that_exits_before_its_vehicle_answers_is_told_the_same_however_soon_it_exits(tmp_path, thesis_mission):
    """How soon a SITL that cannot start exits depends on the machine's load; the start check (0.2 s) or the
    watch during the connection finds it, and either says the same: the binary, how it ended, before its
    vehicle answered. This one exits once the companion's MAVLink answers it, so after the start check: it
    says it is a ground station (not an autopilot) until MAVSDK's heartbeat comes back."""
    binary = _python_stand_in(tmp_path, """from pymavlink.dialects.v20 import ardupilotmega as mavlink2
mav = mavlink2.MAVLink(None, srcSystem=200, srcComponent=1)
heartbeat = mav.heartbeat_encode(mavlink2.MAV_TYPE_GCS, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, 0).pack(mav)
out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
out.settimeout(0.2)
for _ in range(300):  # 60 s at most
    out.sendto(heartbeat, (host, int(port)))
    try:
        out.recv(2048)
        break
    except socket.timeout:
        pass
sys.stderr.write("no vehicle here\\n")
sys.exit(3)
""")
    from preland_app.runtime.sitl import SitlError

    with pytest.raises(SitlError) as raised:
        run_sitl_trial(TrialRequest(mission=thesis_mission, seed=1, land_mode="normal"),
                       options=SitlOptions(binary=binary, speedup=1.0))
    assert str(raised.value) == (f"{binary} exited with code 3 (its last line on stderr: no vehicle here) "
                                 "before its vehicle answered")

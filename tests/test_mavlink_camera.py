"""Camera land modes over MAVLink (MAVSDK), in lock-step with the simulator's MAVLink face on localhost."""

import asyncio

import pytest

from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest
from preland_app.runtime.mavlink import fly_mavlink

from .ports import free_udp_port as free_port
from .test_mavlink_runtime import PATIENCE_S, ServedSimulator, fly_paced
from .waiting import until_async


@pytest.mark.parametrize("mode, faults", [
    ("marker", None), ("fused", None), ("cautious", {"marker": "below:3:first-attempt"}),
])
def test_camera_land_modes_over_mavlink(short_mission, mode, faults):
    # In lock-step: the camera renders and detects in wall time while the vehicle waits for each frame. The
    # thesis mission made short (from 5 m): the camera's work is the landing's.
    outcome, served = fly_paced(short_mission, seed=4, land_mode=mode, faults=faults)
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.landing_error_cm < 15.0, told(outcome)
    assert served.face.landing_targets == outcome.details["landing_targets_sent"] > 100
    # Every frame at its vehicle time: the camera's 15 frames a second of the landing, none waited for truth.
    assert outcome.details["ticks_without_new_truth"] <= 1
    assert outcome.details["marker_frames"] >= 0.9 * 15 * outcome.landing_time_s
    if mode == "cautious":
        assert outcome.details["attempts"] == 2 and outcome.details["marker_dropped"] > 0


def told(outcome) -> str:
    """A trial's events and details in full, one event a line (a repr of them would be cut short)."""
    return "\n".join([f"landed {outcome.landing_error_cm:.1f} cm off; details {outcome.details}",
                      *(f"{event.time_s:8.2f} {event.kind}: {event.message} {event.data}"
                        for event in outcome.events)])


def test_the_same_seed_flies_the_same_trial_in_lock_step(short_mission):
    # Two paced flights of one seed, each against a fresh paced face: the same landing to the bit, whatever
    # the machine did meanwhile (the camera's wall time no longer decides what the autopilot is told).
    first, _ = fly_paced(short_mission, seed=11, land_mode="marker")
    second, _ = fly_paced(short_mission, seed=11, land_mode="marker")
    assert first.outcome is second.outcome is Outcome.LANDED, (first.message, second.message)
    assert first.landing_error_cm == second.landing_error_cm and first.landing_time_s == second.landing_time_s
    assert first.details["landing_targets_sent"] == second.details["landing_targets_sent"]
    assert [(e.kind, e.time_s) for e in first.events] == [(e.kind, e.time_s) for e in second.events]


@pytest.mark.parametrize("mode", ["paper_adaptive", "paper_static"])
def test_paper_algorithms_over_mavlink(mode):
    from preland_app.config.mission import load_mission

    from .conftest import SHORT_PAPER_MISSION

    # The paper's mission made short (from 8 m): both of its nested markers still steer the landing.
    mission = load_mission(SHORT_PAPER_MISSION)
    outcome, _ = fly_paced(mission, seed=2, land_mode=mode)
    assert outcome.outcome is Outcome.LANDED, outcome.message
    assert outcome.landing_error_cm < 20.0 and not outcome.details["aborted_to_gps"], told(outcome)
    # Both markers steered, the 18 cm one (id 1) last; Algorithm 2 chose the 56 cm one (id 0) first and switched
    # once, never back, where Algorithm 1 takes whichever is the highest id in view.
    chosen = [event.data["to_id"] for event in outcome.events if event.kind == "marker_switch"]
    assert set(chosen) == {0, 1} and chosen[-1] == 1, chosen
    if mode == "paper_adaptive":
        assert chosen == [0, 1], chosen
    else:
        assert len(chosen) > 2, chosen


def test_fault_commands_reach_the_flying_companion(short_mission):
    """PRELAND_FAULT_INJECTION sent with `preland fault send` changes the marker's faults mid-landing."""
    from typer.testing import CliRunner

    from preland_app.cli import app

    served = ServedSimulator(short_mission, seed=6, paced=True)
    fault_port = free_port()

    async def main():
        trial = asyncio.ensure_future(fly_mavlink(TrialRequest(mission=short_mission, seed=6, land_mode="marker"),
                                                  url=served.url, fault_listen=f"udp://127.0.0.1:{fault_port}",
                                                  paced=True))
        # Once the autopilot has the target (a few readings in): the command then lands mid-descent.
        await until_async(lambda: served.face.landing_targets >= 5 or trial.done(), timeout_s=PATIENCE_S,
                          what="the first landing targets")
        # In a thread: the sender waits for the acknowledgement that this loop's listener sends.
        result = await asyncio.to_thread(CliRunner().invoke, app, ["fault", "send", "--connect",
                                                                   f"udp://127.0.0.1:{fault_port}", "--target",
                                                                   "marker", "--r-drop", "1.0"])
        assert result.exit_code == 0, result.output
        assert "the companion applied it" in result.stdout
        targets_when_applied = served.face.landing_targets
        return await asyncio.wait_for(trial, timeout=120), targets_when_applied

    try:
        outcome, targets_when_applied = asyncio.run(main())
    finally:
        served.stop()
    assert outcome.outcome is Outcome.LANDED
    event = next(e for e in outcome.events if e.kind == "fault_command")
    assert event.data["target"] == 2 and event.data["r_drop"] == 1.0
    # From the acknowledgement on, every marker reading is dropped: none reaches the autopilot (one may have
    # been on the wire). How many there were depends on how far the descent had gone when the command
    # arrived, which the command's wall-time round trip decides.
    assert outcome.details["marker_fault"] == "permanent" and outcome.details["marker_dropped"] > 0
    assert targets_when_applied > 0 and served.face.landing_targets - targets_when_applied <= 1

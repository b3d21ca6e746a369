"""The paper's Algorithms 1 and 2: decisions frame by frame, the abort, and a landing that sees no truth."""

import ast
import math
from pathlib import Path

import numpy as np
import pytest

from preland_app.clock import run_virtual
from preland_app.config.mission import load_mission
from preland_app.landing.paper import Action, PaperLanding, PaperPolicy, PaperSpec
from preland_app.outcome import Outcome
from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.sensing.marker import MarkerDetection

from .conftest import ROOT
from .tools.paper_fake import paper_context_over_fake

PAPER_MISSION = ROOT / "missions" / "paper_marker_land.yaml"


def seen(marker_id, *, x=0.0, y=0.0, z=10.0, side=0.56):
    """A detection of `marker_id` at camera-frame position (x, y, z) in m."""
    tvec = np.array([x, y, z])
    return MarkerDetection(marker_id=marker_id, side_m=side, corners_px=np.zeros((4, 2)), rvec=np.zeros(3),
                           tvec=tvec, pad_center_cam_m=tvec)


def test_adaptive_switches_to_a_marker_only_below_half_its_first_sighting_altitude():
    policy = PaperPolicy(adaptive=True)
    policy.step([seen(0, z=20)], altitude_m=20.0, time_s=0.0)
    assert policy.selected_id == 0
    policy.step([seen(0, z=12), seen(1, z=12, side=0.18)], altitude_m=12.0, time_s=10.0)
    assert policy.activation_m == {0: 20.0, 1: 12.0}
    policy.step([seen(0, z=12), seen(1, z=12, side=0.18)], altitude_m=12.0, time_s=10.1)
    assert policy.activation_m == {0: 20.0, 1: 12.0}
    assert policy.selected_id == 0  # 12 m is not below half of 12 m
    policy.step([seen(0, z=6.5), seen(1, z=6.5)], altitude_m=6.5, time_s=20.0)
    assert policy.selected_id == 0  # 6.5 m: still not below 6 m
    command = policy.step([seen(0, z=5.9), seen(1, z=5.9)], altitude_m=5.9, time_s=21.0)
    assert policy.selected_id == 1 and command.marker_id == 1
    assert policy.switches[-1] == (21.0, 0, 1, 5.9)
    # The small marker missing from a frame does not switch back to the big one.
    command = policy.step([seen(0, z=5.5)], altitude_m=5.5, time_s=21.1)
    assert policy.selected_id == 1 and command.action is Action.HOLD
    assert len(policy.switches) == 2


def test_static_takes_the_highest_id_every_frame_and_glitches():
    policy = PaperPolicy(adaptive=False)
    policy.step([seen(0), seen(1)], altitude_m=12.0, time_s=0.0)
    policy.step([seen(0)], altitude_m=12.0, time_s=0.1)
    policy.step([seen(0), seen(1)], altitude_m=12.0, time_s=0.2)
    assert [s[2] for s in policy.switches] == [1, 0, 1]


@pytest.mark.parametrize("z, expected_alpha", [(15.0, 20.0), (10.0, 10.0)])
def test_virtual_border_decision_at_both_altitudes(z, expected_alpha):
    policy = PaperPolicy(adaptive=True)
    inside = math.tan(math.radians(expected_alpha - 1.0)) * z
    outside = math.tan(math.radians(expected_alpha + 1.0)) * z
    command = policy.step([seen(0, x=inside, y=-inside, z=z)], altitude_m=z, time_s=0.0)
    assert command.action is Action.DESCEND and command.alpha_deg == expected_alpha
    assert command.down_m_s > 0
    command = policy.step([seen(0, x=outside, y=0.0, z=z)], altitude_m=z, time_s=0.1)
    assert command.action is Action.MOVE and command.right_m_s > 0 and command.forward_m_s == 0
    command = policy.step([seen(0, x=0.0, y=outside, z=z)], altitude_m=z, time_s=0.2)
    assert command.action is Action.MOVE and command.forward_m_s < 0  # marker behind: move back


def test_beta_exactly_15_degrees_descends_above_z2_and_moves_below():
    above, below = PaperPolicy(adaptive=True), PaperPolicy(adaptive=True)
    assert above.step([seen(0, x=math.tan(math.radians(15)) * 14, z=14)], altitude_m=14, time_s=0).action \
        is Action.DESCEND
    assert below.step([seen(0, x=math.tan(math.radians(15)) * 12, z=12)], altitude_m=12, time_s=0).action \
        is Action.MOVE


def test_speeds_follow_the_paper_percentages():
    spec = PaperSpec()
    adaptive, static = PaperPolicy(adaptive=True), PaperPolicy(adaptive=False)
    assert adaptive.descent_speed_m_s(20.0) == pytest.approx(0.40 * spec.vertical_full_scale_m_s)  # 20 x 2 %
    assert adaptive.descent_speed_m_s(40.0) == pytest.approx(0.60 * spec.vertical_full_scale_m_s)  # capped
    assert adaptive.descent_speed_m_s(5.0) == pytest.approx(0.10 * spec.vertical_full_scale_m_s)  # v3
    assert static.descent_speed_m_s(20.0) == pytest.approx(0.10 * spec.vertical_full_scale_m_s)
    assert adaptive.horizontal_speed_m_s(1.5) == pytest.approx(0.15 * spec.horizontal_full_scale_m_s)  # v1
    assert adaptive.horizontal_speed_m_s(0.5) == pytest.approx(0.05 * spec.horizontal_full_scale_m_s)  # v2


def test_recovery_climbs_one_metre_after_the_marker_is_lost():
    policy = PaperPolicy(adaptive=True)
    policy.step([seen(0, z=8)], altitude_m=8.0, time_s=0.0)
    assert policy.step([], altitude_m=8.0, time_s=0.5).action is Action.HOLD  # within the grace period
    command = policy.step([], altitude_m=8.0, time_s=1.2)
    assert command.action is Action.RECOVER and command.down_m_s < 0
    assert policy.step([], altitude_m=8.6, time_s=2.0).action is Action.RECOVER
    assert policy.step([], altitude_m=9.01, time_s=3.0).action is Action.HOLD  # 1 m higher: wait there
    assert policy.recovery_climbs == 1
    policy.step([seen(0, z=9)], altitude_m=9.0, time_s=3.1)
    policy.step([], altitude_m=8.0, time_s=3.2)
    policy.step([], altitude_m=8.0, time_s=4.5)
    assert policy.recovery_climbs == 2


def test_marker_hidden_aborts_to_a_gps_landing_after_30_vehicle_seconds():
    mission = load_mission(PAPER_MISSION)
    outcome = run_trial(TrialRequest(mission=mission, seed=4, land_mode="paper_adaptive",
                                     faults={"marker": "permanent"}, record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED and outcome.details["aborted_to_gps"] is True
    events = {e.kind: e for e in outcome.events}
    assert events["aborted_to_gps"].time_s - events["land_command"].time_s == pytest.approx(30.0, abs=0.2)
    assert outcome.details["recovery_climbs"] == 1
    assert outcome.details["marker_dropped"] == outcome.details["marker_produced"] > 0


def test_paper_adaptive_lands_on_the_marker(thesis_mission):
    outcome = run_trial(TrialRequest(mission=load_mission(PAPER_MISSION), seed=2, land_mode="paper_adaptive",
                                     record_trajectory=False))
    assert outcome.outcome is Outcome.LANDED and not outcome.details["aborted_to_gps"]
    assert outcome.landing_error_cm < 20.0
    assert outcome.details["marker_switches"] == 2  # none -> 0 -> 1
    assert outcome.details["first_detection_altitude_m"] > 15.0


def test_normal_on_the_paper_mission_is_scored_from_the_marker():
    outcome = run_trial(TrialRequest(mission=load_mission(PAPER_MISSION), seed=2, land_mode="normal",
                                     record_trajectory=False))
    assert outcome.scoring_reference == "pad" and outcome.landing_error_cm > 20.0


def test_the_strategy_lands_a_vehicle_that_exposes_no_truth():
    """A fake vehicle and a camera rendering from the fake's own state: nothing but the Vehicle protocol and frames."""
    pad_at = (3.0, 1.0)

    async def main():
        vehicle, context = await paper_context_over_fake(pad_at_ned_m=pad_at, timeout_s=300.0)
        report = await PaperLanding(adaptive=True).land(context)
        return vehicle, report

    vehicle, report = run_virtual(main())
    assert not vehicle.armed and vehicle.down_m == 0.0
    assert math.hypot(vehicle.north_m - pad_at[0], vehicle.east_m - pad_at[1]) < 0.3
    assert report.details["aborted_to_gps"] is False
    assert "set_velocity_body" in vehicle.operations()


def test_landing_strategies_import_nothing_from_the_simulator_or_the_runtime():
    landing = ROOT / "preland_app" / "landing"
    for path in sorted(Path(landing).glob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                module = node.module or ""
                assert not module.startswith(("sim", "runtime")) and ".sim" not in f".{module}" \
                    and "runtime" not in module, f"{path.name} imports {module}"

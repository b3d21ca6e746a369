from __future__ import annotations

from pathlib import Path

import pytest

from preland_app.config.mission import MissionSpec, load_mission
from preland_app.runtime.embedded import TrialRequest, run_trial

ROOT = Path(__file__).resolve().parents[1]
THESIS_MISSION = ROOT / "missions" / "thesis_square_land.yaml"


@pytest.fixture(scope="session")
def thesis_mission() -> MissionSpec:
    return load_mission(THESIS_MISSION)


@pytest.fixture(scope="session")
def square_trial(thesis_mission):
    """One normal-mode trial of the thesis mission, with its trajectory."""
    return run_trial(TrialRequest(mission=thesis_mission, seed=7))

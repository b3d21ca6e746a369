from __future__ import annotations

import os
from pathlib import Path

# The suite runs 4 xdist workers on 2 cores: OpenCV's own thread pool in each (and in the processes the tests
# start) would only add waiting threads on top, as in a campaign's workers, which run OpenCV on one thread.
os.environ.setdefault("OPENCV_FOR_THREADS_NUM", "1")

import cv2  # noqa: E402
import pytest  # noqa: E402

cv2.setNumThreads(1)

from preland_app.config.mission import MissionSpec, load_mission  # noqa: E402
from preland_app.runtime.embedded import TrialRequest, run_trial  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
THESIS_MISSION = ROOT / "missions" / "thesis_square_land.yaml"


@pytest.fixture(scope="session")
def thesis_mission() -> MissionSpec:
    return load_mission(THESIS_MISSION)


@pytest.fixture(scope="session")
def square_trial(thesis_mission):
    """One normal-mode trial of the thesis mission, with its trajectory."""
    return run_trial(TrialRequest(mission=thesis_mission, seed=7))

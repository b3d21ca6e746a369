from __future__ import annotations

from pathlib import Path

import pytest

from preland_app.config.mission import MissionSpec, load_mission
from preland_app.runtime.embedded import TrialRequest, run_trial

ROOT = Path(__file__).resolve().parents[1]
THESIS_MISSION = ROOT / "missions" / "thesis_square_land.yaml"


def pytest_configure(config):
    """Refuse `--dist loadgroup` where pytest-xdist cannot group: pytest 9.2 no longer lets it suffix node
    ids with `@group` (pytest-xdist#1386, open in 3.8.0), and the groups are then silently ignored: every
    worker starts its own Ray instance and the real-time camera tests run side by side.
    pyproject.toml keeps pytest below 9.2 until pytest-xdist groups again."""
    if hasattr(config, "workerinput") or config.getoption("dist", default="no") != "loadgroup":
        return
    from importlib.metadata import version

    xdist = tuple(int(part) for part in version("pytest-xdist").split(".")[:3] if part.isdigit())
    if pytest.version_tuple[:2] >= (9, 2) and xdist <= (3, 8, 0):
        raise pytest.UsageError(f"pytest {pytest.__version__} with pytest-xdist {version('pytest-xdist')} ignores "
                                "xdist_group under --dist loadgroup (pytest-xdist#1386): install pytest<9.2, "
                                "as pyproject.toml asks")


@pytest.fixture(scope="session")
def thesis_mission() -> MissionSpec:
    return load_mission(THESIS_MISSION)


@pytest.fixture(scope="session")
def square_trial(thesis_mission):
    """One normal-mode trial of the thesis mission, with its trajectory."""
    return run_trial(TrialRequest(mission=thesis_mission, seed=7))

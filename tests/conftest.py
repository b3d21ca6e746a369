from __future__ import annotations

import os
from pathlib import Path

# The suite runs its test processes side by side on every core (xdist), and each starts simulators, faces
# and campaigns of its own: one thread each for OpenCV and the BLAS libraries, as campaign workers already
# have (campaign/executors/local.py), so that pools of threads do not compete with the processes. Set before
# cv2 or numpy is imported, here and in every process a test starts (they inherit the environment).
for _name in ("OPENCV_FOR_THREADS_NUM", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ.setdefault(_name, "1")

import functools

import pytest
import typer.testing

from preland_app.config.mission import MissionSpec, load_mission
from preland_app.runtime.embedded import TrialRequest, run_trial

ROOT = Path(__file__).resolve().parents[1]
THESIS_MISSION = ROOT / "missions" / "thesis_square_land.yaml"
# The thesis mission made short (5 m, 1 m legs): for tests of what surrounds a flight over MAVLink (field
# campaigns, fault kinds and commands, camera land modes), where the thesis' own altitude only adds vehicle seconds.
SHORT_MISSION = ROOT / "tests" / "data" / "short_square_land.yaml"
# The paper's mission made short (8 m, a 6 m leg), for its algorithms over MAVLink.
SHORT_PAPER_MISSION = ROOT / "tests" / "data" / "short_paper_land.yaml"

# typer's CliRunner builds the whole click command tree from the app's functions on every `invoke` (about
# 25 ms each, and most test modules invoke the CLI). The tree of one app does not change between
# invocations: the choices that registries hold are read when an option is shown or checked (cli/app.py),
# not when the tree is built. So each app's tree is built once per test process.
typer.testing._get_command = functools.cache(typer.testing._get_command)


@pytest.fixture(scope="session")
def thesis_mission() -> MissionSpec:
    return load_mission(THESIS_MISSION)


@pytest.fixture(scope="session")
def short_mission() -> MissionSpec:
    return load_mission(SHORT_MISSION)


@pytest.fixture(scope="session")
def square_trial(thesis_mission):
    """One normal-mode trial of the thesis mission, with its trajectory."""
    return run_trial(TrialRequest(mission=thesis_mission, seed=7))


# The longest test files (by `pytest --durations=0`, summed per file, on a loaded machine), first. `make test`
# gives each xdist worker whole files (--dist loadfile, --no-loadscope-reorder: in this order, not by test
# count): a long file collected late runs alone at the end while the other workers idle. xdist starts each of
# the six workers (`-n` in the Makefile) on one of the first six files, and hands a worker the next file in
# the order once at most two of its tests are left to run: so a file's last two tests are short ones. The
# vehicle tutorials have two tests, so their worker takes the next file at once, to run after them: the
# seventh is a short one. Any file not named keeps its place after these.
FIRST_WAVE = ("test_field_campaign.py", "test_campaign_ray.py", "test_mavlink_runtime.py", "test_docs_site.py",
              "test_docs_tutorials_vehicle.py", "test_docs_tutorials.py")
LONGEST_FIRST = FIRST_WAVE + (
    "test_endpoint.py", "test_mavlink_camera.py", "test_calibrate.py",
    "test_sitl_failures.py", "test_sitl.py", "test_campaign.py", "test_roi_render.py", "test_runtimes.py",
    "test_field_ops.py", "test_campaign_drivers.py", "test_figures.py", "test_error_budget_pinned.py",
    "test_ground_effect.py", "test_precision_landing.py", "test_plugins.py", "test_sensing.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: index for index, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: a file's tests keep their order

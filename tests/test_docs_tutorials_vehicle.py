"""The tutorials that fly a vehicle over MAVLink in wall time (docs/tutorials/field-trial.md against a served
vehicle, sitl.md against a SITL), run as test_docs_tutorials.py runs every page. They wait on the vehicle more
than they compute: a module of their own runs them on another xdist worker meanwhile."""

import pytest

from .test_docs_tutorials import VEHICLE_PAGES, check_tutorial


@pytest.mark.parametrize("page", VEHICLE_PAGES)
def test_tutorial(page, tmp_path):
    check_tutorial(page, tmp_path)

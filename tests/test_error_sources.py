"""The error-source table: every source names real mission fields, and switching it off sets them."""

import pytest

from preland_app.runtime.embedded import TrialRequest, run_trial
from preland_app.sim.error_sources import ERROR_SOURCES, ErrorSourceError, field_default, find_error_source, \
    switched_off


def test_every_source_names_mission_fields_that_switching_off_sets(thesis_mission):
    for source in ERROR_SOURCES:
        off = switched_off(thesis_mission, source)
        for path, value in source.off.items():
            section, *parts = path.split(".")
            spec = getattr(off, section)
            for part in parts:
                spec = getattr(spec, part)
            assert spec == value, (source.name, path)
        assert source.magnitude_from


def test_defaults_come_from_the_specs_and_a_wrong_path_is_refused():
    assert field_default("environment.navigation.gps_drift_sigma_m") == 0.75
    assert field_default("sensors.irlock.quantize") is True
    with pytest.raises(ErrorSourceError, match="no such field"):
        field_default("environment.navigation.gps_drift_sigma")
    with pytest.raises(ErrorSourceError, match="must start with"):
        field_default("navigation.gps_drift_sigma_m")


def test_switching_gps_drift_off_brings_a_gps_landing_onto_its_take_off_point(thesis_mission):
    mission = switched_off(thesis_mission, find_error_source("GPS drift + noise"))
    with_drift = run_trial(TrialRequest(mission=thesis_mission, seed=2, land_mode="normal", record_trajectory=False))
    without = run_trial(TrialRequest(mission=mission, seed=2, land_mode="normal", record_trajectory=False))
    assert with_drift.landing_error_cm > 20.0
    assert without.landing_error_cm < 15.0

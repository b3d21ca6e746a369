"""Fault models, the thesis' fault command, and the CLI/spec fault syntax."""

import numpy as np
import pytest
from typer.testing import CliRunner

from preland_app.cli import app
from preland_app.sensing.faults import (
    FaultCommand,
    FaultInjector,
    FaultKind,
    FaultSpec,
    FaultSyntaxError,
    FaultTarget,
)

from .conftest import THESIS_MISSION


def _injector(text, seed=0, sensor="irlock"):
    return FaultInjector(sensor=sensor, spec=FaultSpec.parse(text), rng=np.random.default_rng(seed))


def test_random_drops_the_asked_fraction_with_seeded_results():
    injector = _injector("random:0.75", seed=11)
    kept = [injector.admit(height_m=5.0) for _ in range(10_000)]
    assert injector.produced == 10_000
    assert injector.dropped / injector.produced == pytest.approx(0.75, abs=0.02)
    again = _injector("random:0.75", seed=11)
    assert [again.admit(height_m=5.0) for _ in range(10_000)] == kept
    other = _injector("random:0.75", seed=12)
    assert [other.admit(height_m=5.0) for _ in range(10_000)] != kept


def test_periodic_pattern_is_exact():
    injector = _injector("periodic:3:2")
    pattern = [injector.admit(height_m=None) for _ in range(15)]
    assert pattern == [True, True, True, False, False] * 3
    assert (injector.produced, injector.dropped) == (15, 6)


def test_permanent_and_none():
    permanent, none = _injector("permanent"), _injector("none")
    assert not any(permanent.admit(height_m=1.0) for _ in range(100))
    assert all(none.admit(height_m=1.0) for _ in range(100))
    assert permanent.dropped == 100 and none.dropped == 0


def test_below_and_above_gate_exactly_at_the_threshold():
    below, above = _injector("below:3"), _injector("above:3")
    heights = [5.0, 3.0001, 3.0, 2.9999, 0.5]
    assert [below.admit(height_m=h) for h in heights] == [True, True, False, False, False]
    assert [above.admit(height_m=h) for h in heights] == [False, False, False, True, True]
    assert below.admit(height_m=None) and above.admit(height_m=None)  # unknown height: keep


def test_first_attempt_scope():
    injector = _injector("below:3:first-attempt")
    assert not injector.admit(height_m=2.0, attempt=1)
    assert injector.admit(height_m=2.0, attempt=2)
    assert str(injector.spec) == "below:3:first-attempt"


def _drop_runs(dropped: np.ndarray) -> np.ndarray:
    """The lengths of the runs of consecutive drops in a 0/1 sequence."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], dropped.astype(int), [0]))))
    return edges[1::2] - edges[0::2]


@pytest.mark.parametrize("loss, length", [(0.3, 5.0), (0.5, 1.0), (0.75, 12.0)])
def test_burst_drops_the_asked_share_in_bursts_of_the_asked_mean_length(loss, length):
    injector = _injector(f"burst:{loss:g}:{length:g}", seed=21)
    dropped = np.array([not injector.admit(height_m=5.0) for _ in range(100_000)])
    runs = _drop_runs(dropped)
    # A Gilbert channel's bursts are geometric: standard error of their mean length sqrt(L(L-1)/n); the share
    # lost, correlated over a burst and a gap, is within 0.02 at 100,000 values for these parameters.
    assert dropped.mean() == pytest.approx(loss, abs=0.02)
    assert runs.mean() == pytest.approx(length, abs=max(0.01, 5 * np.sqrt(length * (length - 1) / len(runs))))
    assert injector.dropped == dropped.sum() and injector.produced == 100_000
    again = _injector(f"burst:{loss:g}:{length:g}", seed=21)
    assert [not again.admit(height_m=5.0) for _ in range(1000)] == list(dropped[:1000])


def test_burst_and_random_drop_alike_shares_but_bursts_last_longer():
    bursts, scattered = _injector("burst:0.5:10", seed=3), _injector("random:0.5", seed=3)
    burst_runs = _drop_runs(np.array([not bursts.admit(height_m=None) for _ in range(20_000)]))
    random_runs = _drop_runs(np.array([not scattered.admit(height_m=None) for _ in range(20_000)]))
    assert burst_runs.mean() > 4 * random_runs.mean()  # random:0.5 drops runs of 2 values on average
    assert burst_runs.max() > 50 > random_runs.max()


def test_a_new_burst_fault_starts_from_its_stationary_state():
    firsts = []
    for seed in range(2000):
        injector = _injector("burst:0.25:8", seed=seed)
        firsts.append(not injector.admit(height_m=None))
    assert np.mean(firsts) == pytest.approx(0.25, abs=0.03)


def test_stale_gives_the_last_value_again_as_new_in_the_asked_share():
    injector = _injector("stale:0.3", seed=4)
    given = [injector.apply(k, height_m=5.0) for k in range(10_000)]
    assert injector.produced == 10_000 and injector.dropped == 0
    assert injector.repeated == sum(1 for k, value in enumerate(given) if value != k)
    assert injector.repeated / injector.produced == pytest.approx(0.3, abs=0.02)
    # A value given again is the one given just before it: nothing is dropped, nothing invented.
    assert given[0] == 0 and all(value in (k, given[k - 1]) for k, value in enumerate(given) if k)
    # A reading given again carries the new one's time.
    from preland_app.sensing.readings import TargetReading

    def reading(angle_x_rad: float, time_s: float) -> TargetReading:
        return TargetReading(sensor="irlock", capture_time_s=time_s, angle_x_rad=angle_x_rad, angle_y_rad=0.0)

    restamping = _injector("stale:1", seed=4)
    assert restamping.apply(reading(0.1, 1.0), height_m=None) == reading(0.1, 1.0)  # nothing to repeat yet
    assert restamping.apply(reading(0.2, 2.0), height_m=None) == reading(0.1, 2.0)
    assert not restamping.admit(height_m=None)  # admit: the new value is not the one used


def test_a_stale_fault_repeats_readings_and_the_outcome_records_it():
    """The marker's detections, half of them replaced by the frame before's: the vehicle lands, nothing is
    dropped, and the outcome counts the values given again."""
    import preland_app as preland

    mission = preland.load_mission(THESIS_MISSION)
    outcome = preland.fly(mission, seed=3, land="marker", faults={"marker": "stale:0.5"}, record_trajectory=False)
    assert outcome.outcome is preland.Outcome.LANDED and outcome.landing_error_cm < 30.0
    details = outcome.details
    assert details["marker_fault"] == "stale:0.5" and details["marker_dropped"] == 0
    assert 0.35 < details["marker_repeated"] / details["marker_produced"] < 0.65


@pytest.mark.parametrize("text", ["random", "random:1.5", "periodic:3", "below", "sometimes", "periodic:0:0",
                                  "below:-1", "random:x", "permanent:2", "burst:0.3", "burst:0.3:0.5",
                                  "burst:0.6:1", "burst:1:5", "burst:0.3:inf", "burst:-0.1:3", "stale",
                                  "stale:1.5", "stale:0.2:3"])
def test_bad_fault_syntax_is_rejected(text):
    with pytest.raises(FaultSyntaxError):
        FaultSpec.parse(text)


def test_fault_syntax_round_trips():
    for text in ("none", "random:0.5", "periodic:4:1", "permanent", "below:3", "above:2.5:first-attempt",
                 "burst:0.3:5", "burst:0.5:2.5:first-attempt", "stale:0.25"):
        assert str(FaultSpec.parse(text)) == text


# The thesis' Table 1 rules.

def test_command_r_drop_positive_selects_random_and_ignores_the_rest():
    command = FaultCommand(target=FaultTarget.IRLOCK, r_drop=0.75, p_keep=5, p_drop=5)
    assert command.faults() == {"irlock": FaultSpec(FaultKind.RANDOM, probability=0.75)}


def test_command_r_drop_zero_selects_periodic():
    command = FaultCommand(target=2, r_drop=0.0, p_keep=4, p_drop=2)
    assert command.faults() == {"marker": FaultSpec(FaultKind.PERIODIC, keep=4, drop=2)}


def test_command_r_drop_one_is_permanent_and_so_is_keep_zero_drop_positive():
    assert FaultCommand(target=3, r_drop=1.0).fault().kind is FaultKind.PERMANENT
    assert FaultCommand(target=3, p_keep=0, p_drop=7).fault().kind is FaultKind.PERMANENT
    assert set(FaultCommand(target=3, r_drop=1.0).faults()) == {"irlock", "marker"}


def test_command_all_zero_turns_injection_off():
    assert FaultCommand(target=1).fault() == FaultSpec()
    injector = _injector("permanent")
    injector.set_spec(FaultCommand(target=1).fault())
    assert injector.admit(height_m=1.0)


def test_command_fields_are_checked():
    with pytest.raises(FaultSyntaxError):
        FaultCommand(target=1, r_drop=1.5)
    with pytest.raises(ValueError):
        FaultCommand(target=4)
    with pytest.raises(FaultSyntaxError):
        FaultCommand(target=1, p_keep=70000)


# CLI and mission spec.

@pytest.mark.parametrize("args, needle", [
    (["--fault", "marker=sometimes"], "unknown fault"),
    (["--fault", "camera=random:0.5"], "SENSOR=FAULT"),
    (["--fault", "marker=below:3", "--fault", "marker=above:3"], "given twice"),
    (["--land", "irlock", "--fault", "marker=below:3"], "does not use the marker"),
    (["--land", "marker", "--sensor", "irlock"], "only the cautious mode"),
    (["--land", "cautious", "--sensor", "sonar"], "unknown sensor"),
])
def test_cli_rejects_bad_fault_options_with_one_line(args, needle):
    result = CliRunner().invoke(app, ["fly", str(THESIS_MISSION), *args])
    assert result.exit_code == 2, result.output
    assert needle in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_mission_file_fault_errors_name_the_field(tmp_path):
    text = THESIS_MISSION.read_text().replace("  mode: normal", "  mode: marker\n  faults:\n    marker: below:three")
    path = tmp_path / "m.yaml"
    path.write_text(text)
    result = CliRunner().invoke(app, ["fly", str(path)])
    assert result.exit_code == 2 and "land.faults.marker" in result.stderr


def test_fault_message_round_trips_in_mavlink_2_frames():
    from preland_app.mavlink.fault_message import decode, encode

    for command in (FaultCommand(target=1, r_drop=0.75), FaultCommand(target=3, p_keep=4, p_drop=2),
                    FaultCommand(target=2)):
        frame = encode(command)
        assert frame[0] == 0xFD and decode(frame) == command
    corrupt = bytearray(encode(FaultCommand(target=1, r_drop=0.5)))
    corrupt[12] ^= 0xFF
    assert decode(bytes(corrupt)) is None
    assert decode(b"\xfd\x01" + b"\x00" * 20) is None


def test_a_burst_fault_flies_and_the_outcome_records_it():
    """IR-LOCK readings lost in bursts of half a second on average (25 readings at 50 Hz), three in four lost
    in all: the vehicle still lands on the beacon, and the outcome says what was dropped."""
    import preland_app as preland

    mission = preland.load_mission(THESIS_MISSION)
    outcome = preland.fly(mission, seed=5, land="irlock", faults={"irlock": "burst:0.75:25"}, record_trajectory=False)
    assert outcome.outcome is preland.Outcome.LANDED and outcome.landing_error_cm < 30.0
    details = outcome.details
    assert details["irlock_fault"] == "burst:0.75:25"
    assert 0.6 < details["irlock_dropped"] / details["irlock_produced"] < 0.9

"""Fault models, the thesis' fault command, and the CLI/spec fault syntax."""

import math

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
                                  "stale:1.5", "stale:0.2:3", "delay", "delay:0", "delay:-5", "delay:100:120",
                                  "delay:100:-1", "delay:1:2:3", "delay:nan", "delay:6000", "delay:100:x",
                                  "false", "false:0.5", "false:0.5:0", "false:0.5:-1", "false:0.5:60",
                                  "false:1.5:2", "false:0.5:nan", "false:0.1:2:3", "stalestamp",
                                  "stalestamp:2", "stalestamp:0.5:1", "none+random:0.5", "random:0.5+none",
                                  "delay:50+random:0.2+delay:20", "random:0.5+", "+delay:50",
                                  "random:0.5++delay:5", "random:2+delay:50"])
def test_bad_fault_syntax_is_rejected(text):
    with pytest.raises(FaultSyntaxError):
        FaultSpec.parse(text)


def test_fault_syntax_round_trips():
    for text in ("none", "random:0.5", "periodic:4:1", "permanent", "below:3", "above:2.5:first-attempt",
                 "burst:0.3:5", "burst:0.5:2.5:first-attempt", "stale:0.25", "delay:120", "delay:100:40",
                 "delay:60:first-attempt", "false:0.1:3", "false:0.25:0.5:first-attempt",
                 "stalestamp:0.3", "stalestamp:1:first-attempt", "random:0.75+delay:50",
                 "below:3:first-attempt+stale:0.2", "burst:0.5:3+false:0.1:2+delay:100:20"):
        assert str(FaultSpec.parse(text)) == text


def test_a_delay_holds_each_value_back_by_its_drawn_delay_and_keeps_the_order():
    fixed = _injector("delay:120", seed=2)
    assert [fixed.arrival_s(t) for t in (1.0, 1.02)] == pytest.approx([1.12, 1.14])
    jittered = _injector("delay:100:40", seed=2)
    ready = np.arange(20_000) * 0.02  # 50 Hz, as the IR-LOCK
    arrivals = np.array([jittered.arrival_s(t) for t in ready])
    delays = arrivals - ready
    # Uniform 60..140 ms, except where the value ahead arrives later: then right after it, never before.
    assert delays.min() >= 0.06 - 1e-12 and delays.max() <= 0.14 + 1e-12 and np.all(np.diff(arrivals) >= 0)
    # Each arrival is the later of its own (ready + 100 ms + a uniform draw) and the one ahead.
    drawn_s = ready + (100.0 + np.random.default_rng(2).uniform(-40.0, 40.0, ready.size)) / 1000.0
    assert arrivals == pytest.approx(np.maximum.accumulate(drawn_s), abs=1e-12)
    assert 0.100 < delays.mean() < 0.110  # the order adds a little to the drawn mean of 100 ms
    assert jittered.delayed == 20_000 and jittered.delay_total_s == pytest.approx(delays.sum())
    again = _injector("delay:100:40", seed=2)
    assert [again.arrival_s(t) for t in ready[:50]] == list(arrivals[:50])
    once = _injector("delay:100:first-attempt", seed=2)
    assert once.arrival_s(3.0, attempt=2) == 3.0 and once.delayed == 0


def test_a_reader_at_its_ticks_gets_the_newest_value_that_has_arrived():
    from preland_app.landing.fault_gate import FaultGate

    gate = FaultGate(faults={"marker": FaultSpec.parse("delay:150")}, sensors=["marker"],
                     rng=np.random.default_rng(0), streams=["marker"])
    ticks = [0.0, 0.1, 0.2, 0.3, 0.4]
    read = [gate.take("marker", f"frame {k}", now_s=t, height_m=None) for k, t in enumerate(ticks)]
    # Each value arrives 150 ms after its tick: frame 0 at 0.15 is read at 0.2, frame 1 at 0.25 at 0.3.
    assert read == [None, None, "frame 0", "frame 1", "frame 2"]
    assert gate.take("marker", None, now_s=0.5, height_m=None) == "frame 3"  # a tick without a value still reads
    assert gate.take("marker", None, now_s=0.61, height_m=None) == "frame 4"
    assert gate.take("marker", None, now_s=0.7, height_m=None) is None
    details = gate.details()
    assert (details["marker_fault"], details["marker_delayed"], details["marker_delay_mean_ms"],
            details["marker_superseded"]) == ("delay:150", 5, 150.0, 0)
    # With jitter, two values can arrive between ticks: the reader gets the newer, the older is passed over.
    jittery = FaultGate(faults={"irlock": FaultSpec.parse("delay:50:45")}, sensors=["irlock"],
                        rng=np.random.default_rng(0), streams=["irlock"])
    read = [jittery.take("irlock", k, now_s=k * 0.02, height_m=None) for k in range(2000)]
    got = [value for value in read if value is not None]
    superseded = jittery.details()["irlock_superseded"]
    assert got == sorted(got) and len(set(got)) == len(got) and superseded > 50
    # Every value is read, passed over, or still on its way at the last tick (within 95 ms of it).
    assert 0 <= 2000 - len(got) - superseded <= 5


def test_a_delayed_irlock_reaches_the_autopilot_late_in_order_and_the_landing_counts_it():
    """A precision land mode sends each reading at its own arrival: a LANDING_TARGET leaves 60 to 140 ms after
    its capture (delay:100:40), in the readings' order, and the outcome counts the delayed values."""
    from preland_app.clock import LoopClock, run_virtual, wait_until
    from preland_app.events import EventLog
    from preland_app.landing.base import LandingContext
    from preland_app.landing.precision import PrecisionLanding
    from preland_app.sensing.readings import TargetReading
    from preland_app.sensing.spec import SensorsSpec
    from preland_app.sensing.suite import SensorSuite
    from preland_app.vehicle.fake import FakeVehicle
    from preland_app.vehicle.types import FlightMode

    async def land() -> tuple[FakeVehicle, dict]:
        clock = LoopClock()
        vehicle = FakeVehicle(clock=clock, climb_rate_m_s=3.0, descent_rate_m_s=1.0)
        await vehicle.connect()
        await vehicle.set_mode(FlightMode.GUIDED)
        await vehicle.arm()
        await vehicle.takeoff(altitude_rel_m=6.0)

        async def up() -> bool:
            return (await vehicle.telemetry()).altitude_rel_m >= 5.99

        await wait_until(up, clock=clock, timeout_s=30, operation="climb")

        class Beacon:
            async def next_reading(self) -> TargetReading:
                await clock.sleep(0.02)
                return TargetReading(sensor="irlock", capture_time_s=clock.now_s(), angle_x_rad=0.0,
                                     angle_y_rad=0.0)

        context = LandingContext(vehicle=vehicle, clock=clock, events=EventLog(clock), rng=np.random.default_rng(7),
                                 timeout_s=60.0, sensors=SensorSuite(spec=SensorsSpec(), irlock=Beacon()))
        report = await PrecisionLanding("irlock", faults={"irlock": FaultSpec.parse("delay:100:40")}).land(context)
        return vehicle, report.details

    vehicle, details = run_virtual(land())
    sent_s = np.array([call.time_s for call in vehicle.calls if call.operation == "send_landing_target"])
    captured_s = np.array([target.timestamp_s for target in vehicle.landing_targets])
    ages_s = sent_s - captured_s
    assert len(sent_s) > 200  # 6 m at 1 m/s, 50 readings a second
    assert ages_s.min() >= 0.06 - 1e-6 and ages_s.max() <= 0.14 + 1e-6 and 0.095 < ages_s.mean() < 0.11
    assert np.all(np.diff(captured_s) > 0) and np.all(np.diff(sent_s) >= 0)
    assert details["irlock_fault"] == "delay:100:40" and details["irlock_dropped"] == 0
    # Values still on their way at touchdown never arrive: at most 140 ms of them.
    assert 0 <= details["irlock_delayed"] - details["landing_targets_sent"] <= 7
    assert 95.0 < details["irlock_delay_mean_ms"] < 110.0


def test_combined_faults_apply_in_order_and_the_first_draws_as_it_would_alone():
    """random:0.5+delay:100: the values random:0.5 alone keeps (same seed), each 100 ms late and in order."""
    alone, combined = _injector("random:0.5", seed=9), _injector("random:0.5+delay:100", seed=9)
    assert [part.kind.value for part in combined.spec.parts()] == ["random", "delay"]
    kept_alone = [k for k in range(2000) if alone.apply(k, height_m=5.0) is not None]
    kept, arrivals = [], []
    for k in range(2000):
        if combined.apply(k, height_m=5.0) is not None:
            kept.append(k)
            arrivals.append(combined.arrival_s(0.02 * k))
    assert kept == kept_alone and 900 < len(kept) < 1100
    assert np.allclose(np.array(arrivals) - 0.02 * np.array(kept), 0.1)
    assert sum(part.dropped for part in combined.chain()) == 2000 - len(kept)
    assert combined.chain()[1].delayed == len(kept)


def test_the_thesis_frame_time_with_random_drops_flies_and_counts_both():
    """The marker's detections at the thesis' Raspberry Pi processing time (about 50 ms a frame, Section 4.2)
    and half of them lost at random, as in Table 3: it lands on the pad; the outcome counts both."""
    import preland_app as preland

    mission = preland.load_mission(THESIS_MISSION)
    outcome = preland.fly(mission, seed=2, land="marker", faults={"marker": "random:0.5+delay:50"},
                          record_trajectory=False)
    assert outcome.outcome is preland.Outcome.LANDED and outcome.landing_error_cm < 20.0
    details = outcome.details
    assert details["marker_fault"] == "random:0.5+delay:50"
    assert 0.35 < details["marker_dropped"] / details["marker_produced"] < 0.65
    kept = details["marker_produced"] - details["marker_dropped"]
    assert 0 <= kept - details["marker_delayed"] <= 3
    assert details["marker_delay_mean_ms"] == pytest.approx(50.0, abs=1.0)


def test_stalestamp_gives_new_readings_the_time_of_the_one_before_in_the_asked_share():
    from preland_app.sensing.readings import TargetReading

    injector = _injector("stalestamp:0.3", seed=5)
    readings = [TargetReading(sensor="irlock", capture_time_s=0.02 * k, angle_x_rad=0.001 * k, angle_y_rad=0.0)
                for k in range(5000)]
    given = [injector.apply(reading, height_m=5.0) for reading in readings]
    old = [k for k, (reading, out) in enumerate(zip(readings, given)) if out.capture_time_s != reading.capture_time_s]
    assert injector.old_stamped == len(old) and injector.dropped == injector.repeated == 0
    assert len(old) / 5000 == pytest.approx(0.3, abs=0.02)
    # The value is the new one's; its time is the one given before it (a frozen clock stays frozen).
    assert all(out.angle_x_rad == reading.angle_x_rad for reading, out in zip(readings, given))
    assert all(given[k].capture_time_s == given[k - 1].capture_time_s for k in old) and 0 not in old
    # A value without a time (a frame's marker detections) passes as it is.
    frames = _injector("stalestamp:1", sensor="marker")
    assert frames.apply(["a"], height_m=5.0) == ["a"] and frames.apply(["b"], height_m=5.0) == ["b"]
    assert frames.old_stamped == 0


def test_a_stalestamp_irlock_flies_and_a_stalestamp_marker_is_refused_where_detections_carry_no_time():
    import preland_app as preland
    from preland_app.errors import SpecError

    mission = preland.load_mission(THESIS_MISSION)
    outcome = preland.fly(mission, seed=3, land="irlock", faults={"irlock": "stalestamp:0.5"},
                          record_trajectory=False)
    assert outcome.outcome is preland.Outcome.LANDED and outcome.landing_error_cm < 15.0
    details = outcome.details
    assert details["irlock_fault"] == "stalestamp:0.5" and details["irlock_dropped"] == 0
    assert 0.4 < details["irlock_old_stamp"] / details["irlock_produced"] < 0.6
    with pytest.raises(SpecError, match="faults.marker.*carry no time"):
        preland.fly(mission, seed=3, land="paper_adaptive", faults={"marker": "stalestamp:0.5"})


def test_a_false_fault_points_the_asked_share_of_readings_at_one_spot_off_the_target():
    """false:0.2:3: a fifth of the readings point 3 m from the target on the ground, always at the same spot
    (a reflection stays where it is); the others are the readings themselves."""
    from preland_app.sensing.readings import TargetReading

    injector = _injector("false:0.2:3", seed=11)
    height_m = 6.0
    spots = []
    for k in range(5000):
        # The target seen 0.5 m right of and 0.25 m behind the camera's axis, with and without a range.
        reading = TargetReading(sensor="irlock", capture_time_s=0.02 * k, angle_x_rad=math.atan(0.5 / height_m),
                                angle_y_rad=math.atan(0.25 / height_m),
                                distance_m=math.sqrt(0.5**2 + 0.25**2 + height_m**2) if k % 2 else None)
        given = injector.apply(reading, height_m=height_m)
        assert given.capture_time_s == reading.capture_time_s
        if given == reading:
            continue
        x_m, y_m = height_m * math.tan(given.angle_x_rad), height_m * math.tan(given.angle_y_rad)
        if given.distance_m is not None:
            assert given.distance_m == pytest.approx(math.sqrt(x_m**2 + y_m**2 + height_m**2))
        spots.append((x_m - 0.5, y_m - 0.25))
    spots = np.array(spots)
    assert injector.falsified == len(spots) and injector.dropped == 0 and injector.produced == 5000
    assert len(spots) / 5000 == pytest.approx(0.2, abs=0.02)
    assert np.allclose(np.hypot(spots[:, 0], spots[:, 1]), 3.0) and np.allclose(spots, spots[0])
    # Without a range or a height a reading cannot be put on the ground: it passes as it is.
    blind = _injector("false:1:3")
    reading = TargetReading(sensor="irlock", capture_time_s=0.0, angle_x_rad=0.1, angle_y_rad=0.0)
    assert blind.apply(reading, height_m=None) == reading and blind.falsified == 0


def test_a_false_marker_detection_moves_the_pose_and_the_pad_centre():
    from preland_app.sensing.marker import MarkerDetection

    detection = MarkerDetection(marker_id=7, side_m=0.2, corners_px=np.zeros((4, 2)), rvec=np.zeros(3),
                                tvec=np.array([0.1, -0.2, 4.0]), pad_center_cam_m=np.array([0.15, -0.2, 4.0]))
    injector = _injector("false:1:2", seed=3, sensor="marker")
    (moved,) = injector.apply([detection], height_m=4.0)
    shift = moved.tvec - detection.tvec
    assert np.allclose(moved.pad_center_cam_m - detection.pad_center_cam_m, shift)
    assert shift[2] == 0.0 and math.hypot(shift[0], shift[1]) == pytest.approx(2.0)
    assert moved.marker_id == 7 and injector.falsified == 1


@pytest.mark.parametrize("land, seed", [("irlock", 3), ("marker", 4)])
def test_false_detections_among_true_ones_are_refused_by_the_autopilot_and_it_lands_on_the_pad(land, seed):
    """One reading in ten points 3 m off the pad: AC_PrecLand's outlier gate refuses them (a false one is
    fused only after three refused in a row), so the vehicle lands on the pad; the outcome counts them."""
    import preland_app as preland

    mission = preland.load_mission(THESIS_MISSION)
    outcome = preland.fly(mission, seed=seed, land=land, faults={land: "false:0.1:3"}, record_trajectory=False)
    assert outcome.outcome is preland.Outcome.LANDED and outcome.landing_error_cm < 20.0
    details = outcome.details
    assert details[f"{land}_fault"] == "false:0.1:3" and details[f"{land}_dropped"] == 0
    assert 0.05 < details[f"{land}_false"] / details[f"{land}_produced"] < 0.15


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

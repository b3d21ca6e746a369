"""Simulated sensors over MAVLink see the world through SIM_STATE: each reading shows a pose of its own and
carries that pose's time, so a stalled truth stream gives no readings rather than old views."""

import math

import numpy as np
import pytest

from preland_app.clock import LoopClock, run_virtual
from preland_app.sensing.camera import RPI_CAMERA_V2_640X480
from preland_app.sensing.irlock import IrLockModel, IrLockSpec
from preland_app.sensing.pad import THESIS_PAD
from preland_app.sensing.sources import IrLockSource, VirtualFrameSource
from preland_app.sensing.virtual_camera import CameraPose, VirtualCamera


class StalledTruth:
    """A pose stream that updates at 20 Hz of vehicle time, except between `stall_from_s` and `stall_to_s`."""

    def __init__(self, clock, *, stall_from_s: float, stall_to_s: float) -> None:
        self.clock = clock
        self.stall_from_s, self.stall_to_s = stall_from_s, stall_to_s
        self._time_s = 0.0

    def _update(self) -> None:
        now_s = self.clock.now_s()
        if not self.stall_from_s <= now_s < self.stall_to_s:
            self._time_s = math.floor(now_s * 20.0) / 20.0

    def pose(self) -> CameraPose:
        self._update()
        # The vehicle slides east at 1 m/s, 6 m above the pad.
        return CameraPose(0.0, self._time_s, -6.0, 0.0, 0.0, 0.0)

    def time_s(self) -> float:
        self._update()
        return self._time_s


def test_each_frame_shows_a_pose_of_its_own_stamped_with_that_poses_time():
    async def frames():
        clock = LoopClock()
        truth = StalledTruth(clock, stall_from_s=1.0, stall_to_s=2.0)
        renderer = VirtualCamera(camera=RPI_CAMERA_V2_640X480, pad=THESIS_PAD, pad_origin_ned_m=(0.0, 0.0),
                                 rng=np.random.default_rng(0))
        source = VirtualFrameSource(renderer=renderer, pose=truth.pose, clock=clock, pose_time_s=truth.time_s)
        out = []
        while clock.now_s() < 3.0:
            frame = await source.next_frame()
            out.append((clock.now_s(), frame.capture_time_s))
        return out, source.ticks_without_new_truth

    out, waits = run_virtual(frames())
    stamps = [capture_s for _, capture_s in out]
    assert stamps == sorted(set(stamps))  # no pose shown twice
    for now_s, capture_s in out:
        assert 0.0 <= now_s - capture_s < 0.05 + 1e-9
    # The last pose before the stall (0.95 s) is shown once, at 0.967 s; the next frame waits for the truth
    # to resume at 2.0 s. The camera's 30 ticks a second outrun the 20 poses: 90 ticks, 60 poses, 20 stalled.
    assert [now_s for now_s, _ in out if 0.96 < now_s < 2.01] == [pytest.approx(29 / 30), pytest.approx(2.0)]
    assert len(out) == 41 and waits == 90 - len(out)


def test_irlock_reads_each_pose_once_at_the_poses_time():
    async def readings():
        clock = LoopClock()
        truth = StalledTruth(clock, stall_from_s=1.0, stall_to_s=2.0)
        spec = IrLockSpec(noise_sigma_deg=0.0, quantize=False, mount_offset_frd_m=(0.0, 0.0, 0.0), latency_s=0.0)
        source = IrLockSource(model=IrLockModel(spec=spec, beacon_ned_m=(0.0, 0.0), rng=np.random.default_rng(0)),
                              pose=truth.pose, clock=clock, pose_time_s=truth.time_s)
        out = []
        while clock.now_s() < 3.0:
            reading = await source.next_reading()
            out.append((clock.now_s(), reading))
        return out, source.ticks_without_new_truth

    out, waits = run_virtual(readings())
    read = [(now_s, reading) for now_s, reading in out if reading is not None]
    # 20 poses a second, one reading each, none while the truth is stalled (the pose of 0.95 s read once).
    assert [reading.capture_time_s for _, reading in read] == pytest.approx([0.05 * i for i in range(0, 20)]
                                                                            + [0.05 * i for i in range(40, 61)])
    assert waits == len(out) - len(read) == 150 - 41
    for now_s, reading in read:
        # The reading shows the beacon from where the vehicle was at its capture time.
        assert -6.0 * math.tan(reading.angle_x_rad) == pytest.approx(reading.capture_time_s, abs=1e-6)
        assert now_s - reading.capture_time_s < 0.05 + 1e-9

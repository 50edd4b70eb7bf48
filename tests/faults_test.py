"""Fault schedules of the SIL (sim/rig/faults.py): which frames carry which HQ_IMU_FAULT."""

import numpy as np
import pytest

from heliquad.sim.base.dialect import dialect
from heliquad.sim.base.errors import InputError
from heliquad.sim.rig.faults import Fault, imu_fault_codes, link_close_frame, parse_fault

MAV = dialect()
DT_US = 5000


def test_a_holding_fault_covers_its_frames_from_t_for_d():
    # silent from 20 ms for 10 ms: the frames at 20 and 25 ms.
    codes = imu_fault_codes([parse_fault("silent@0.02:0.01")], 1, 8, DT_US)
    expected = np.zeros(8, dtype=np.uint8)
    expected[[3, 4]] = MAV.HQ_IMU_FAULT_SILENT          # frames 4 and 5
    np.testing.assert_array_equal(codes, expected)


def test_a_fault_without_duration_holds_to_the_end_and_one_shots_act_once():
    faults = [parse_fault("nack@0.012"), parse_fault("reset@0.001")]
    codes = imu_fault_codes(faults, 1, 5, DT_US)
    # reset on the first frame at or after 1 ms (frame 1); nack from 12 ms (frame 3) on.
    assert list(codes) == [MAV.HQ_IMU_FAULT_RESET, 0, MAV.HQ_IMU_FAULT_NACK,
                           MAV.HQ_IMU_FAULT_NACK, MAV.HQ_IMU_FAULT_NACK]


def test_batches_see_the_same_schedule_as_one_long_batch():
    faults = [parse_fault("silent@0.1:0.2"), parse_fault("overflow@0.5")]
    whole = imu_fault_codes(faults, 1, 200, DT_US)
    parts = [imu_fault_codes(faults, first, 50, DT_US) for first in (1, 51, 101, 151)]
    parts = [p if p is not None else np.zeros(50, dtype=np.uint8) for p in parts]
    np.testing.assert_array_equal(np.concatenate(parts), whole)


def test_no_imu_fault_means_no_codes_and_link_gives_its_frame():
    faults = [parse_fault("link@1.5")]
    assert imu_fault_codes(faults, 1, 400, DT_US) is None
    assert link_close_frame(faults, DT_US) == 300
    assert link_close_frame([], DT_US) is None


@pytest.mark.parametrize("text, match", [
    ("bogus@1", "unknown fault"), ("silent", "expected KIND@T"), ("silent@nan", "non-negative"),
    ("link@1:2", "takes no duration"), ("silent@1:-2", "positive"),
])
def test_bad_faults_are_input_errors(text, match):
    with pytest.raises(InputError, match=match):
        parse_fault(text)


def test_a_fault_shorter_than_a_loop_between_two_frames_is_refused():
    from heliquad.sim.rig.faults import check_faults

    with pytest.raises(InputError, match="falls between two loops"):
        check_faults([parse_fault("silent@0.0012:0.0005")], DT_US)
    check_faults([parse_fault("silent@0.0012:0.005")], DT_US)      # covers the frame at 5 ms


def test_fault_is_a_value():
    assert parse_fault("SILENT@2:0.5") == Fault("silent", 2.0, 0.5)

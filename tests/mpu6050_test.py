"""The MPU6050 driver against the emulated chip (firmware/core/mpu6050.cpp and
firmware/targets/host/mpu6050_emulator.cpp)."""

import math
import struct

import pytest

from heliquad import _firmware as fw

# Stand-in DMP image for upload/verify tests: the driver treats the image as opaque bytes.
# (The real MotionApps image is InvenSense's and is not in this repository.)
FAKE_IMAGE = bytes((i * 7 + 3) & 0xFF for i in range(1929))
GYRO_LSB = 16.4          # per deg/s at +/-2000 deg/s
ACCEL_LSB = 16384.0      # per g at +/-2 g


def dmp_packet(q_chip, gyro_dps=(0, 0, 0), accel_g=(0, 0, 1)):
    """A MotionApps 2.0 FIFO packet: quaternion Q30, gyro and accel as int32 (value in the
    high half), 2 unused bytes; big-endian."""
    quat = [int(round(c * (1 << 30))) for c in q_chip]
    gyro = [int(round(g * GYRO_LSB)) << 16 for g in gyro_dps]
    accel = [int(round(a * ACCEL_LSB)) << 16 for a in accel_g]
    return struct.pack(">4i3i3i2x", *quat, *gyro, *accel)


def raw_packet(accel_g, gyro_dps):
    return struct.pack(">3h3h", *[int(round(a * ACCEL_LSB)) for a in accel_g],
                       *[int(round(g * GYRO_LSB)) for g in gyro_dps])


def test_parse_known_dmp_bytes():
    half = math.sqrt(0.5)
    packet = dmp_packet((half, half, 0.0, 0.0), gyro_dps=(10, -20, 30), accel_g=(0, 0, 1))
    assert len(packet) == 42 and packet[:4] == bytes([0x2D, 0x41, 0x3C, 0xCD])
    s = fw.Mpu6050.parse_dmp_packet(packet)
    assert s.has_attitude
    # chip (w, x, y, z) -> FRD (w, x, -y, -z): a +90 deg roll about x stays +90 deg roll
    assert fw.to_euler(s.attitude).roll == pytest.approx(math.pi / 2, abs=1e-5)
    g = s.gyro_rad_s.to_list()
    assert g == pytest.approx([math.radians(10), math.radians(20), math.radians(-30)], rel=1e-3)
    assert s.accel_m_s2.to_list() == pytest.approx([0, 0, -9.80665], abs=1e-3)


def test_misaligned_bytes_are_not_an_attitude():
    packet = dmp_packet((1, 0, 0, 0))
    assert fw.Mpu6050.parse_dmp_packet(packet[5:] + packet[:5]) is None


def init(image=FAKE_IMAGE):
    chip, drv = fw.Mpu6050Emulator(), fw.Mpu6050(image)
    return chip, drv, drv.init(chip)


def test_init_uploads_and_verifies_the_dmp_image():
    chip, drv, result = init()
    assert result == fw.InitResult.OK_DMP and drv.mode == fw.SensorMode.DMP
    rate_at = 2 * 256 + 0x16                  # the DMP rate divisor lives inside the image
    expected = FAKE_IMAGE[:rate_at] + b"\x00\x00" + FAKE_IMAGE[rate_at + 2:]
    assert chip.memory(0, len(FAKE_IMAGE)) == expected
    assert chip.dmp_enabled and drv.packet_size == 42


def test_without_an_image_the_raw_path_flies():
    chip, drv, result = init(b"")
    assert result == fw.InitResult.OK_RAW and chip.raw_fifo_enabled
    chip.push_fifo(raw_packet((0, 0, 1), (1, 2, 3)), False)
    s = drv.poll(chip)
    assert not s.has_attitude
    counts = [round(g * GYRO_LSB) for g in (1, 2, 3)]          # 16, 33, 49 LSB
    expected = [math.radians(c / GYRO_LSB) * sign for c, sign in zip(counts, (1, -1, -1))]
    assert s.gyro_rad_s.to_list() == pytest.approx(expected, rel=1e-6)


def test_missing_chip_is_reported():
    chip, drv = fw.Mpu6050Emulator(), fw.Mpu6050(FAKE_IMAGE)
    chip.set_present(False)
    assert drv.init(chip) == fw.InitResult.NO_DEVICE


def test_drains_to_the_newest_packet():
    chip, drv, _ = init()
    for roll in (0.1, 0.2, 0.3):
        q = (math.cos(roll / 2), math.sin(roll / 2), 0.0, 0.0)
        chip.push_fifo(dmp_packet(q), True)
    s = drv.poll(chip)
    assert fw.to_euler(s.attitude).roll == pytest.approx(0.3, abs=1e-5)
    assert drv.counters.dropped == 2 and drv.counters.packets == 1
    assert chip.fifo_count == 0 and drv.poll(chip) is None


def test_fifo_overflow_is_detected_and_recovered():
    chip, drv, _ = init()
    packet = dmp_packet((1, 0, 0, 0))
    for _ in range(25):                       # 1050 bytes: the 1024-byte FIFO overflows
        chip.push_fifo(packet, True)
    assert chip.fifo_count == 1024            # 1024 is not a multiple of 42: misaligned
    assert drv.poll(chip) is None
    c = drv.counters
    assert (c.overflows, c.resyncs) == (1, 1) and chip.fifo_count == 0
    chip.push_fifo(packet, True)              # after the reset, packets line up again
    assert drv.poll(chip) is not None and drv.counters.packets == 1


def test_partial_packet_count_forces_a_resync():
    chip, drv, _ = init()
    chip.push_fifo(dmp_packet((1, 0, 0, 0))[:30], True)
    assert drv.poll(chip) is None and drv.counters.resyncs == 1 and chip.fifo_count == 0

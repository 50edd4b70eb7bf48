"""The MPU6050 driver against the emulated chip (firmware/core/mpu6050.cpp and
sim/sensor/mpu6050_emulator.cpp)."""

import math
import struct

import pytest

# Made-up DMP firmware of MotionApps 2.0's form (the real one is InvenSense's and is not in
# this repository); the driver and the emulator treat its bytes as opaque.
from fake_dmp import FAKE_CONFIG, FAKE_DMP, FAKE_IMAGE, FAKE_UPDATES, chip_and_driver
from heliquad import _firmware as fw
from heliquad.host.commands.dmp_image import table_entries

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


def init(dmp=FAKE_DMP, **kw):
    chip, drv = chip_and_driver(dmp, **kw)
    return chip, drv, drv.init(chip)


def test_init_performs_the_motionapps_sequence_and_the_emulator_accepts_dmp_packets():
    chip, drv, result = init()
    assert result == fw.InitResult.OK_DMP and drv.mode == fw.SensorMode.DMP
    assert chip.dmp_configured and chip.dmp_status == "configured"
    n_config = len(table_entries(FAKE_CONFIG, specials=True))
    assert chip.dmp_progress == (1929, n_config, 7) and chip.dmp_config_entries == n_config
    # DMP memory: the image with every configuration entry, then every update, written over
    # it; the configuration's FIFO rate divisor replaced by the driver's (0).
    expected = bytearray(FAKE_IMAGE)
    writes = table_entries(FAKE_CONFIG, specials=True) + table_entries(FAKE_UPDATES, specials=False)
    for bank, offset, data in writes:
        if isinstance(data, bytes):
            at = bank * 256 + offset
            expected[at:at + len(data)] = b"\x00\x00" if (bank, offset) == (2, 0x16) else data
    assert chip.memory(0, 1929) == bytes(expected)
    # Registers as MotionApps leaves them, then ours: DMP and FIFO on, Z gyro PLL.
    assert chip.read(0x70, 2) == b"\x03\x00"                  # DMP_CFG_1/2
    assert chip.read(0x6B, 1) == b"\x03"                       # PWR_MGMT_1: PLL on the Z gyro
    assert chip.read(0x1A, 1) == b"\x0b"                       # CONFIG: EXT_SYNC TEMP_OUT_L, DLPF 3
    assert chip.read(0x1F, 4) == bytes([2, 80, 156, 0])         # MOT_THR, MOT_DUR, ZRMOT_THR/DUR
    assert chip.read(0x38, 1) == b"\x12"                       # INT_ENABLE: DMP_INT | FIFO_OFLOW
    assert chip.dmp_enabled and drv.packet_size == 42
    assert chip.push_fifo(dmp_packet((1, 0, 0, 0)), True) == 42
    assert drv.poll(chip).has_attitude and drv.probe(chip) == fw.ImuHealth.CONFIGURED


def test_the_fifo_rate_divisor_is_the_drivers():
    chip, drv, result = init(dmp_rate_div=4)
    assert result == fw.InitResult.OK_DMP and chip.dmp_configured
    assert chip.memory(2 * 256 + 0x16, 2) == b"\x00\x04"
    assert drv.sample_rate_hz == pytest.approx(40.0)


def upload_image(chip, image):
    """The image into DMP memory from address 0, 16 bytes a write (BANK_SEL, MEM_START_ADDR,
    MEM_R_W)."""
    for at in range(0, len(image), 16):
        chip.write(0x6D, bytes([at // 256]))
        chip.write(0x6E, bytes([at % 256]))
        chip.write(0x6F, image[at:at + 16])


def old_driver_sequence(chip, image):
    """What the driver did before it knew the MotionApps configuration: image upload, the
    FIFO rate, DMP_CFG_1/2, and the DMP enabled; no configuration table, no updates."""
    chip.write(0x6B, b"\x80")                                  # reset
    chip.write(0x6B, b"\x01")
    upload_image(chip, image)
    chip.write(0x6D, b"\x02")
    chip.write(0x6E, b"\x16")
    chip.write(0x6F, b"\x00\x00")
    chip.write(0x70, b"\x03\x00")
    chip.write(0x38, b"\x12")
    chip.write(0x6A, b"\x0c")
    chip.write(0x6A, b"\xc0")


def test_a_driver_that_skips_the_configuration_is_caught():
    chip = fw.Mpu6050Emulator()
    assert chip.set_dmp_reference(FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES)
    old_driver_sequence(chip, FAKE_IMAGE)
    assert chip.dmp_enabled and not chip.dmp_configured
    # The rate write lands where configuration entry 1 was due.
    assert chip.dmp_status.startswith("configuration entry 1 of 24 (bank 1 offset 0x0B, byte 1) "
                                      "was due; got a write at bank 2 offset 0x16")
    assert chip.push_fifo(dmp_packet((1, 0, 0, 0)), True) == 0 and chip.fifo_count == 0


def test_without_the_rate_write_the_emulator_says_what_is_missing():
    chip = fw.Mpu6050Emulator()
    assert chip.set_dmp_reference(FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES)
    upload_image(chip, FAKE_IMAGE)
    chip.write(0x6A, b"\xc0")
    assert chip.dmp_status == ("configuration: 0 of 24 entries applied; entry 1 (bank 1 offset "
                               "0x0B) not written")
    assert chip.push_fifo(dmp_packet((1, 0, 0, 0)), True) == 0


def test_configuration_entries_out_of_order_are_named():
    chip = fw.Mpu6050Emulator()
    assert chip.set_dmp_reference(FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES)
    upload_image(chip, FAKE_IMAGE)
    entries = table_entries(FAKE_CONFIG, specials=True)
    bank, offset, data = entries[1]                             # entry 2 before entry 1
    chip.write(0x6D, bytes([bank]))
    chip.write(0x6E, bytes([offset]))
    chip.write(0x6F, data)
    assert chip.dmp_status.endswith("(entry 2's address)")
    assert not chip.dmp_configured


def test_the_special_entry_must_come_in_its_place():
    # A configuration whose special entry (INT_ENABLE = 0x32) is skipped: the next memory
    # write is refused, and the reason names the special entry.
    chip = fw.Mpu6050Emulator()
    assert chip.set_dmp_reference(FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES)
    entries = table_entries(FAKE_CONFIG, specials=True)
    special = next(i for i, e in enumerate(entries) if not isinstance(e[2], bytes))
    without = b"".join(bytes([b, o, len(d)]) + d if isinstance(d, bytes) else bytes([b, o, 0, d])
                       for i, (b, o, d) in enumerate(entries) if i != special)
    drv = fw.Mpu6050(FAKE_IMAGE, without, FAKE_UPDATES)
    assert drv.init(chip) == fw.InitResult.OK_DMP         # the driver cannot know
    assert not chip.dmp_configured
    assert f"entry {special + 1} of 24 (special 0x01: INT_ENABLE = 0x32) was due" in chip.dmp_status
    assert chip.push_fifo(dmp_packet((1, 0, 0, 0)), True) == 0


def test_after_a_reset_the_whole_sequence_is_needed_again():
    chip, drv, _ = init()
    chip.power_on_reset()
    assert not chip.dmp_configured and chip.dmp_progress == (0, 0, 0)
    assert drv.probe(chip) == fw.ImuHealth.UNCONFIGURED
    assert drv.init(chip) == fw.InitResult.OK_DMP and chip.dmp_configured


@pytest.mark.parametrize("parts, step", [
    ((FAKE_IMAGE, b"", b""), fw.DmpStep.TABLES),                  # the image alone
    ((FAKE_IMAGE, FAKE_CONFIG[:-1], FAKE_UPDATES), fw.DmpStep.TABLES),   # runs past its end
    ((FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES[:-7]), fw.DmpStep.TABLES),   # six updates
    ((FAKE_IMAGE, FAKE_CONFIG[:-5] + bytes([0, 0, 0, 0x02]), FAKE_UPDATES),
     fw.DmpStep.TABLES),                                          # an unknown special command
])
def test_missing_or_malformed_tables_fall_back_to_the_raw_path(parts, step):
    chip = fw.Mpu6050Emulator()
    drv = fw.Mpu6050(*parts)
    assert drv.init(chip) == fw.InitResult.OK_RAW_FALLBACK and drv.dmp_failure == step
    assert drv.mode == fw.SensorMode.RAW and chip.raw_fifo_enabled
    assert drv.sample_rate_hz == pytest.approx(200.0)


@pytest.mark.parametrize("stuck, step", [
    (100, fw.DmpStep.IMAGE),                          # a byte of the image
    (1 * 256 + 0x0B, fw.DmpStep.CONFIG),              # the first configuration entry's first byte
    (0 * 256 + 0x80, fw.DmpStep.UPDATES),             # the first update's first byte
])
def test_a_write_that_does_not_read_back_falls_back_to_the_raw_path(stuck, step):
    chip, drv = chip_and_driver()
    if step != fw.DmpStep.IMAGE:                      # stuck at the image's value: it verifies
        chip.write(0x6D, bytes([stuck // 256]))
        chip.write(0x6E, bytes([stuck % 256]))
        chip.write(0x6F, FAKE_IMAGE[stuck:stuck + 1])
    chip.set_stuck_memory_byte(stuck)
    assert drv.init(chip) == fw.InitResult.OK_RAW_FALLBACK and drv.dmp_failure == step
    assert drv.mode == fw.SensorMode.RAW and chip.raw_fifo_enabled and not chip.dmp_enabled
    chip.push_fifo(raw_packet((0, 0, 1), (0, 0, 0)), False)
    assert drv.poll(chip) is not None


def test_without_an_image_the_raw_path_flies():
    chip, drv, result = init(None)
    assert result == fw.InitResult.OK_RAW and chip.raw_fifo_enabled
    assert drv.dmp_failure == fw.DmpStep.NONE
    chip.push_fifo(raw_packet((0, 0, 1), (1, 2, 3)), False)
    s = drv.poll(chip)
    assert not s.has_attitude
    counts = [round(g * GYRO_LSB) for g in (1, 2, 3)]          # 16, 33, 49 LSB
    expected = [math.radians(c / GYRO_LSB) * sign for c, sign in zip(counts, (1, -1, -1))]
    assert s.gyro_rad_s.to_list() == pytest.approx(expected, rel=1e-6)


def test_missing_chip_is_reported():
    chip, drv = chip_and_driver()
    chip.set_present(False)
    assert drv.init(chip) == fw.InitResult.NO_DEVICE


def test_a_reference_that_does_not_parse_is_refused():
    chip = fw.Mpu6050Emulator()
    assert not chip.set_dmp_reference(FAKE_IMAGE, FAKE_CONFIG[:-1], FAKE_UPDATES)
    assert chip.dmp_status.startswith("no reference DMP firmware")


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


@pytest.mark.parametrize("gyro_dps, accel_g, gyro_clipped, accel_clipped", [
    ((1, 2, 3), (0, 0, 1), False, False),
    ((2000, 0, 0), (0, 0, 1), True, False),       # +2000 deg/s: the gyro's last count
    ((0, -2000, 0), (0, 0, 1), True, False),      # -2000 deg/s is -32800 LSB: clamped to -32768
    ((0, 0, 0), (0, 0, 2), False, True),          # +2 g: the accelerometer's last count
    ((1990, 0, 0), (1.99, 0, 0), False, False),   # just inside both ranges
])
def test_a_sample_at_full_scale_says_it_is_clipped(gyro_dps, accel_g, gyro_clipped, accel_clipped):
    # A clipped rate is not the vehicle's rate: the driver flags the sample (the firmware
    # reports it in HQ_SYSID_SAMPLE.saturation), on the raw path and the DMP path alike.
    def clamp(v):
        return max(-32768, min(32767, v))
    raw = struct.pack(">3h3h", *[clamp(int(round(a * ACCEL_LSB))) for a in accel_g],
                      *[clamp(int(round(g * GYRO_LSB))) for g in gyro_dps])
    chip, drv, _ = init(None)
    chip.push_fifo(raw, False)
    s = drv.poll(chip)
    assert (s.gyro_clipped, s.accel_clipped) == (gyro_clipped, accel_clipped)
    packet = bytearray(dmp_packet((1, 0, 0, 0)))
    for i in range(3):
        packet[16 + 4 * i:18 + 4 * i] = raw[6 + 2 * i:8 + 2 * i]
        packet[28 + 4 * i:30 + 4 * i] = raw[2 * i:2 + 2 * i]
    s = fw.Mpu6050.parse_dmp_packet(bytes(packet))
    assert (s.gyro_clipped, s.accel_clipped) == (gyro_clipped, accel_clipped)

"""A made-up DMP firmware of MotionApps 2.0's shape, for tests: an image of the real one's
length and two tables with the real ones' sizes and form (bank, offset, length, data; the
special entry 0x01; the FIFO rate entry at bank 2, offset 0x16, last; seven updates). The real
firmware is InvenSense's and is never in this repository; the emulated chip runs no DMP code,
so any firmware of the right form exercises the driver's set-up and the emulator's check."""

from heliquad import _firmware as fw
from heliquad.host.commands.dmp_image import DmpFirmware, pack_dmp_file

FAKE_IMAGE = bytes((i * 7 + 3) & 0xFF for i in range(1929))


def _config() -> bytes:
    entries = []
    for i in range(22):                      # 21 entries of 5 bytes, one of 12: 183 bytes
        n = 12 if i == 21 else 5
        entries.append(bytes([1 + i % 6, (i * 37 + 11) % 200, n])
                       + bytes((i * 31 + j * 7 + 5) & 0xFF for j in range(n)))
    entries.insert(16, bytes([0x00, 0x00, 0x00, 0x01]))      # special: INT_ENABLE = 0x32
    entries.append(bytes([0x02, 0x16, 0x02, 0x00, 0x09]))    # the FIFO rate divisor
    return b"".join(entries)


def _updates() -> bytes:
    return b"".join(bytes([i % 2, 0x80 + 8 * i, n]) + bytes((0x40 + i * 5 + j) & 0xFF
                                                            for j in range(n))
                    for i, n in enumerate((4, 4, 4, 4, 4, 4, 2)))


FAKE_CONFIG = _config()
FAKE_UPDATES = _updates()
FAKE_DMP = DmpFirmware(FAKE_IMAGE, FAKE_CONFIG, FAKE_UPDATES)
assert (len(FAKE_CONFIG), len(FAKE_UPDATES)) == (192, 47)


def write_fake_dmp(path) -> str:
    """Writes the made-up firmware as `heliquad dmp-image` would; returns the path."""
    with open(path, "wb") as fh:
        fh.write(pack_dmp_file(FAKE_DMP))
    return str(path)


def chip_and_driver(dmp=FAKE_DMP, driver_dmp=None, dmp_rate_div=0):
    """An emulated chip that is to run `dmp`, and a driver given `driver_dmp` (default the
    same; None parts are not given)."""
    chip = fw.Mpu6050Emulator()
    if dmp is not None:
        assert chip.set_dmp_reference(dmp.image, dmp.config, dmp.updates)
    given = dmp if driver_dmp is None else driver_dmp
    parts = (given.image, given.config, given.updates) if given is not None else (b"", b"", b"")
    return chip, fw.Mpu6050(*parts, dmp_rate_div=dmp_rate_div)

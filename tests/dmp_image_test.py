"""The DMP firmware's way into the firmware: extraction (heliquad dmp-image), the file format
(docs/file-formats.md), run-time loading (heliquad-fw-host --dmp-image) and build-time
embedding (CMake HQ_DMP_IMAGE). The firmware here is made up, in the same form as the mpu6050
package's MPUConstants.py; the real one is not in this repository. One test runs on the real
package when it is on this machine."""

import importlib.metadata
import pathlib
import re
import shutil
import struct
import subprocess
import sys
import zipfile
import zlib

import pytest

from fake_dmp import FAKE_CONFIG, FAKE_DMP, FAKE_IMAGE, FAKE_UPDATES, write_fake_dmp
from heliquad import _firmware as fw
from heliquad.host.commands.dmp_image import (pack_dmp_file, read_dmp_file, read_dmp_firmware,
                                              table_entries, unpack_dmp_file)
from heliquad.sim.base.errors import InputError
from heliquad.sim.rig.lockstep import FirmwareError, HostFirmware

ROOT = pathlib.Path(__file__).resolve().parents[1]
REAL_WHEEL = "/tmp/mpu/mpu6050-0.0.3-py3-none-any.whl"


def constants_py(image=FAKE_IMAGE, config=FAKE_CONFIG, updates=FAKE_UPDATES):
    return ("class MPUConstants:\n    MPU6050_DMP_CODE_SIZE = 1929\n"
            f"    dmpMemory = {list(image)!r}\n    dmpConfig = {list(config)!r}\n"
            f"    dmpUpdates = {list(updates)!r}\n")


def test_reads_the_three_lists_without_importing(tmp_path):
    src = tmp_path / "MPUConstants.py"
    src.write_text("import smbus  # would fail on import\n" + constants_py())
    assert read_dmp_firmware(str(src)) == FAKE_DMP
    whl = tmp_path / "mpu6050-0.0.3-py3-none-any.whl"
    with zipfile.ZipFile(whl, "w") as z:
        z.writestr("mpu6050/MPUConstants.py", constants_py())
    assert read_dmp_firmware(str(whl)) == FAKE_DMP


@pytest.mark.parametrize("change, message", [
    ({"image": FAKE_IMAGE[:100]}, "dmpMemory has 100 entries; expected 1929"),
    ({"config": FAKE_CONFIG[:191]}, "dmpConfig has 191 entries; expected 192"),
    ({"config": FAKE_CONFIG[:-5] + bytes([2, 0x16, 3, 0, 9])}, "runs past the end"),
    ({"updates": FAKE_UPDATES[:-5] + bytes([1, 0x10, 0, 1, 0])}, "special command 0x01"),
])
def test_tables_of_the_wrong_size_or_form_are_refused(change, message, tmp_path):
    src = tmp_path / "MPUConstants.py"
    src.write_text(constants_py(**change))
    with pytest.raises(InputError, match=message):
        read_dmp_firmware(str(src))


def test_the_file_round_trips_and_its_header_is_as_documented():
    data = pack_dmp_file(FAKE_DMP)
    assert len(data) == 16 + 1929 + 192 + 47
    magic, version, n_image, n_config, n_updates, crc = struct.unpack_from("<4sHHHHI", data)
    assert (magic, version, n_image, n_config, n_updates) == (b"HQDM", 1, 1929, 192, 47)
    assert crc == zlib.crc32(data[:12] + data[16:])
    assert data[16:] == FAKE_IMAGE + FAKE_CONFIG + FAKE_UPDATES
    assert unpack_dmp_file(data) == FAKE_DMP


@pytest.mark.parametrize("damage, message", [
    (lambda d: FAKE_IMAGE, "bare 1929-byte DMP image .* regenerate it with heliquad dmp-image"),
    (lambda d: b"XXXX" + d[4:], "no HQDM magic"),
    (lambda d: d[:4] + b"\x02\x00" + d[6:], "version 2; this heliquad reads version 1"),
    (lambda d: d[:-1], "its header says 2184 .truncated"),
    (lambda d: d[:100] + bytes([d[100] ^ 1]) + d[101:], "CRC-32 mismatch"),
])
def test_a_bad_file_is_one_clear_line(damage, message, tmp_path):
    bad = tmp_path / "dmp.bin"
    bad.write_bytes(damage(pack_dmp_file(FAKE_DMP)))
    with pytest.raises(InputError, match=message) as err:
        read_dmp_file(str(bad))
    assert "\n" not in str(err.value)


def test_cli_writes_the_file_and_refuses_a_wrong_source(tmp_path):
    good, bad = tmp_path / "good.py", tmp_path / "bad.py"
    good.write_text(constants_py())
    bad.write_text(constants_py(image=FAKE_IMAGE[:100]))
    cli = [sys.executable, "-m", "heliquad.host.cli.parser", "dmp-image"]
    res = subprocess.run(cli + ["--source", str(good), "--out", str(tmp_path / "d.bin")],
                         capture_output=True, text=True)
    assert res.returncode == 0 and "image 1929, configuration 192, updates 47" in res.stdout
    assert read_dmp_file(str(tmp_path / "d.bin")) == FAKE_DMP
    res = subprocess.run(cli + ["--source", str(bad), "--out", str(tmp_path / "e.bin")],
                         capture_output=True, text=True)
    assert res.returncode == 2 and "expected 1929" in res.stderr and "Traceback" not in res.stderr


def test_run_time_file_puts_the_firmware_on_the_dmp_path(tmp_path):
    with HostFirmware(dmp_image=write_fake_dmp(tmp_path / "dmp.bin")) as fw_host:
        assert fw_host.imu_mode == "dmp"


def test_run_time_bare_image_is_refused_with_one_line_saying_to_regenerate(tmp_path):
    old = tmp_path / "old.bin"
    old.write_bytes(FAKE_IMAGE)
    with pytest.raises(FirmwareError, match="heliquad-fw-host: .*old.bin: a bare "
                                            "1929-byte DMP image .*regenerate it with heliquad "
                                            "dmp-image"):
        HostFirmware(dmp_image=str(old))


def _cmake(tmp_path, image):
    build = tmp_path / "build"
    return subprocess.run(["cmake", "-S", ROOT / "firmware", "-B", build, f"-DHQ_DMP_IMAGE={image}",
                           f"-DPython3_EXECUTABLE={sys.executable}"], capture_output=True,
                          text=True, timeout=300), build


def test_build_time_file_puts_the_firmware_on_the_dmp_path(tmp_path):
    if not (shutil.which("cmake") and shutil.which("c++")):
        pytest.skip("needs cmake and a C++ compiler")
    res, build = _cmake(tmp_path, write_fake_dmp(tmp_path / "dmp.bin"))
    assert res.returncode == 0, res.stderr
    assert "image 1929, configuration 192, updates 47 bytes" in res.stdout
    subprocess.run(["cmake", "--build", build, "--target", "heliquad-fw-host", "-j2"],
                   check=True, capture_output=True, timeout=600)
    res = subprocess.run([build / "heliquad-fw-host", "--sim-link", tmp_path / "s",
                          "--telemetry", tmp_path / "t", "--idle-timeout-s", "1"],
                         capture_output=True, text=True, timeout=30)
    assert "imu: dmp" in res.stdout and res.returncode == 3


@pytest.mark.parametrize("content, message", [
    (FAKE_IMAGE, "bare 1929-byte DMP image .* regenerate it with heliquad dmp-image"),
    (pack_dmp_file(FAKE_DMP)[:-1], "has 2183 bytes; its header says 2184"),
    (pack_dmp_file(FAKE_DMP)[:-1] + b"\x00", "CRC-32 mismatch"),
])
def test_build_time_bad_file_stops_the_configuration(content, message, tmp_path):
    if not shutil.which("cmake"):
        pytest.skip("needs cmake")
    bad = tmp_path / "dmp.bin"
    bad.write_bytes(content)
    res, _ = _cmake(tmp_path, bad)
    assert res.returncode != 0
    assert re.search(message, " ".join(res.stderr.split()))    # CMake wraps its messages


def _real_source():
    if pathlib.Path(REAL_WHEEL).is_file():
        return REAL_WHEEL
    try:
        importlib.metadata.files("mpu6050")
        return None                                  # the installed package
    except importlib.metadata.PackageNotFoundError:
        return False


@pytest.mark.skipif(_real_source() is False,
                    reason=f"the mpu6050 0.0.3 package is neither at {REAL_WHEEL} nor installed "
                           "(pip install mpu6050==0.0.3 --no-deps)")
def test_the_real_package_extracts_and_the_emulated_chip_takes_its_sequence():
    real = read_dmp_firmware(_real_source())
    assert (len(real.image), len(real.config), len(real.updates)) == (1929, 192, 47)
    config = table_entries(real.config, specials=True)
    updates = table_entries(real.updates, specials=False)
    assert len(config) == 30 and len(updates) == 7
    specials = [(b, o, d) for b, o, d in config if not isinstance(d, bytes)]
    assert specials == [(0, 0, 0x01)]                   # INT_ENABLE = 0x32
    assert config[-1][:2] == (2, 0x16) and len(config[-1][2]) == 2   # the FIFO rate, last
    assert unpack_dmp_file(pack_dmp_file(real)) == real
    chip = fw.Mpu6050Emulator()
    assert chip.set_dmp_reference(real.image, real.config, real.updates)
    driver = fw.Mpu6050(real.image, real.config, real.updates)
    assert driver.init(chip) == fw.InitResult.OK_DMP
    assert chip.dmp_configured and chip.dmp_progress == (1929, 30, 7)

"""The DMP image's way into the firmware: extraction (heliquad dmp-image) and build-time
embedding (CMake HQ_DMP_IMAGE). The image here is a made-up pattern in the same form as the
mpu6050 package's MPUConstants.py; the real one is not in this repository."""

import pathlib
import shutil
import subprocess
import sys
import zipfile

import pytest

from heliquad.host.dmp_image import read_dmp_image

ROOT = pathlib.Path(__file__).resolve().parents[1]
IMAGE = bytes((i * 7 + 3) & 0xFF for i in range(1929))


def constants_py(values):
    return ("class MPUConstants:\n    MPU6050_DMP_CODE_SIZE = 1929\n"
            f"    dmpMemory = {list(values)!r}\n    dmpConfig = [3, 123]\n")


def test_reads_the_list_without_importing(tmp_path):
    src = tmp_path / "MPUConstants.py"
    src.write_text("import smbus  # would fail on import\n" + constants_py(IMAGE))
    assert read_dmp_image(str(src)) == IMAGE
    whl = tmp_path / "mpu6050-0.0.3-py3-none-any.whl"
    with zipfile.ZipFile(whl, "w") as z:
        z.writestr("mpu6050/MPUConstants.py", constants_py(IMAGE))
    assert read_dmp_image(str(whl)) == IMAGE


def test_cli_writes_the_image_and_refuses_a_wrong_one(tmp_path):
    good, bad = tmp_path / "good.py", tmp_path / "bad.py"
    good.write_text(constants_py(IMAGE))
    bad.write_text(constants_py(IMAGE[:100]))
    cli = [sys.executable, "-m", "heliquad.host.cli", "dmp-image"]
    res = subprocess.run(cli + ["--source", str(good), "--out", str(tmp_path / "d.bin")],
                         capture_output=True, text=True)
    assert res.returncode == 0 and (tmp_path / "d.bin").read_bytes() == IMAGE
    res = subprocess.run(cli + ["--source", str(bad), "--out", str(tmp_path / "e.bin")],
                         capture_output=True, text=True)
    assert res.returncode == 2 and "expected 1929" in res.stderr and "Traceback" not in res.stderr


def test_build_time_image_puts_the_firmware_on_the_dmp_path(tmp_path):
    if not (shutil.which("cmake") and shutil.which("c++")):
        pytest.skip("needs cmake and a C++ compiler")
    image = tmp_path / "dmp.bin"
    image.write_bytes(IMAGE)
    build = tmp_path / "build"
    subprocess.run(["cmake", "-S", ROOT / "firmware", "-B", build, f"-DHQ_DMP_IMAGE={image}",
                    f"-DPython3_EXECUTABLE={sys.executable}"], check=True, capture_output=True,
                   timeout=300)
    subprocess.run(["cmake", "--build", build, "--target", "heliquad-fw-host", "-j2"],
                   check=True, capture_output=True, timeout=600)
    res = subprocess.run([build / "heliquad-fw-host", "--sim-link", tmp_path / "s",
                          "--telemetry", tmp_path / "t", "--idle-timeout-s", "1"],
                         capture_output=True, text=True, timeout=30)
    assert "imu: dmp" in res.stdout and res.returncode == 3

"""The firmware core compiles for the Teensy 3.5 (Cortex-M4F) with the ARM cross compiler.

-fno-exceptions -fno-rtti and -Werror: nothing host-only may creep into the core. The static
library must also hold no writable data (.data/.bss): the core has no globals. In CI
(CI=true) a missing toolchain fails the test; elsewhere it skips with the install hint.
"""

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
TOOLCHAIN = ROOT / "firmware" / "cmake" / "arm-none-eabi.cmake"


def require_toolchain():
    if shutil.which("arm-none-eabi-g++") and shutil.which("cmake"):
        return
    message = ("arm-none-eabi-g++ not found: apt-get install gcc-arm-none-eabi "
               "libnewlib-arm-none-eabi libstdc++-arm-none-eabi-dev")
    if os.environ.get("CI"):
        pytest.fail(message)
    pytest.skip(message)


def test_core_builds_for_cortex_m4f(tmp_path):
    require_toolchain()
    build = tmp_path / "arm"
    subprocess.run(["cmake", "-S", ROOT / "firmware", "-B", build, f"--toolchain={TOOLCHAIN}",
                    "-DCMAKE_BUILD_TYPE=MinSizeRel"], check=True, capture_output=True, timeout=300)
    res = subprocess.run(["cmake", "--build", build, "-j2"], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    lib = build / "libhq_core.a"
    size = subprocess.run(["arm-none-eabi-size", "-t", lib], capture_output=True, text=True,
                          check=True).stdout.splitlines()[-1].split()
    text, data, bss = map(int, size[:3])
    assert text > 0 and data == 0 and bss == 0, size
    header = subprocess.run(["arm-none-eabi-readelf", "-A", lib], capture_output=True,
                            text=True, check=True).stdout
    assert "Tag_CPU_name: \"7E-M\"" in header or "Cortex-M4" in header or "v7E-M" in header
    assert "VFPv4-D16" in header and "VFP registers" in header   # hard float ABI

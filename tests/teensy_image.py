"""Builds the Teensy 3.5 image once per test session, with the CMake preset a user runs.

`image()` runs `cmake --preset teensy35` and `cmake --build --preset teensy35` (incremental:
cheap when nothing changed) and returns the paths. Without the ARM toolchain it skips with
the install hint, except in CI (CI set), where the image is required and the test fails.
"""

from __future__ import annotations

import functools
import os
import pathlib
import shutil
import subprocess
import sys
from dataclasses import dataclass

import pytest

from heliquad.sim.base.firmware_image import ARM_TOOLCHAIN_PACKAGES

ROOT = pathlib.Path(__file__).resolve().parents[1]
BUILD = ROOT / "build" / "teensy35"
INSTALL_HINT = f"arm-none-eabi-g++ not found: apt-get install {ARM_TOOLCHAIN_PACKAGES}"


@dataclass(frozen=True)
class Image:
    elf: pathlib.Path
    hex: pathlib.Path
    map: pathlib.Path
    core_lib: pathlib.Path
    link_command: pathlib.Path


def require_toolchain() -> None:
    if shutil.which("arm-none-eabi-g++") and shutil.which("cmake"):
        return
    if os.environ.get("CI"):
        pytest.fail(INSTALL_HINT)
    pytest.skip(INSTALL_HINT)


def build_preset(binary_dir: pathlib.Path = BUILD, defines: tuple = ()) -> tuple[int, str]:
    """Configure and build the teensy35 preset into binary_dir (its own folder by default),
    with extra -D definitions; (exit code, output). The preset's build runs mavgen with the
    Python that CMake finds: point it at this one (it has pymavlink), whatever the PATH says."""
    configure = subprocess.run(
        ["cmake", "--preset", "teensy35", "-B", str(binary_dir),
         f"-DPython3_EXECUTABLE={sys.executable}", *(f"-D{d}" for d in defines)],
        cwd=ROOT, capture_output=True, text=True, timeout=600)
    if configure.returncode != 0:
        return configure.returncode, configure.stdout + configure.stderr
    build = subprocess.run(["cmake", "--build", str(binary_dir), "-j2"], cwd=ROOT,
                           capture_output=True, text=True, timeout=1200)
    return build.returncode, build.stdout + build.stderr


@functools.lru_cache(maxsize=1)
def _build() -> tuple[int, str]:
    return build_preset()


def image() -> Image:
    require_toolchain()
    rc, log = _build()
    assert rc == 0, log[-4000:]
    return Image(elf=BUILD / "heliquad-fw-teensy35.elf", hex=BUILD / "heliquad-fw-teensy35.hex",
                 map=BUILD / "heliquad-fw-teensy35.map",
                 core_lib=BUILD / "firmware" / "libhq_core.a",
                 link_command=BUILD / "firmware" / "targets" / "teensy35" / "CMakeFiles"
                 / "heliquad-fw-teensy35.dir" / "link.txt")

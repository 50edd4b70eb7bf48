"""Where the Teensy 3.5 image is (interim: the in-tree preset build or HQ_TEENSY35_ELF)."""

from __future__ import annotations

import os
import pathlib

from .lockstep import FirmwareError

ROOT = pathlib.Path(__file__).resolve().parents[1]


class ImageNotFound(FirmwareError):
    pass


def teensy35_image(kind: str = "elf") -> pathlib.Path:
    env = os.environ.get("HQ_TEENSY35_ELF") if kind == "elf" else None
    for path in ([pathlib.Path(env)] if env else []) + [
            ROOT / "build" / "teensy35" / f"heliquad-fw-teensy35.{kind}"]:
        if path.is_file():
            return path
    raise ImageNotFound("the Teensy 3.5 image is not built: cmake --preset teensy35 && "
                        "cmake --build --preset teensy35")

"""The two firmwares a lockstep test can fly (not a test module: a helper the tests import).

``host``: the host build, heliquad-fw-host. ``teensy35``: the Teensy 3.5 image as flashed,
in the emulated MK64FX512 (heliquad.sim.chip.pil), the image built with the CMake preset by
tests/teensy_image.py (skipped without the ARM toolchain, except in CI, where it must be
there). Tests parametrised with :data:`FIRMWARES` run against both; the processor-in-the-
loop cases carry the ``pil`` mark, so ``pytest -m pil`` runs only them and ``-m "not pil"``
leaves them out.
"""

from __future__ import annotations

import pytest

import teensy_image
from heliquad.sim.rig.lockstep import HostFirmware, start_firmware

FIRMWARES = ["host", pytest.param("teensy35", marks=pytest.mark.pil)]


def start(name: str, **kwargs) -> HostFirmware:
    """Start the named firmware with HostFirmware's arguments (the Teensy image: the one the
    tests built)."""
    if name == "teensy35":
        kwargs["image"] = str(teensy_image.image().elf)
    return start_firmware(name, **kwargs)


def image_for(name: str) -> dict:
    """SilConfig/SilSession arguments that fly ``name`` (the image path for the PIL)."""
    if name == "teensy35":
        return {"firmware": name, "firmware_image": str(teensy_image.image().elf)}
    return {"firmware": name}

"""Where the Teensy 3.5 image is: the one finder every command uses (docs/teensy35.md).

:func:`teensy35_image` returns, in this order, the first of:

1. the file named by ``HQ_TEENSY35_ELF`` (for the .hex, the file beside it with the suffix
   ``.hex``); when the variable is set, nothing else is looked at;
2. the image installed in the package, ``heliquad/firmware/teensy35/`` (``pip install .``
   builds it when the ARM toolchain is there: firmware/cmake/teensy35_image.cmake);
3. the preset's build, ``build/teensy35/`` (``cmake --preset teensy35 && cmake --build --preset
   teensy35``) in the checkout this module runs from (an editable install or a source tree on
   ``sys.path``), then in the current directory when it is a heliquad checkout.

Otherwise it raises :class:`ImageNotFound`, whose message is one line saying how to get one.
"""

from __future__ import annotations

import os
import pathlib

import heliquad

from .errors import FirmwareError

__all__ = ["ENV_VAR", "IMAGE_NAME", "PACKAGE_DIR", "ImageNotFound", "teensy35_image"]

#: Names the image to use instead of any other (the .hex is the file beside it).
ENV_VAR = "HQ_TEENSY35_ELF"
#: The image's file name without its suffix: ``heliquad-fw-teensy35.elf`` and ``.hex``.
IMAGE_NAME = "heliquad-fw-teensy35"
#: Where the install puts the image, relative to the ``heliquad`` package.
PACKAGE_DIR = ("firmware", "teensy35")
#: Where the teensy35 preset builds it, relative to a checkout.
PRESET_DIR = ("build", "teensy35")
KINDS = ("elf", "hex")

#: The Debian packages of the ARM toolchain the image needs.
ARM_TOOLCHAIN_PACKAGES = "gcc-arm-none-eabi libnewlib-arm-none-eabi libstdc++-arm-none-eabi-dev"
HOW_TO_GET_IT = (f"install the ARM toolchain (apt-get install {ARM_TOOLCHAIN_PACKAGES}) "
                 "and reinstall heliquad "
                 "(pip install .), or build it from the repository with "
                 "cmake --preset teensy35 && cmake --build --preset teensy35")


class ImageNotFound(FirmwareError):
    """No Teensy 3.5 image where :func:`teensy35_image` looks; the message says how to get one."""


def teensy35_image(kind: str = "elf") -> pathlib.Path:
    """The Teensy 3.5 image's .elf or .hex (``kind``), looked for in the module's order."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, not {kind!r}")
    name = f"{IMAGE_NAME}.{kind}"
    override = os.environ.get(ENV_VAR)
    if override:
        path = pathlib.Path(override)
        if kind != "elf":
            path = path.with_suffix(f".{kind}")
        if path.is_file():
            return path
        raise ImageNotFound(f"no Teensy 3.5 image at {path} ({ENV_VAR}={override}): point "
                            f"{ENV_VAR} at a built .elf (with its .hex beside it) or unset it; "
                            f"to get one, {HOW_TO_GET_IT}")
    installed = _installed(name)
    if installed is not None:
        return installed
    for root in _checkouts():
        path = root.joinpath(*PRESET_DIR, name)
        if path.is_file():
            return path
    raise ImageNotFound(f"no Teensy 3.5 image ({name}) installed or built: {HOW_TO_GET_IT}")


def _installed(name: str) -> pathlib.Path | None:
    """The package's copy: heliquad/firmware/teensy35/ in a portion of the ``heliquad``
    namespace package (an editable install has two: site-packages and the checkout)."""
    for portion in _package_portions():
        path = pathlib.Path(portion).joinpath(*PACKAGE_DIR, name)
        if path.is_file():
            return path
    return None


def _package_portions() -> list[str]:
    return list(heliquad.__path__)


#: The checkout this module belongs to, when it runs from one (editable install, source tree).
_SOURCE_ROOT = pathlib.Path(__file__).resolve().parents[1]


def _checkouts() -> list[pathlib.Path]:
    """Source trees to look in: the one holding this module, then the current directory; each
    only if it is a heliquad checkout."""
    here = [_SOURCE_ROOT]
    try:
        here.append(pathlib.Path.cwd())
    except OSError:                              # the current directory was removed
        pass
    roots = []
    for root in here:
        if _is_checkout(root) and root not in roots:
            roots.append(root)
    return roots


def _is_checkout(root: pathlib.Path) -> bool:
    """Whether ``root`` is a heliquad source tree (where the teensy35 preset builds)."""
    return ((root / "CMakePresets.json").is_file()
            and (root / "firmware" / "targets" / "teensy35").is_dir())

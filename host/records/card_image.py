"""Card images: the host build's SD card as a file (docs/file-formats.md, "Card image";
docs/sd-card.md). A card image is the card's 512-byte blocks one after another, formatted
FAT32 by FatFs's own f_mkfs (through the firmware's bindings) with the volume at byte 0 (no
partition table), so fsck.fat and mtools read the file as it is. The logs the firmware writes
on it are LOGS/00000001.BIN ... and LASTLOG.TXT.
"""

from __future__ import annotations

import contextlib
import os
import re

from heliquad import _firmware

from ...sim.base.errors import DiskFull, InputError
from .output import check_output

__all__ = ["DEFAULT_BYTES", "MIN_BYTES", "MAX_BYTES", "parse_size", "write_card_image"]

#: The sizes a card image may have, and the one it gets when none is asked for (the
#: firmware's: targets/host/card_image.hpp says why).
DEFAULT_BYTES = _firmware.DEFAULT_CARD_IMAGE_BYTES
MIN_BYTES, MAX_BYTES = _firmware.MIN_CARD_IMAGE_BYTES, _firmware.MAX_CARD_IMAGE_BYTES
#: A size's unit suffixes: binary multiples (a card's MiB), none for bytes.
UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30}


def parse_size(text: str) -> int:
    """Bytes from "64M", "1G", "41943040" (K, M, G: KiB, MiB, GiB); InputError for anything
    else, or a size a FAT32 card image cannot have."""
    m = re.fullmatch(r"\s*(\d+)\s*([KMG]?)(?:i?B)?\s*", text, re.IGNORECASE)
    if m is None:
        raise InputError(f"--size {text}: not a size (bytes, or a number with K, M or G)")
    size = int(m.group(1)) * UNITS[m.group(2).upper()]
    if size % 512:
        raise InputError(f"--size {text}: not a whole number of 512-byte blocks")
    if not MIN_BYTES <= size <= MAX_BYTES:
        raise InputError(f"--size {text}: a FAT32 card image is {MIN_BYTES >> 20} MiB to "
                         f"{MAX_BYTES >> 30} GiB")
    return size


def write_card_image(path, size_bytes: int) -> None:
    """A fresh FAT32 card image of ``size_bytes`` at ``path``, made beside it and renamed over
    it at the end (a failure leaves what was there). InputError or DiskFull in one line."""
    path = os.fspath(path)
    check_output(path, "FILE")
    tmp = os.path.join(os.path.dirname(os.path.abspath(path)),
                       f".{os.path.basename(path)}.{os.getpid()}.tmp")
    try:
        error = _firmware.make_card_image(tmp, size_bytes)
        if error:
            raise InputError(error.replace(tmp, path))
        os.replace(tmp, path)
    except OSError as exc:
        raise (DiskFull(f"{path}: no room on the disk") if exc.errno == 28
               else InputError(f"{path}: {exc.strerror}")) from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)

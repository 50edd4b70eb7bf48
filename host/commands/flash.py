"""``heliquad flash``: write the firmware image to a Teensy 3.5 with teensy_loader_cli.

The image is checked before anything is sent to the board: it must be an Intel HEX file that
fits the MK64FX512's 512 KiB of flash, start with a vector table (initial stack pointer in
SRAM, a Thumb reset vector inside the image) and carry a flash configuration field that
leaves the chip unsecured. A secured chip refuses the bootloader's reprogramming and is
mass-erased by the next button press, so such an image is refused outright.

Then ``teensy_loader_cli --mcu=TEENSY35 -w -s -v HEX`` runs (Debian/Ubuntu package
teensy-loader-cli). Its ``-s`` (soft reboot) sets 134 baud on the board's USB serial port
(16C0:0483): a heliquad image that runs and is disarmed enters its bootloader by itself; an
armed one refuses (its STATUSTEXT says "bootloader refused: armed (disarm first)"). The
loader then waits for the bootloader: press the Teensy's program button when the board does
not reboot by itself (firmware without USB Serial, a hung board, an armed one).
--no-soft-reboot leaves ``-s`` out (``-w -v`` only) and the button is always needed.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from dataclasses import dataclass

from ...sim.base.errors import InputError
from ..process.signals import EXIT_CODES, WORDS, stopped_by

__all__ = ["ImageInfo", "check_image", "default_image", "default_hex", "add_parser"]

FLASH_SIZE = 512 * 1024                      # MK64FX512
SRAM_LOW, SRAM_HIGH = 0x1FFF0000, 0x20020000  # SRAM_L + SRAM_U, 192 KiB
FLASH_CONFIG = 0x400                         # 16 bytes: key, FPROT, FSEC, FOPT, FEPROT, FDPROT
FSEC_UNSECURE = 0b10                         # FSEC.SEC


@dataclass(frozen=True)
class ImageInfo:
    path: str
    size: int            # bytes of data in the image
    top: int             # highest address + 1
    initial_sp: int
    reset_vector: int
    fsec: int
    fopt: int

    @property
    def usage(self) -> float:
        return self.size / FLASH_SIZE


def check_image(path: str) -> ImageInfo:
    """Read and check a Teensy 3.5 image; InputError with the reason when it is not one."""
    # intelhex only to read an image: --help imports every command module
    from intelhex import HexRecordError, IntelHex, IntelHexError

    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not an Intel HEX image")
    if not os.path.isfile(path):
        raise InputError(f"{path}: no such file")
    ih = IntelHex()
    try:
        ih.loadhex(path)
    except (HexRecordError, IntelHexError, ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not an Intel HEX file ({exc.__class__.__name__})") from None
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None
    addresses = ih.addresses()
    present = set(addresses)        # (IntelHex has no membership test: `in` would iterate)
    if not addresses:
        raise InputError(f"{path}: the file holds no data")
    top = max(addresses) + 1
    if top > FLASH_SIZE:
        raise InputError(f"{path}: data up to 0x{top:X}, beyond the Teensy 3.5's 512 KiB of flash; "
                         "not a Teensy 3.5 image")
    missing = [a for a in (*range(8), *range(FLASH_CONFIG, FLASH_CONFIG + 16)) if a not in present]
    if missing:
        raise InputError(f"{path}: no vector table or flash configuration field at 0x{missing[0]:X}; "
                         "not a Teensy 3.5 image")
    sp = int.from_bytes(bytes(ih[a] for a in range(0, 4)), "little")
    reset = int.from_bytes(bytes(ih[a] for a in range(4, 8)), "little")
    if not (SRAM_LOW < sp <= SRAM_HIGH) or sp % 8:
        raise InputError(f"{path}: initial stack pointer 0x{sp:08X} is not 8-aligned inside the "
                         "Teensy 3.5's SRAM; not a Teensy 3.5 image")
    if not (reset & 1) or (reset & ~1) >= top or (reset & ~1) not in present:
        raise InputError(f"{path}: reset vector 0x{reset:08X} is not a Thumb address inside the "
                         "image; not a Teensy 3.5 image")
    fsec, fopt = ih[FLASH_CONFIG + 12], ih[FLASH_CONFIG + 13]
    if fsec & 0b11 != FSEC_UNSECURE:
        raise InputError(f"{path}: FSEC 0x{fsec:02X} would secure the chip (the bootloader could "
                         "not reprogram it again); refusing to flash")
    return ImageInfo(path=path, size=len(addresses), top=top, initial_sp=sp,
                     reset_vector=reset, fsec=fsec, fopt=fopt)


def default_image(kind: str, instead: str) -> str:
    """The image a command takes when none is given: the finder's .elf or .hex (``kind``;
    heliquad.sim.base.firmware_image: $HQ_TEENSY35_ELF, the installed image, the teensy35
    preset's build); when there is none, an InputError that also names ``instead``, what the
    user may give in its place."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.base.firmware_image import ImageNotFound, teensy35_image

    try:
        return str(teensy35_image(kind))
    except ImageNotFound as exc:
        raise InputError(f"{exc}, or give {instead}") from None


def default_hex() -> str:
    """The image to flash when none is given: the finder's .hex."""
    return default_image("hex", "HEX")


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("flash", help="flash the firmware image to a Teensy 3.5",
                       description=__doc__ + """
Without HEX, the image is the one the install built when the ARM toolchain was there
(heliquad/firmware/teensy35/ in the package), or the teensy35 preset's build
(build/teensy35/heliquad-fw-teensy35.hex), made from the repository with
  cmake --preset teensy35 && cmake --build --preset teensy35
$HQ_TEENSY35_ELF, when set, names the image instead (its .hex beside it).
""", formatter_class=fmt)
    p.add_argument("hex", nargs="?", default=None, metavar="HEX",
                   help="the image (default: the installed or built heliquad-fw-teensy35.hex)")
    p.add_argument("--check-only", action="store_true",
                   help="check the image and print what would be flashed; do not flash")
    p.add_argument("--loader", default="teensy_loader_cli", metavar="PROGRAM",
                   help="the loader to run (default: teensy_loader_cli on the PATH)")
    p.add_argument("--no-soft-reboot", dest="soft_reboot", action="store_false",
                   help="do not ask a running board to reboot into its bootloader (the "
                        "loader's -s): press the program button instead")
    p.set_defaults(func=_cmd)


def _cmd(args) -> int:
    info = check_image(args.hex if args.hex is not None else default_hex())
    print(f"{info.path}: {info.size} bytes, {100 * info.usage:.1f}% of the Teensy 3.5's flash; "
          f"stack 0x{info.initial_sp:08X}, reset 0x{info.reset_vector:08X}, "
          f"FSEC 0x{info.fsec:02X} (unsecure), FOPT 0x{info.fopt:02X}")
    if args.check_only:
        return 0
    loader = shutil.which(args.loader)
    if loader is None:
        raise InputError(f"{args.loader} not found: install it (Debian/Ubuntu: apt-get install "
                         "teensy-loader-cli) or give --loader")
    soft_reboot = ["-s"] if args.soft_reboot else []
    cmd = [loader, "--mcu=TEENSY35", "-w", *soft_reboot, "-v", info.path]
    print("running: " + " ".join(cmd), flush=True)
    if args.soft_reboot:
        print("a running heliquad board that is disarmed reboots into its bootloader by itself",
              flush=True)
    print("press the program button on the Teensy if it does not start by itself", flush=True)
    try:
        rc = subprocess.run(cmd).returncode
    except KeyboardInterrupt as exc:             # Ctrl-C, SIGTERM, SIGHUP: the signal's code

        signum = stopped_by(exc)
        print(f"heliquad flash: {WORDS[signum]}; the board may hold a partial image: flash "
              "again", file=sys.stderr)
        return EXIT_CODES[signum]
    except OSError as exc:
        raise InputError(f"{loader}: {exc.strerror}") from None
    if rc != 0:
        print(f"heliquad flash: {os.path.basename(loader)} failed (exit {rc})", file=sys.stderr)
        return 1
    print("flashed; the board reboots into the new firmware")
    return 0

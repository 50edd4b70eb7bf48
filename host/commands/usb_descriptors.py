"""``heliquad usb-descriptors``: what a computer reads from the Teensy 3.5 image's USB port.

The image runs in the emulated MK64FX512 (heliquad.sim.chip) with a USB host on its USB0
port that enumerates it as Linux does: a bus reset, the device descriptor, the address, the
configuration descriptor with everything under it, the strings, SET_CONFIGURATION
(docs/teensy35-emulator.md). The descriptors it read are printed decoded: the device (USB
version, vendor and product IDs, EP0's packet size, its strings), the configuration, each
interface with its class, its CDC functional descriptors and its endpoints, and the
interface associations.

With --out DIR the two descriptors are written as the host read them: device.bin (the
device descriptor, 18 bytes) and config.bin (the configuration descriptor and all its
wTotalLength bytes). DIR must be new or empty, so no earlier file is overwritten.

An image whose USB port does not attach within 2 s of emulated time after reset
(firmware without USB), one that stops or faults first, or one whose enumeration fails, is
refused in one line (exit 2).
"""

from __future__ import annotations

import os

from ...sim.base.errors import InputError
from .flash import default_image

__all__ = ["ATTACH_WITHIN_S", "ENUMERATION_WITHIN_S", "DEVICE_FILE", "CONFIG_FILE",
           "enumerate_image", "add_parser"]

#: Emulated time from reset within which the image must turn its USB pull-up on: heliquad's
#: image does it once its start-up is done (clocks, the MPU6050, the parameters), about
#: 0.1 s after reset.
ATTACH_WITHIN_S = 2.0
#: Emulated time from the attach within which the enumeration must be done: Linux's 100 ms
#: debounce, two resets and ten control transfers take about 0.2 s.
ENUMERATION_WITHIN_S = 2.0
#: Emulated time the chip runs between two looks at the host.
STEP_S = 0.01
DEVICE_FILE, CONFIG_FILE = "device.bin", "config.bin"
ELF_MAGIC = b"\x7fELF"


def _board(path: str):
    """The image loaded into an emulated Teensy 3.5 with a USB host on its port (enumerating
    at attach); InputError when the file is not an image the chip can run."""
    # the command's work, imported when it runs: --help imports every command module
    from elftools.common.exceptions import ELFError

    from ...sim.chip import ImageError, Teensy35
    from ...sim.chip.usb_host import UsbHost

    if os.path.isdir(path):
        raise InputError(f"{path}: is a folder, not an ELF image")
    try:
        with open(path, "rb") as fh:
            magic = fh.read(len(ELF_MAGIC))
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror}") from None
    if magic != ELF_MAGIC:
        raise InputError(f"{path}: not an ELF file (give the image's .elf, not its .hex)")
    try:
        board = Teensy35(path, track_loops=False)
    except ImageError as exc:                       # its message names the file
        raise InputError(f"{exc}: not a Teensy 3.5 image") from None
    except ELFError as exc:
        raise InputError(f"{path}: a damaged ELF ({exc}): not a Teensy 3.5 image") from None
    return board, UsbHost(board.chip)


def enumerate_image(path: str):
    """Boot ``path`` in the emulated chip with the host on its USB port, and let the host
    enumerate it; the host (its ``device_bytes``, ``config_bytes``, ``transfers`` and
    ``identity()``). InputError, naming the file, when the port never attaches, the image
    stops or faults first, or the enumeration fails."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.chip import EmulationError
    from ...sim.chip.usb_host import UsbError, settle

    board, host = _board(path)

    def run_for(seconds):
        stop = board.run(seconds=seconds)
        if stop.reason != "time":
            raise InputError(f"{path}: the image stopped ({stop.reason} at 0x{stop.pc:08X}) "
                             "before its USB port was enumerated")

    try:
        waited_s = 0.0
        while not host.device_attached:
            if waited_s >= ATTACH_WITHIN_S:
                raise InputError(f"{path}: no USB device attached within {ATTACH_WITHIN_S:g} s "
                                 "of emulated time after reset: an image without a USB port?")
            run_for(STEP_S)
            waited_s += STEP_S
        settle(host, run_for, ENUMERATION_WITHIN_S, STEP_S)
    except UsbError as exc:
        raise InputError(f"{path}: the enumeration failed: {exc}") from None
    except EmulationError as exc:              # a fault, a lockup: the image's, not the tool's
        raise InputError(f"{path}: the image failed in the emulated chip: {exc}") from None
    return host


def describe_host(host) -> list:
    """What the host read, as the command prints it: the descriptors decoded, then the
    interface associations."""
    # the command's work, imported when it runs: --help imports every command module
    from ...sim.chip.usb_descriptors import describe

    identity = host.identity()
    lines = describe(identity)
    for first, count, cls, subclass, protocol in identity.configuration.associations:
        lines.append(f"  interface association: interfaces {first}-{first + count - 1}, class "
                     f"0x{cls:02X}/0x{subclass:02X}/0x{protocol:02X}")
    return lines


def add_parser(sub, fmt) -> None:
    p = sub.add_parser("usb-descriptors",
                       help="the Teensy 3.5 image's USB descriptors, read in the emulator",
                       description=__doc__ + """
Without --image, the image is the one heliquad flash takes (its .elf): $HQ_TEENSY35_ELF when
set, else the one the install built, else the teensy35 preset's build
(build/teensy35/heliquad-fw-teensy35.elf).
""", formatter_class=fmt)
    p.add_argument("--image", metavar="ELF",
                   help="the image (default: the installed or built heliquad-fw-teensy35.elf)")
    p.add_argument("--out", metavar="DIR",
                   help=f"write {DEVICE_FILE} and {CONFIG_FILE} here (a new or empty folder)")
    p.set_defaults(func=run)


def run(args) -> int:
    # the command's work, imported when it runs: --help imports every command module
    from ..records.output import atomic_write, new_output_folder

    path = args.image if args.image is not None else default_image("elf", "--image ELF")
    created = args.out is not None and new_output_folder(args.out, "each read of the descriptors")
    try:
        host = enumerate_image(path)
    except BaseException:
        if created and not os.listdir(args.out):     # nothing written: leave nothing behind
            os.rmdir(args.out)
        raise
    print(f"{path}: enumerated as Linux does ({len(host.transfers)} control transfers, "
          f"{host.machine.seconds():.3f} s of emulated time from reset)")
    for line in describe_host(host):
        print(line)
    if args.out is None:
        return 0
    for name, data in ((DEVICE_FILE, host.device_bytes), (CONFIG_FILE, host.config_bytes)):
        with atomic_write(os.path.join(args.out, name), "wb") as fh:
            fh.write(data)
    print(f"wrote {os.path.join(args.out, DEVICE_FILE)} ({len(host.device_bytes)} bytes) and "
          f"{os.path.join(args.out, CONFIG_FILE)} ({len(host.config_bytes)} bytes)")
    return 0

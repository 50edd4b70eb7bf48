"""The drop-in's command line (``python -m heliquad.sim.chip.pil``): its options, the start
(the board booted, the ptys published, ``ready``) and the run to its exit code."""

from __future__ import annotations

import argparse
import gc
import os
import signal
import sys

from heliquad import _firmware

from ...base.dialect import dialect
from ...base.firmware_image import ImageNotFound, teensy35_image
from ...rig.setup import DEFAULT_BOARD_LINK
from .board import IMAGE_LOOP_HZ, LINKS, ImageFault, PilBoard
from .drop_in import EXIT_IMAGE, EXIT_USAGE, DropIn, Stop
from .param_file import ParamFileError
from .pty import Pty


#: ``python`` runs every frame in the Python path, as the reference the native path's frames
#: are compared with (tests/pil_frames_test.py); ``native`` (the default) runs the plain
#: frames natively (native_frames.py).
FRAMES_VARIABLE = "HQ_PIL_FRAMES"


def native_frames() -> bool:
    """Whether the drop-in runs its plain frames natively (``HQ_PIL_FRAMES``); an unknown
    value is a usage error."""
    value = os.environ.get(FRAMES_VARIABLE, "native")
    if value not in ("native", "python"):
        _usage(f"{FRAMES_VARIABLE}={value}: native or python")
    return value == "native"


def _usage(message: str) -> None:
    print(f"heliquad-fw-pil: {message}", file=sys.stderr)
    sys.exit(EXIT_USAGE)


def parse(argv):
    p = argparse.ArgumentParser(
        prog="heliquad-fw-pil",
        description="The Teensy 3.5 image in the emulated MK64FX512, driven in lockstep like "
                    "heliquad-fw-host (the same sim-link and telemetry ptys).")
    p.add_argument("--sim-link", required=True, help="path for the sim link's pty symlink")
    p.add_argument("--telemetry", required=True, help="path for the telemetry pty symlink")
    p.add_argument("--image", help="the .elf (default: the image the install built)")
    p.add_argument("--link", choices=LINKS, default=DEFAULT_BOARD_LINK,
                   help="the board's telemetry link the ptys carry: usb (its USB port, which "
                        "an emulated USB host enumerates and holds open; the default) or uart "
                        "(UART0, pins 0/1, where a telemetry radio goes)")
    p.add_argument("--loop-hz", type=float, default=IMAGE_LOOP_HZ,
                   help=f"must be the image's loop rate, {IMAGE_LOOP_HZ:g}")
    p.add_argument("--idle-timeout-s", type=int, default=10,
                   help="exit when no sensor frame arrives for this long (wall time)")
    p.add_argument("--dmp-image", help="refused: the Teensy image carries its DMP firmware "
                                       "from its build")
    p.add_argument("--telemetry-backlog-bytes", type=int, default=0, metavar="N",
                   help="the most telemetry that waits for a reader, the oldest dropped past "
                        "it, as a board's USB or UART buffer (default 0: unbounded, for the "
                        "lockstep simulator)")
    p.add_argument("--params", metavar="FILE",
                   help="keep the board's parameter flash (two 4 KiB sectors, 8 KiB) in FILE "
                        "across runs: restored before the boot, written when the image "
                        "changes it; a missing FILE is a new board")
    p.add_argument("--program", metavar="FILE",
                   help="keep the board's on-board program flash (the two 4 KiB sectors below "
                        "the parameters', 8 KiB) in FILE across runs, as --params keeps the "
                        "parameters")
    p.add_argument("--sd-image", metavar="FILE",
                   help="the card-image file in the board's microSD socket (docs/sd-card.md); "
                        "a missing FILE is made first, a FAT32 card of the default size, as "
                        "heliquad-fw-host makes it (default: the socket empty)")
    args = p.parse_args(argv)
    if args.loop_hz != IMAGE_LOOP_HZ:
        _usage(f"--loop-hz {args.loop_hz:g}: the Teensy image runs its loop at "
               f"{IMAGE_LOOP_HZ:g} Hz")
    if args.idle_timeout_s <= 0:
        _usage("--idle-timeout-s must be positive")
    if args.telemetry_backlog_bytes < 0:
        _usage("--telemetry-backlog-bytes must not be negative")
    if args.dmp_image:
        _usage("--dmp-image: the Teensy image carries its DMP firmware from its build "
               "(-DHQ_DMP_IMAGE=FILE); the emulated board runs what the image has")
    if args.sd_image:
        _make_card(args.sd_image)
    return args


def _make_card(path: str) -> None:
    """A missing card image made as the host build makes it; a folder refused."""
    if os.path.isdir(path):
        _usage(f"--sd-image {path}: is a folder, not a card image")
    if not os.path.exists(path):
        error = _firmware.make_card_image(path, _firmware.DEFAULT_CARD_IMAGE_BYTES)
        if error:
            _usage(f"--sd-image {error}")


def _open(args):
    """The booted board and its two ptys, or a one-line usage error."""
    try:
        elf = args.image or str(teensy35_image("elf"))
    except ImageNotFound as e:
        _usage(str(e))
    try:
        board = PilBoard(elf, args.params, link=args.link, sd_image=args.sd_image,
                         program_file=args.program)
        board.boot()
    except (ImageFault, ParamFileError, OSError, ValueError) as e:
        _usage(str(e))
    # What the start-up made lives as long as the process (the image, the register maps,
    # most of the heap): kept out of the collector's passes, which the frames' short-lived
    # objects would otherwise trigger over all of it.
    gc.collect()
    gc.freeze()
    try:
        sim, tel = Pty(args.sim_link), Pty(args.telemetry)
    except OSError as e:
        _usage(f"cannot create the links: {e}")
    report = board.report()
    print(f"sim link: {args.sim_link} -> {sim.slave_path}\ntelemetry: {args.telemetry} -> "
          f"{tel.slave_path}\nimu: {'dmp' if report[5] == dialect().HQ_SENSOR_DMP else 'raw'}\n"
          f"image: {elf}\nlink: {args.link}\nready", flush=True)
    return board, sim, tel


def main(argv=None) -> int:
    args = parse(sys.argv[1:] if argv is None else argv)

    def on_signal(signum, frame):
        Stop.requested = True
    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    board, sim, tel = _open(args)
    drop_in = DropIn(board, sim, tel, args.idle_timeout_s, args.telemetry_backlog_bytes,
                     native=native_frames())
    exit_code = 0
    try:
        exit_code = drop_in.serve()
    except ImageFault as e:
        print(f"heliquad-fw-pil: the image faulted at frame {drop_in.last_frame}: {e}",
              file=sys.stderr)
        exit_code = EXIT_IMAGE
    finally:
        if board.telemetry_out:
            tel.write_some(bytes(board.telemetry_out))
        print(drop_in.summary(), file=sys.stderr)
        sim.close()
        tel.close()
    return exit_code

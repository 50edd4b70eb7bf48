"""Command-line options shared by several subcommands."""

from __future__ import annotations

__all__ = ["add_firmware_argument"]


def add_firmware_argument(p) -> None:
    """--firmware: which firmware flies the simulated rig (sim.lockstep.FIRMWARES)."""
    p.add_argument("--firmware", choices=("host", "teensy35"), default="host",
                   help="host: the firmware's host build (default); teensy35: the Teensy 3.5 "
                        "image itself, run instruction by instruction in the emulated "
                        "MK64FX512 (processor in the loop: slower; the install builds the "
                        "image when the ARM toolchain is present)")

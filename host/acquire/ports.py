"""``--port auto``: the one heliquad board there is, found by its USB identity.

The candidates are the serial ports pyserial lists (``serial.tools.list_ports.comports()``:
each with its USB vendor and product IDs, product string and serial number) and the ptys that
boards emulated by ``heliquad board`` announce (:mod:`heliquad.sim.rig.announce`). A heliquad
board has the Teensy image's vendor and product IDs and a product string that contains
"heliquad" (:mod:`heliquad.sim.base.firmware_facts`, from the firmware's
``usb_identity.hpp``); where the system does not report the product string (Windows'
pyserial), the IDs alone. A stock Teensyduino sketch has the same IDs and the product "USB
Serial": not a heliquad board.

One board that this user can open: that port, said on stderr with its serial number. Several:
one line listing them, and the user chooses (exit 2). None: one line saying so (exit 2), with
what was found instead: a Teensy without heliquad's USB firmware, or a heliquad board this
user may not open (on Linux a udev rule gives access: docs/usb.md).
"""

from __future__ import annotations

import os
import sys

from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import USB_IDENTITY
from ...sim.rig.announce import BoardPort, announcements, folder

__all__ = ["AUTO", "resolve_port", "auto_board", "found_record", "find_board", "usb_ports"]

#: The --port value that asks for the board to be found.
AUTO = "auto"
#: What a heliquad board's product string contains (the firmware's is USB_IDENTITY.product).
PRODUCT_MARK = "heliquad"


def resolve_port(name: str) -> str:
    """``name``, or for ``auto`` the device of the one heliquad board (said on stderr); an
    InputError when there is none or more than one."""
    return name if name != AUTO else auto_board().device


def auto_board() -> BoardPort:
    """The one heliquad board (said on stderr); an InputError when there is none or more."""
    board = find_board(usb_ports() + announcements())
    sys.stderr.write(f"port auto: {board.device} ({_identity(board)})\n")
    sys.stderr.flush()
    return board


def found_record(board: BoardPort) -> dict:
    """What ``--port auto`` found, as a sweep's manifest keeps it (``port_found``): where it
    was published, its serial number and, for an announced (emulated) board, its firmware."""
    record = {"source": board.source, "serial_number": board.serial_number}
    if board.firmware is not None:
        record["firmware"] = board.firmware
    return record


def usb_ports() -> list[BoardPort]:
    """The serial ports the system lists, with their USB identities."""
    # pyserial's port listing (it probes the system's devices) only for --port auto: the
    # command line's start-up never pays for it
    from serial.tools import list_ports

    return [BoardPort(p.device, p.vid, p.pid, p.product, p.serial_number)
            for p in list_ports.comports()]


def find_board(ports) -> BoardPort:
    """The one heliquad board among ``ports`` that this user can open (module docstring)."""
    ours = [p for p in ports if _teensy_ids(p) and _says_heliquad(p)]
    usable = [p for p in ours if _can_open(p.device)]
    if len(usable) == 1:
        return usable[0]
    if usable:
        listed = "; ".join(f"{p.device} ({_identity(p)})" for p in usable)
        raise InputError(f"--port auto: {len(usable)} heliquad boards found: {listed}; choose "
                         "one with --port DEVICE")
    return _none_found(ours, [p for p in ports if _teensy_ids(p) and not _says_heliquad(p)])


def _none_found(closed, stock):
    """The InputError for no usable board: ``closed`` heliquad boards this user cannot open,
    ``stock`` Teensys whose product is not heliquad's."""
    text = ("--port auto: no heliquad board found among the USB devices and the boards "
            f"announced in {folder()}")
    if closed:
        devices = ", ".join(p.device for p in closed)
        text += (f"; {devices} is a heliquad board this user cannot open (permission denied: "
                 "on Linux add the udev rule of docs/usb.md, or join the group that owns it)")
    if stock:
        devices = ", ".join(f"{p.device} (product {p.product!r})" for p in stock)
        text += (f"; a Teensy without heliquad's USB firmware is at {devices} (flash it with "
                 "heliquad flash)")
    raise InputError(text + "; or give --port DEVICE")


def _teensy_ids(port: BoardPort) -> bool:
    return (port.vid, port.pid) == (USB_IDENTITY.vid, USB_IDENTITY.pid)


def _says_heliquad(port: BoardPort) -> bool:
    """The product string says heliquad, or the system does not report it."""
    return port.product is None or PRODUCT_MARK in port.product.lower()


def _identity(port: BoardPort) -> str:
    product = port.product if port.product is not None else "product not reported"
    serial = port.serial_number if port.serial_number else "none"
    via = ", heliquad board" if port.source != "usb" else ""
    return f"{product}, serial {serial}{via}"


def _can_open(device: str) -> bool:
    """Whether this user may read and write ``device`` (a path: Linux, macOS; Windows' COMn
    names are no paths, and its permissions are not per user)."""
    if os.name != "posix":
        return True
    return os.access(device, os.R_OK | os.W_OK)

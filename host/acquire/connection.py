"""Connections: the bytes under the telemetry link, from a connection string as
pymavlink's tools take it.

* a serial device: ``/dev/ttyACM0`` (Linux), ``/dev/cu.usbmodem1`` (macOS), ``COM3``
  (Windows), or a pty (the SIL's, ``heliquad board``'s), through pyserial and its own
  non-blocking read (timeout 0), so it works wherever pyserial does; ``auto`` is the one
  heliquad board there is (:mod:`.ports` finds it, before a connection opens);
* ``udpin:HOST:PORT`` (listen; ``udp:`` is the same, as in MAVProxy and mavutil),
  ``udpout:HOST:PORT`` (send to), ``tcp:HOST:PORT`` (connect to) and ``tcpin:HOST:PORT``
  (listen for one connection), through pymavlink's ``mavutil.mavlink_connection`` and its
  raw ``recv()`` and ``write()``: the bytes are framed by the host's own framer
  (:mod:`heliquad.sim.base.framing`), never by mavutil's parser.

A listening link (``udpin:``, ``udp:``, ``tcpin:``) learns where to send from the peer: it
can send only once the other end has sent to it (or, for ``tcpin:``, connected).
:attr:`can_send` says whether it can yet; a write before that is an :class:`InputError`
that says so.

Every failure to open is one :class:`InputError` line naming the connection (exit 2). A
serial device or pty is opened for this program alone (an advisory lock, as pyserial's
``exclusive=True`` takes): a second heliquad (or any program that locks its ports) on a
port in use is refused with one line naming the port as busy, instead of stealing bytes
from the first (:class:`LinkLost`, exit 1). A link lost while reading or writing is a
:class:`LinkLost` (``telemetry link lost: ...``, exit 1).
"""

from __future__ import annotations

import errno
import re
import socket

import serial

from ...sim.base.errors import InputError, LinkLost

__all__ = ["open_connection", "NETWORK_KINDS", "CONNECTION_HELP"]

#: The network connections: scheme -> what it does.
NETWORK_KINDS = {"udpin": "listen for UDP", "udp": "listen for UDP (as udpin:)",
                 "udpout": "send UDP to HOST:PORT", "tcp": "connect to a TCP server",
                 "tcpin": "listen for one TCP connection"}
#: The listening kinds: they send only to a peer that reached them first.
LISTENING = ("udpin", "udp", "tcpin")
#: How long a TCP connect may take before it is refused as unreachable.
CONNECT_TIMEOUT_S = 5.0
#: The most bytes one read takes in (a board sends about 25 kB/s).
READ_SIZE = 65536
#: The --port help of every command that opens the telemetry link.
CONNECTION_HELP = ("the board's telemetry link: a serial device (/dev/ttyACM0, COM3, a "
                   "heliquad board pty), auto (the one heliquad board attached by USB or "
                   "running as heliquad board, found by its USB identity) or a network link "
                   "as pymavlink's tools write it: "
                   "udpin:HOST:PORT (listen; udp: is the same), udpout:HOST:PORT, "
                   "tcp:HOST:PORT (connect), tcpin:HOST:PORT (listen)")
_SCHEME = re.compile(r"^([A-Za-z][A-Za-z0-9]+):")


def open_connection(name: str, baud: int):
    """The transport for a connection string: ``read()`` (bytes, never blocks), ``write()``,
    ``fileno()``, ``close()``, ``can_send``; an InputError naming it if it cannot be opened."""
    match = _SCHEME.match(name)
    if match and match.group(1).lower() in NETWORK_KINDS:
        return NetworkPort(name, match.group(1).lower(), name[match.end():])
    if match:
        raise InputError(f"{name}: unknown connection {match.group(1)}:; use a serial device "
                         "or one of " + ", ".join(f"{k}:HOST:PORT" for k in NETWORK_KINDS))
    return SerialPort(name, baud)


class SerialPort:
    """A serial device or pty, read with pyserial's non-blocking read."""

    can_send = True

    def __init__(self, name: str, baud: int):
        self.name = name
        try:
            self.serial = serial.Serial(name, baudrate=baud, timeout=0, write_timeout=1.0,
                                        exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            if getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK):
                raise LinkLost(f"{name} is busy: another program has it open (a second "
                               "heliquad log, params or sweep on the same port?); stop that "
                               "one first") from None
            raise InputError(f"cannot open {name}: {exc}") from None

    def read(self) -> bytes:
        try:
            return self.serial.read(READ_SIZE)
        except (serial.SerialException, OSError) as exc:
            raise LinkLost(f"telemetry link lost: {exc}") from None

    def write(self, data) -> int:
        """A failed write (the port gone, or a board that stopped reading for a second) is
        the link lost, as a failed read is."""
        try:
            return self.serial.write(data)
        except (serial.SerialException, OSError) as exc:
            raise LinkLost(f"telemetry link lost: {exc}") from None

    def fileno(self) -> int:
        return self.serial.fileno()

    def close(self) -> None:
        self.serial.close()


def _address(name: str, kind: str, rest: str) -> tuple[str, int]:
    """HOST and PORT of ``KIND:HOST:PORT``, checked."""
    host, colon, port = rest.rpartition(":")
    if not colon or not host or ":" in host:
        raise InputError(f"{name}: expected {kind}:HOST:PORT (for example "
                         f"{kind}:{'0.0.0.0' if kind in LISTENING else '127.0.0.1'}:14550)")
    if not port.isdigit() or not 1 <= int(port) <= 65535:
        raise InputError(f"{name}: the port must be a number from 1 to 65535, not {port!r}")
    return host, int(port)


class NetworkPort:
    """A UDP or TCP link opened by pymavlink's ``mavlink_connection``; its raw ``recv`` and
    ``write`` carry the bytes."""

    def __init__(self, name: str, kind: str, rest: str):
        host, port = _address(name, kind, rest)
        self.name, self.kind, self.lost = name, kind, None
        # pymavlink's mavutil (0.3 s) only for UDP or TCP: a serial port or pty never pays
        from pymavlink import mavutil

        # A TCP connect to a host that never answers would wait minutes: bound it. mavutil
        # makes its sockets non-blocking once connected.
        previous = socket.getdefaulttimeout()
        socket.setdefaulttimeout(CONNECT_TIMEOUT_S)
        try:
            self.conn = mavutil.mavlink_connection(f"{kind}:{host}:{port}", retries=0)
        except TimeoutError:
            raise InputError(f"cannot open {name}: no answer within {CONNECT_TIMEOUT_S:g} s") from None
        except (OSError, ValueError, OverflowError) as exc:
            raise InputError(f"cannot open {name}: {getattr(exc, 'strerror', None) or exc}") from None
        finally:
            socket.setdefaulttimeout(previous)
        # mavutil's TCP link prints and carries on when the other end goes; here that is the
        # link lost, said by the next read or write.
        self.conn.handle_eof = self.conn.handle_disconnect = self._closed_by_peer

    def _closed_by_peer(self) -> None:
        self.lost = f"telemetry link lost: {self.name}: the other end closed the connection"

    @property
    def can_send(self) -> bool:
        """Whether a write reaches anyone: a listening link needs to have heard its peer."""
        if self.kind == "tcpin":
            return self.conn.port is not None
        if self.kind in LISTENING:
            return bool(getattr(self.conn, "clients", None) or getattr(self.conn, "last_address", None))
        return True

    def read(self) -> bytes:
        """What has arrived (every waiting datagram), never blocking."""
        chunks, total = [], 0
        while total < READ_SIZE:
            try:
                data = self.conn.recv(READ_SIZE)
            except OSError as exc:
                raise LinkLost(f"telemetry link lost: {self.name}: {exc.strerror or exc}") from None
            if self.lost:
                raise LinkLost(self.lost)
            if not data:
                break
            chunks.append(bytes(data))
            total += len(data)
        return b"".join(chunks)

    def write(self, data) -> int:
        if not self.can_send:
            raise InputError(f"{self.name} has heard nothing from the board yet, and a "
                             f"{self.kind}: link can send only to a peer that reached it first: "
                             "wait for its telemetry, or let the tool connect out "
                             "(udpout:HOST:PORT, tcp:HOST:PORT)")
        self.conn.write(bytes(data))
        if self.lost:
            raise LinkLost(self.lost)
        return len(data)

    def fileno(self) -> int:
        return self.conn.fd

    def close(self) -> None:
        self.conn.close()

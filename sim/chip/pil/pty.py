"""The drop-in's ends of its two links: a pseudo-terminal whose slave device is published
as a symlink, as heliquad-fw-host publishes its own (docs/link-contract.md)."""

from __future__ import annotations

import errno
import fcntl
import os
import select
import struct
import termios
import time
import tty


class Pty:
    """A pseudo-terminal whose slave device is published as ``link_path`` (a symlink), raw,
    with our own slave descriptor kept open so the master never sees EOF between users."""

    def __init__(self, link_path: str):
        self.master, slave = os.openpty()
        self.slave = slave
        tty.setraw(slave)
        os.set_blocking(self.master, False)
        self.slave_path = os.ttyname(slave)
        self.link_path = link_path
        try:
            os.unlink(link_path)
        except FileNotFoundError:
            pass
        os.symlink(self.slave_path, link_path)
        os.set_blocking(self.slave, False)        # read only to drop the oldest: never wait

    def drop_oldest(self, queued: bytearray, limit: int) -> int:
        """Drop the oldest bytes of what waits for a reader (in the pty, then at the front
        of ``queued``) past ``limit``; returns how many were dropped."""
        waiting = struct.unpack("i", fcntl.ioctl(self.slave, termios.FIONREAD, b"\0" * 4))[0]
        excess, dropped = waiting + len(queued) - limit, 0
        while excess > 0 and waiting > 0:
            try:
                data = os.read(self.slave, min(excess, waiting, 4096))
            except BlockingIOError:
                break
            if not data:
                break
            excess, waiting, dropped = excess - len(data), waiting - len(data), dropped + len(data)
        if excess > 0:
            cut = min(excess, len(queued))
            del queued[:cut]
            dropped += cut
        return dropped

    def close(self) -> None:
        try:
            os.unlink(self.link_path)
        except OSError:
            pass
        for fd in (self.slave, self.master):
            try:
                os.close(fd)
            except OSError:
                pass

    def read(self) -> bytes:
        try:
            return os.read(self.master, 65536)
        except BlockingIOError:
            return b""
        except OSError as e:
            if e.errno == errno.EIO:
                return b""
            raise

    def write_some(self, data: bytes) -> int:
        """Write what fits without blocking; the rest is lost as on a wire nobody reads."""
        try:
            return os.write(self.master, data)
        except BlockingIOError:
            return 0

    def write_all(self, data: bytes, timeout_s: float) -> bool:
        view, deadline = memoryview(data), time.monotonic() + timeout_s
        while view:
            try:
                n = os.write(self.master, view)
                view = view[n:]
            except BlockingIOError:
                if time.monotonic() > deadline:
                    return False
                select.select([], [self.master], [], 0.05)
        return True

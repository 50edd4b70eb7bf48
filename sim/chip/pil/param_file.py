"""The emulated board's stored records kept in files across runs, as a board keeps its flash
across power cycles: the parameter sectors (the drop-in's ``--params FILE``) and the on-board
program's (``--program FILE``)."""

from __future__ import annotations

import os
import sys

#: What each file keeps: the option that names it, and what the sectors hold.
OPTIONS = {"parameters": "--params", "program": "--program"}


class ParamFileError(ValueError):
    """A --params or --program that cannot be kept: the file is not those sectors, or the
    image has none."""


class ParamFile:
    """Two of the board's flash sectors kept in a file across runs, as a board keeps them
    across power cycles: ``what`` is "parameters" (the top two sectors) or "program" (the two
    below them). The file holds the two sectors exactly as the flash does (8 KiB; the slot
    format is the image's, docs/teensy35.md), not the host build's file. A file that does not
    exist yet is a new board: the sectors stay erased, and the file is created when the image
    first writes them. :meth:`keep` writes the file back (whole, replaced in one rename) when
    a flash command has changed these sectors since the last time."""

    def __init__(self, board, path: str, what: str = "parameters"):
        self.board, self.path, self.what = board, path, what
        try:
            self.start, self.end = board.stored_range(what)
        except KeyError:
            raise ParamFileError(f"the image has no {what} flash: it is older than that "
                                 f"storage; {OPTIONS[what]} needs a newer one") from None
        self._changes = board.chip.ftfe.changes
        self._kept = None

    def restore(self) -> None:
        """The file's bytes into the sectors (before the boot)."""
        size = self.end - self.start
        try:
            with open(self.path, "rb") as fh:
                data = fh.read(size + 1)
        except FileNotFoundError:
            return
        if len(data) != size:
            raise ParamFileError(f"{self.path}: {len(data)} bytes; the Teensy image's "
                                 f"{OPTIONS[self.what]} file holds its two flash sectors, "
                                 f"{size} bytes")
        self.board.write_stored(data, self.what)
        self._changes, self._kept = self.board.chip.ftfe.changes, data

    def keep(self) -> None:
        """Write the sectors back if the image has changed them. A write that fails is said
        on stderr; the run goes on (the flash itself still has them)."""
        changes = self.board.chip.ftfe.changes
        if changes == self._changes:
            return
        self._changes = changes
        data = self.board.read_stored(self.what)
        if data == self._kept or (self._kept is None and data == b"\xff" * len(data)):
            return                          # a command on the other sectors
        tmp = self.path + ".tmp"
        try:
            with open(tmp, "wb") as fh:
                fh.write(data)
            os.replace(tmp, self.path)
            self._kept = data
        except OSError as e:
            print(f"heliquad-fw-pil: the {self.what} could not be kept in {self.path}: {e}",
                  file=sys.stderr, flush=True)

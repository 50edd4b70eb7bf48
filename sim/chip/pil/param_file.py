"""The emulated board's parameter flash kept in a file across runs (the drop-in's
``--params FILE``), as a board keeps it across power cycles."""

from __future__ import annotations

import os
import sys


class ParamFileError(ValueError):
    """A --params that cannot be kept: the file is not the board's parameter flash, or the
    image has none."""


class ParamFile:
    """The board's parameter flash kept in a file across runs, as a board keeps it across
    power cycles. The file holds the two sectors exactly as the flash does (8 KiB; the slot
    format is the image's, docs/teensy35.md), not the host build's parameter file. A file
    that does not exist yet is a new board: the sectors stay erased, and the file is created
    when the image first writes them. :meth:`keep` writes the file back (whole, replaced in
    one rename) when a flash command has changed the flash since the last time."""

    def __init__(self, board, path: str):
        self.board, self.path = board, path
        try:
            self.start, self.end = board.param_flash_range()
        except KeyError:
            raise ParamFileError("the image has no parameter flash (hq_param_flash_start): it is "
                             "older than the parameter storage; --params needs a newer one") \
                from None
        self._changes = board.chip.ftfe.changes

    def restore(self) -> None:
        """The file's bytes into the sectors (before the boot)."""
        size = self.end - self.start
        try:
            with open(self.path, "rb") as fh:
                data = fh.read(size + 1)
        except FileNotFoundError:
            return
        if len(data) != size:
            raise ParamFileError(f"{self.path}: {len(data)} bytes; the Teensy image's parameter "
                                 f"file holds its two flash sectors, {size} bytes")
        self.board.write_param_flash(data)
        self._changes = self.board.chip.ftfe.changes

    def keep(self) -> None:
        """Write the sectors back if the image has changed them. A write that fails is said
        on stderr; the run goes on (the flash itself still has them)."""
        changes = self.board.chip.ftfe.changes
        if changes == self._changes:
            return
        self._changes = changes
        tmp = self.path + ".tmp"
        try:
            with open(tmp, "wb") as fh:
                fh.write(self.board.read_param_flash())
            os.replace(tmp, self.path)
        except OSError as e:
            print(f"heliquad-fw-pil: the parameters could not be kept in {self.path}: {e}",
                  file=sys.stderr, flush=True)

"""Errors the host tool reports to users as one line, without a traceback.

``InputError``, ``LinkLost``, ``BoardRefused`` and ``DiskFull`` are defined with the simulator (the layer below: its
parameter files and fault specifications are user input too, and its telemetry tap writes
the SIL's log) and are the same classes here.
"""

from ..sim.errors import NO_ROOM, BoardRefused, DiskFull, InputError, LinkLost, no_room

__all__ = ["InputError", "DiskFull", "LinkLost", "BoardRefused", "NO_ROOM", "no_room",
           "Terminated", "HungUp"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal arrives (the command line installs the handler) so
    a run ends as it does on Ctrl-C: the excitation stopped, the records kept and marked,
    the firmware stopped and its temporary folder removed."""


class HungUp(Terminated):
    """SIGHUP: the terminal or SSH session the command ran in closed. The run ends as it
    does on SIGTERM (exit 129 instead of 143)."""

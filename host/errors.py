"""Errors the host tool reports to users as one line, without a traceback.

``InputError`` and ``DiskFull`` are defined with the simulator (the layer below: its
parameter files and fault specifications are user input too, and its telemetry tap writes
the SIL's log) and are the same classes here.
"""

from ..sim.errors import NO_ROOM, DiskFull, InputError, no_room

__all__ = ["InputError", "DiskFull", "NO_ROOM", "no_room", "Terminated"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal arrives (the command line installs the handler) so
    a run ends as it does on Ctrl-C: the excitation stopped, the records kept and marked,
    the firmware stopped and its temporary folder removed."""

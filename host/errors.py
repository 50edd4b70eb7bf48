"""Errors the host tool reports to users as one line, without a traceback.

``InputError`` is defined with the simulator (the layer below: its parameter files and fault
specifications are user input too) and is the same class here.
"""

from ..sim.errors import InputError

__all__ = ["InputError", "Terminated"]


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the signal arrives (the command line installs the handler) so
    a run ends as it does on Ctrl-C: the excitation stopped, the records kept and marked,
    the firmware stopped and its temporary folder removed."""

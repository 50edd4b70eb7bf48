"""The files a simulated run reads before it flies, as command-line options: the pilot as an
RC script (``--rc-script``) and the parameter values the board is given before the pilot arms
(``--load-params``). Each file is read and checked when the option is parsed, so a bad one is
refused before anything runs."""

from __future__ import annotations

import argparse

from ...sim.base.errors import InputError

__all__ = ["add_rc_script_argument", "add_load_params_argument"]


def _read_as_argument(read, path: str):
    """``read(path)``, its InputError as argparse's refusal of the option's value."""
    try:
        return read(path)
    except InputError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _params_file(path: str) -> str:
    """A .params file's path once it reads (a bad one is refused before anything runs)."""
    # imported only when the option is given: every command's parser imports this module
    from ..records.params_file import read_params_file

    _read_as_argument(read_params_file, path)
    return path


def add_load_params_argument(p) -> None:
    """--load-params: values the simulated board is given before the pilot arms."""
    p.add_argument("--load-params", metavar="FILE.params", type=_params_file,
                   help="the simulated board is given these parameter values before it arms, "
                        "as `heliquad params load` would set them (after a --params vehicle's "
                        "geometry); one it refuses ends the run")


def _rc_script(path: str):
    """An RC script file, read and checked (sim/rig/rc_script.py)."""
    # imported only when the option is given: every command's parser imports this module
    from ...sim.rig.rc_script import read_rc_script

    return _read_as_argument(read_rc_script, path)


def add_rc_script_argument(p) -> None:
    """--rc-script FILE: the simulated pilot as a script of channel changes."""
    p.add_argument("--rc-script", metavar="FILE", type=_rc_script,
                   help="the pilot as a script: lines of 'TIME_S CH=US ...' (CH the radio's "
                        "channel 1-8: 3 throttle, 5 arm switch, 7 the program switch; US a "
                        "pulse of 800-2200 us, or 0 for none), each setting its channels from "
                        "TIME_S seconds of simulated time on, e.g. '2.5 5=2000 3=1000'; '#' "
                        "starts a comment; before the first line the pilot is landed (arm "
                        "switch and throttle low). With a script nothing arms unless it says "
                        "so (docs/simulated-pilot.md). Default: the pilot arms, then hovers")

"""The parameter values a simulated board is given before its pilot arms it: the vehicle
file's geometry (``--params VEHICLE.toml``: the CA_* parameters ``heliquad params
from-vehicle`` writes) and a .params file's values (``--load-params``), set over the
telemetry link with the parameter protocol, as ``heliquad params load`` would set them.

:func:`preflight_sets` says what to set; :func:`set_on_board` sets it through any link
:class:`~heliquad.host.acquire.param_protocol.ParamClient` takes (a simulated session's,
:class:`~heliquad.host.acquire.param_protocol.SessionLink`); :class:`LandedRigLink` is that
link for a rig that is not yet a session (``heliquad board`` before it flies in real time):
it steps the rig in lockstep with the pilot landed while the protocol waits. A value the
board refuses ends the run in one line: it would fly other values than asked.
"""

from __future__ import annotations

import os

import numpy as np

from ...sim.base.errors import InputError
from ...sim.plant.rotor_geometry import geometry_params
from ...sim.plant.vehicle_params import load_params as load_vehicle
from ...sim.rig.setup import rc_disarmed
from ..records.params_file import read_params_file
from .link import TelemetryLink
from .param_protocol import ParamClient, load_params

__all__ = ["preflight_sets", "set_on_board", "LandedRigLink", "FRAMES_PER_POLL"]

#: Lockstep frames a :class:`LandedRigLink` runs each time the protocol polls (50 ms at
#: 200 Hz: the firmware answers two parameters a loop).
FRAMES_PER_POLL = 10


def preflight_sets(vehicle: str | None, params_file: str | None) -> list:
    """``[(entries, what, whose)]``: the vehicle file's geometry parameters (None: no
    vehicle file of its own), then the .params file's values, in the order they are set;
    ``entries`` are ``(name, value)`` pairs, ``what`` and ``whose`` name them in what is
    said."""
    sets = []
    if vehicle:
        sets.append(([(g.name, g.value) for g in geometry_params(load_vehicle(vehicle))],
                     f"geometry parameters of {os.path.basename(vehicle)}", "the vehicle's"))
    if params_file:
        sets.append(([(p.name, p.value) for p in read_params_file(params_file)],
                     f"parameters of {os.path.basename(params_file)}", params_file + "'s"))
    return sets


def set_on_board(link, sets, progress=print) -> None:
    """Each of ``sets`` (:func:`preflight_sets`) onto the board behind ``link``, the values
    that differ; the first refusal ends it (InputError naming the parameter and why)."""
    for entries, what, whose in sets:
        done = load_params(ParamClient(link), entries, progress=lambda _: None)
        if done["refused"]:
            name, why = done["refused"][0]
            raise InputError(f"the board refused {whose} {name}: {why}")
        if done["changed"]:
            progress(f"set {len(done['changed'])} {what} on the board")


class LandedRigLink:
    """A lockstep rig (:class:`heliquad.sim.rig.driver.Rig`) as ParamClient's link: requests
    go out on its telemetry port, and each poll runs :data:`FRAMES_PER_POLL` frames with the
    pilot landed (arm switch down, throttle low), then returns what arrived."""

    can_send = True

    def __init__(self, rig):
        self.rig = rig
        self.tel = TelemetryLink(rig.telemetry_path)
        self.name = self.tel.name
        self._landed = np.tile(np.asarray(rc_disarmed(), dtype=np.uint16), (FRAMES_PER_POLL, 1))

    def heartbeat(self) -> None:
        self.tel.heartbeat()

    def poll(self, only=None) -> list:
        self.rig.advance(FRAMES_PER_POLL, self._landed)
        return self.tel.poll(only=only)

    def request_params(self) -> None:
        self.tel.request_params()

    def request_param(self, name: str = "", index: int = -1) -> None:
        self.tel.request_param(name=name, index=index)

    def set_param(self, name: str, value: float, param_type: int) -> None:
        self.tel.set_param(name, value, param_type)

    def close(self) -> None:
        self.tel.close()

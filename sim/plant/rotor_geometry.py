"""The vehicle's rotor geometry as the firmware's control allocation takes it
(docs/vehicle-geometry.md): a vehicle file's rotors and weight as the firmware's geometry
parameters (``CA_ROTOR_COUNT``, ``CA_HOVER_THRUST`` and per rotor ``CA_ROTORn_PX`` ...
``CA_ROTORn_KM``, named as PX4's control allocation names them), checked against the ranges
the firmware takes; and the effectiveness matrix B the firmware's allocation
(firmware/core/allocation.cpp) builds from that geometry, in numpy: the reference its tests
compare it with, from the same rotors the simulator's vehicle (vehicle.py) flies. A geometry
the firmware's allocation would refuse is refused here by the same code, through its bindings.
"""

from __future__ import annotations

import re
from typing import NamedTuple

import numpy as np

from heliquad import _firmware

from ..base import firmware_facts as facts
from ..base.errors import InputError
from .vehicle import GRAVITY_M_S2

__all__ = ["GeometryParam", "RANGES", "UNUSED_ROTOR", "ROWS", "geometry_params",
           "effectiveness", "rotor_names", "range_of", "firmware_geometry",
           "check_with_firmware"]

#: The ranges the firmware's geometry parameters take, read from its parameter table, by name,
#: ``n`` standing for a rotor's index (every rotor's are rotor 0's): m for positions, N for the
#: weight and the largest thrust, m (N m per N) for the moment ratio; the axis is a unit vector.
_TABLE = {p.name: (float(p.minimum), float(p.maximum)) for p in _firmware.param_table()}
RANGES = {"CA_ROTOR_COUNT": tuple(int(v) for v in _TABLE["CA_ROTOR_COUNT"]),
          "CA_HOVER_THRUST": _TABLE["CA_HOVER_THRUST"],
          **{f"CA_ROTORn_{f}": _TABLE[f"CA_ROTOR0_{f}"]
             for f in ("PX", "PY", "PZ", "AX", "AY", "AZ", "CT", "KM")}}
#: What a rotor at or beyond the count is written as: at the centre, thrust straight up, no
#: thrust and no moment ratio. The allocation ignores it; a count raised by hand later meets
#: a rotor it refuses ("max thrust not positive"), never an earlier vehicle's rotor.
UNUSED_ROTOR = {"PX": 0.0, "PY": 0.0, "PZ": 0.0, "AX": 0.0, "AY": 0.0, "AZ": -1.0,
                "CT": 0.0, "KM": 0.0}
#: B's rows, the allocation's command order.
ROWS = ("vertical force (N, up)", "roll (N m)", "pitch (N m)", "yaw (N m)")
#: The smallest normal single-precision float: the firmware refuses a denormal value, so a
#: figure below it (a position of 1e-40 m, an axis component of 1e-17) is written as the 0 it is.
_FLOAT32_TINY = float(np.finfo(np.float32).tiny)


class GeometryParam(NamedTuple):
    """One geometry parameter: its name, its value as the board keeps it (single precision),
    whether it is a whole number (INT32) rather than a real (REAL32)."""
    name: str
    value: float
    integer: bool


def rotor_names(n: int) -> list[str]:
    """The names of rotor ``n``'s parameters (n = 0 the central rotor), in the firmware's
    order: position, thrust axis, largest thrust, moment ratio."""
    return [f"CA_ROTOR{n}_{key}" for key in UNUSED_ROTOR]


def range_of(name: str) -> tuple:
    """A geometry parameter's range, ``CA_ROTOR3_PX`` say, from :data:`RANGES`."""
    if name in RANGES:
        return RANGES[name]
    return RANGES[re.sub(r"^CA_ROTOR\d_", "CA_ROTORn_", name)]


def geometry_params(vehicle) -> list[GeometryParam]:
    """The firmware's geometry parameters of ``vehicle`` (a
    :class:`~heliquad.sim.plant.vehicle_params.VehicleParams`): the rotor count, the weight,
    then every rotor's slot from 0 to the firmware's last (the file's rotors[1], the central
    rotor, is rotor 0; slots past the count as :data:`UNUSED_ROTOR`, so the file sets the
    board's whole geometry). Each value as single precision carries it. A vehicle the
    firmware cannot take is one InputError naming the file, the rotor and the key (a figure
    beyond its parameter's range) or quoting the firmware's allocation (a geometry it cannot
    fly: :func:`check_with_firmware`)."""
    source, n = vehicle.source, len(vehicle.rotors)
    lo, hi = RANGES["CA_ROTOR_COUNT"]
    if not lo <= n <= hi:
        raise InputError(f"{source}: {n} [[rotors]] tables: the firmware's allocation flies "
                         f"{lo} to {hi} rotors")
    weight = _checked(source, "body.mass_kg (as the weight, mass x g)", "CA_HOVER_THRUST",
                      vehicle.body.mass_kg * GRAVITY_M_S2, "N")
    out = [GeometryParam("CA_ROTOR_COUNT", float(n), True),
           GeometryParam("CA_HOVER_THRUST", weight, False)]
    for index in range(hi):
        values = _rotor_values(source, index, vehicle.rotors[index]) if index < n \
            else UNUSED_ROTOR
        out += [GeometryParam(name, values[key], False)
                for name, key in zip(rotor_names(index), UNUSED_ROTOR)]
    check_with_firmware(source, out)
    return out


def _rotor_values(source, index: int, rotor) -> dict:
    """One rotor's parameters by key (PX ... KM), checked; ``index`` the firmware's (0 the
    central rotor, the file's rotors[1])."""
    where = f"rotors[{index + 1}]"
    values = {}
    for axis, position, direction in zip("XYZ", rotor.position_m, rotor.thrust_axis):
        values[f"P{axis}"] = _checked(source, f"{where}.position_m",
                                      f"CA_ROTOR{index}_P{axis}", position, "m")
        values[f"A{axis}"] = _checked(source, f"{where}.thrust_axis",
                                      f"CA_ROTOR{index}_A{axis}", direction, "")
    values["CT"] = _checked(source, f"{where}.max_thrust_n", f"CA_ROTOR{index}_CT",
                            rotor.max_thrust_n, "N")
    values["KM"] = _checked(source, f"{where}.torque_per_thrust_m (signed by spin)",
                            f"CA_ROTOR{index}_KM", rotor.spin * rotor.torque_per_thrust_m, "m")
    return values


def _checked(source, key: str, name: str, value: float, unit: str) -> float:
    """``value`` as the board keeps it, or InputError when it is beyond ``name``'s range."""
    kept = float(np.float32(value))
    if abs(kept) < _FLOAT32_TINY:
        kept = 0.0
    lo, hi = range_of(name)
    if not lo <= kept <= hi:
        unit = f" {unit}" if unit else ""
        raise InputError(f"{source}: {key}: {value:.6g}{unit} is beyond the firmware's "
                         f"{name} ({lo:g} to {hi:g}{unit})")
    return kept


def effectiveness(rotors) -> np.ndarray:
    """B (4 x the rotors, rows :data:`ROWS`): the vertical force and the roll, pitch and yaw
    moments on the body per unit of each rotor's thrust fraction, body FRD about the centre
    of mass. A rotor's thrust T = T_max along its axis a at its hub r pushes up by -a_z T and
    turns the body by r x a T plus its reaction torque -spin k a T (k its torque per newton of
    thrust): docs/mixer.md, "Effectiveness"."""
    b = np.empty((len(ROWS), len(rotors)))
    for i, rotor in enumerate(rotors):
        a, r = np.asarray(rotor.thrust_axis, float), np.asarray(rotor.position_m, float)
        b[0, i] = -a[2]
        b[1:, i] = np.cross(r, a) - rotor.spin * rotor.torque_per_thrust_m * a
        b[:, i] *= rotor.max_thrust_n
    return b


def firmware_geometry(values: dict) -> _firmware.AllocationGeometry:
    """The firmware's allocation geometry from the geometry parameters' ``values`` ({name:
    value}), read by the firmware's own code (its parameter table and
    ``allocation_geometry``, through the bindings): the rotors up to the count, each with
    ``|KM|`` its moment ratio and the sign of ``KM`` its spin."""
    return _firmware.params_geometry({name: float(v) for name, v in values.items()})


def check_with_firmware(source, params: list[GeometryParam]) -> None:
    """Refuse, as the board would, a geometry the firmware's allocation cannot fly (its own
    code, through its bindings: no four independent commands, hover beyond a rotor's range):
    one InputError naming the file and quoting the allocation's reason."""
    allocation = _firmware.Allocation(firmware_geometry({p.name: p.value for p in params}))
    if not allocation.ok:
        raise InputError(f"{source}: the firmware cannot fly this geometry "
                         f"({allocation.reason})")

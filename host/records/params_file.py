"""A .params file, a board's parameters (docs/file-formats.md, ".params"): MAVProxy's
``NAME VALUE`` lines or QGroundControl's ``SYSID COMPID NAME VALUE TYPE``; written as
QGroundControl's (or MAVProxy's). Also the facts of MAVLink's parameters both the file and
the parameter protocol (host/acquire/param_protocol.py) go by: the names a parameter may
have and the MAV_PARAM_TYPE values.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ...sim.base.errors import InputError
from ...sim.base.userfiles import read_text
from .output import atomic_write
from .reading import short

__all__ = ["MAX_NAME", "INTEGER_TYPES", "TYPE_NAMES", "check_name", "ParamLine",
           "read_params_file", "write_params_file"]

#: The longest parameter name (PARAM_VALUE.param_id is char[16]).
MAX_NAME = 16
#: MAV_PARAM_TYPE: the whole-number types (UINT8 .. INT64) and the real ones.
INTEGER_TYPES = range(1, 9)
TYPE_NAMES = {1: "UINT8", 2: "INT8", 3: "UINT16", 4: "INT16", 5: "UINT32", 6: "INT32",
              7: "UINT64", 8: "INT64", 9: "REAL32", 10: "REAL64"}
#: A parameter file is a few kB (a firmware has tens of parameters, ArduPilot about 1000).
MAX_PARAMS_BYTES = 2**20
#: QGroundControl's columns (and MAVProxy's two: NAME VALUE).
QGC_COLUMNS = "Vehicle-Id Component-Id Name Value Type"


def check_name(name: str) -> str:
    """A parameter name as the protocol carries it (1..16 ASCII letters, digits, ``_``)."""
    if not 1 <= len(name) <= MAX_NAME or not name.isascii() or \
            not name.replace("_", "").isalnum():
        raise InputError(f"{name!r} is not a parameter name (1 to {MAX_NAME} letters, digits "
                         "or _)")
    return name


class ParamLine(NamedTuple):
    """One parameter of a .params file: its name, value, and MAV_PARAM_TYPE (None in
    MAVProxy's layout, which has none)."""
    name: str
    value: float
    type: int | None


def read_params_file(path) -> list[ParamLine]:
    """A .params file: its :class:`ParamLine` ``(name, value, type or None)`` in the file's
    order. Lines are MAVProxy's ``NAME VALUE`` (whitespace or a comma between) or
    QGroundControl's ``SYSID COMPID NAME VALUE TYPE`` (tabs), told apart by their number of
    fields; ``#`` starts a comment. A bad line is one InputError naming the file and the line."""
    text = read_text(path, MAX_PARAMS_BYTES, "parameter file (.params)")
    out, first = [], {}
    for number, line in enumerate(text.splitlines(), 1):
        fields = line.split("#", 1)[0].replace(",", " ").split()
        if not fields:
            continue
        where = f"{path}, line {number}"
        if len(fields) not in (2, 5):
            raise InputError(f"{where}: {len(fields)} fields; expected NAME VALUE (MAVProxy) "
                             "or SYSID COMPID NAME VALUE TYPE (QGroundControl)")
        name, value = fields[-3:-1] if len(fields) == 5 else fields
        ptype = _params_ints(where, fields) if len(fields) == 5 else None
        if ptype is not None and ptype not in TYPE_NAMES:
            raise InputError(f"{where}: type {ptype} is not a MAV_PARAM_TYPE (1 to 10)")
        try:
            check_name(name)
        except InputError as exc:
            raise InputError(f"{where}: {exc}") from None
        if name in first:
            raise InputError(f"{where}: {name} again (first on line {first[name]})")
        first[name] = number
        out.append(ParamLine(name, _params_value(where, name, value), ptype))
    if not out:
        raise InputError(f"{path}: no parameters in it (only comments)")
    return out


def _params_ints(where: str, fields) -> int:
    """A QGroundControl line's system and component ids (checked) and its type."""
    try:
        sysid, compid, ptype = int(fields[0]), int(fields[1]), int(fields[4])
    except ValueError:
        raise InputError(f"{where}: the system id, component id and type must be whole "
                         "numbers") from None
    if not (0 <= sysid <= 255 and 0 <= compid <= 255):
        raise InputError(f"{where}: system and component ids are 0 to 255")
    return ptype


def _params_value(where: str, name: str, text: str) -> float:
    try:
        value = float(int(text, 16)) if text.lower().startswith(("0x", "-0x")) else float(text)
    except ValueError:
        raise InputError(f"{where}: {name}'s value {short(text)!r} is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where}: {name}'s value {text} is not a finite number")
    return value


def write_params_file(path, params, header: str = "", layout: str = "qgc") -> None:
    """``params`` (:class:`~heliquad.host.acquire.param_protocol.Param`: ``name``, ``type``
    and ``text()``) as QGroundControl writes them: a header comment, then
    ``1<TAB>1<TAB>NAME<TAB>VALUE<TAB>TYPE`` per parameter, by name;
    with ``layout="mavproxy"``, as MAVProxy's ``param save`` does (``NAME VALUE``, which its
    ``param load`` reads). Each value the shortest decimal that reads back as the same
    single-precision float (a whole-number type's as an integer). Written whole
    (:func:`atomic_write`)."""
    if layout == "mavproxy":
        lines = [f"# {h}" for h in header.splitlines()]
        lines += [f"{p.name:<16} {p.text()}" for p in sorted(params, key=lambda p: p.name)]
        with atomic_write(path) as fh:
            fh.write("\n".join(lines) + "\n")
        return
    lines = ["# Onboard parameters for Vehicle 1", "#"]
    lines += [f"# {h}" for h in header.splitlines()] + ["#", f"# {QGC_COLUMNS}"]
    for p in sorted(params, key=lambda p: p.name):
        lines.append(f"1\t1\t{p.name}\t{p.text()}\t{p.type}")
    with atomic_write(path) as fh:
        fh.write("\n".join(lines) + "\n")

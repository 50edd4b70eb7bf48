"""The generated MAVLink dialect (firmware/mavlink/heliquad.xml, built by mavgen at install),
and the names the tools give its values.

The dialect is the one definition of every enum and message on both links. The tools name an
axis, an injection point or a flight mode in lower case (``roll``, ``mixer``, ``rate``); those
names and their numbers come from the generated module, never from a copy:

* ``AXES``: HQ_AXIS, ``{"roll": 0, "pitch": 1, "yaw": 2}`` (the value is also the body axis
  index, x y z, in the firmware and the simulator);
* ``INJECTIONS``: HQ_INJECTION, ``{"angle": ..., "rate": ..., "mixer": ...}``;
* ``MODES``: HQ_MODE, ``{"angle": ..., "rate": ...}``;
* ``SIGNALS``: HQ_SIGNAL, ``{"sine": ..., "multisine": ...}``.

They are made on first use, so importing a module that names them does not need the
generated module yet: a missing one is the InputError of :func:`dialect` where it is used.
"""

from __future__ import annotations

import types

from .errors import InputError

# AXES, INJECTIONS, MODES and SIGNALS are made on first use (__getattr__), so not listed here.
__all__ = ["dialect", "enum_values", "NAMED_ENUMS"]

#: The lower-case name sets above: module attribute -> dialect enum.
NAMED_ENUMS = {"AXES": "HQ_AXIS", "INJECTIONS": "HQ_INJECTION", "MODES": "HQ_MODE",
               "SIGNALS": "HQ_SIGNAL"}

_made: dict = {}


def dialect():
    """The generated module ``heliquad._mavlink``; a clear error if the build did not make it."""
    try:
        # the generated dialect (0.1 s) when a message is built or read: every parser imports this
        from heliquad import _mavlink
    except ImportError:
        raise InputError("the MAVLink dialect module is missing: reinstall heliquad "
                         "(pip install .) so the build generates it") from None
    return _mavlink


def enum_values(enum: str) -> dict:
    """``{name: value}`` of a dialect enum, in value order: each entry's name lower-cased,
    without the prefix its entries share (``HQ_AXIS_ROLL`` -> ``roll``, ``HQ_SENSOR_DMP`` ->
    ``dmp``), and without the ``*_ENUM_END`` that mavgen adds."""
    entries = {value: e.name for value, e in dialect().enums[enum].items()
               if not e.name.endswith("_ENUM_END")}
    prefix = _shared_prefix(list(entries.values()))
    return {entries[v][len(prefix):].lower(): v for v in sorted(entries)}


def _shared_prefix(names: list) -> str:
    """The words (``_``-separated) that every name starts with, with the last ``_``; one name
    keeps its last word."""
    words = [n.split("_") for n in names]
    shared = []
    for column in zip(*words):
        if len(set(column)) > 1:
            break
        shared.append(column[0])
    shared = shared[:min(len(w) for w in words) - 1]
    return "".join(w + "_" for w in shared)


def __getattr__(name: str):
    """``AXES``, ``INJECTIONS`` and ``MODES``, made from the dialect on first use (read-only
    mappings)."""
    if name not in NAMED_ENUMS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    if name not in _made:
        _made[name] = types.MappingProxyType(enum_values(NAMED_ENUMS[name]))
    return _made[name]

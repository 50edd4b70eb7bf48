"""A sweep folder's manifest.json (docs/file-formats.md, "A sweep folder"): what the sweep
was (axis, injection, source, design, limits, the board's parameters and gains) and what
each frequency gave, rewritten by ``heliquad sweep`` after every frequency and read by
``heliquad identify``, ``report`` and ``validate``.

:class:`SweepManifest` is the one definition of its keys: the sweep (host/acquire/sweep.py)
fills one in and writes it with :func:`write_manifest`, its fields in the order the file
holds them, and :func:`read_manifest` checks a file against the schema built from the same
fields. A frequency's entry stays a dict (:data:`FREQUENCY`: the sweep adds its keys as the
excitation runs), and the reader returns the checked document as a dict: identify, the
report and validation read manifests of older sweeps too, key by key, with their defaults.
"""

from __future__ import annotations

import dataclasses
import functools
import math

from ...sim.base import dialect as names
from . import schema as S
from .choices import RESPONSES
from .gains import recorded_gains_schema
from .output import document, write_json
from .reading import read_json

__all__ = ["MANIFEST", "SWEEP_SIGNALS", "FREQUENCY", "PORT_FOUND", "UNSET", "SweepManifest",
           "write_manifest", "read_manifest", "excited_seconds", "entry_seconds"]

#: The manifest's name in a sweep folder.
MANIFEST = "manifest.json"
#: A sweep's signal (manifest.json and models.json ``signal``): the paper's dwell, one sine
#: at a time, or one multisine for the whole band.
SWEEP_SIGNALS = ("dwell", "multisine", "chirp")
#: A manifest's loop rate (freq_hz x period_samples), Hz.
LOOP_RANGE_HZ = (1.0, 1e4)
#: Timestamps, us since 1970.
TIME_US = S.Int(0, 2**63 - 1)
#: One frequency's entry of ``frequencies``.
FREQUENCY = S.Obj(
    required={"requested_hz": S.Num(0, 1e6, lo_open=True), "samples": S.Int(0, 2**31),
              "status": S.Str()},
    optional={"amplitude": S.Num(), "freq_hz": S.Num(0, 1e6, lo_open=True),
              "period_samples": S.Int(2, 2**31), "start_us": TIME_US, "end_us": TIME_US,
              "messages": S.List(S.Str()),
              **{k: S.Int(0, 2**31) for k in ("seq_gaps", "saturated", "collective_limited",
                                              "sensor_clipped", "cycles", "lost",
                                              "lost_run", "garbage_bytes")},
              "period_inferred": S.Bool(),
              "dwell_end": S.Str(("target", "cap", "amplitude")),
              "relative_sigma": S.Null(S.Num(0)), "signal": S.Str(tuple(names.SIGNALS)),
              "orders": S.List(S.Int(1, 2**31), 1, 16), "fade_samples": S.Int(0, 2**31),
              # a linearity campaign's multisine: its random phases' realisation, and its
              # amplitude's level (0 the peak asked for, 1 the smaller)
              "realisation": S.Int(0, 2**31), "level": S.Int(0, 1),
              "phases_rad": S.List(S.Num(), 1, 16),
              # a redesigned sequential multisine's second pass: the first pass's entry
              # (its index in frequencies) and the lines' relative amplitudes
              "redesign_of": S.Int(0, 2**31), "weights": S.List(S.Num(0), 1, 16),
              "line_amplitudes": S.List(S.Num(0), 1, 16)})

#: What ``--port auto`` found (``port_found``, only when it chose the sweep's port): a USB
#: device or a board ``heliquad board`` emulates (announced, with the firmware it runs).
PORT_FOUND = S.Obj(required={"source": S.Str(("usb", "heliquad board")),
                             "serial_number": S.Null(S.Str())},
                   optional={"firmware": S.Str()}, strict=True)


class _Unset:
    """The value of a field the file leaves out until it has one."""

    def __repr__(self) -> str:
        return "UNSET"


UNSET = _Unset()


def _key(spec, required: bool = False, **field):
    """A manifest key: its schema ``spec``, whether a file must have it, and its default."""
    return dataclasses.field(metadata={"spec": spec, "required": required}, **field)


@dataclasses.dataclass(kw_only=True)
class SweepManifest:
    """A sweep's manifest.json: its keys, in the file's order, each with its schema (the
    meaning of each: docs/file-formats.md). ``in_progress_hz`` is written only once the
    sweep ended by a signal or an error (the frequency that was running, or None)."""

    axis: str = _key(S.Str(tuple(names.AXES)), required=True)
    inject: str = _key(S.Str(tuple(names.INJECTIONS)), required=True)
    source: dict = _key(S.Obj())
    port_found: dict = _key(PORT_FOUND, default=UNSET)
    firmware: str = _key(S.Str())
    gains: dict | None = _key(S.Null(recorded_gains_schema()), default=None)
    params: dict | None = _key(S.Null(S.Obj(values=S.Num())), default=None)
    started: str = _key(S.Str())
    tlog: str = _key(S.Str(file_name=True))
    tlog_start_us: int | None = _key(S.Null(TIME_US))
    cycles: int = _key(S.Int(1, 65535))
    fade_cycles: int = _key(S.Int(1, 65535))
    design: dict = _key(S.Obj())
    limits: dict = _key(S.Obj(values=S.Num()))
    signal: str = _key(S.Str(SWEEP_SIGNALS))
    planned_hz: list = _key(S.List(S.Num(0, 1e6, lo_open=True), 0, 10_000))
    response: str = _key(S.Str(RESPONSES), default=UNSET)
    frequencies: list = _key(S.List(FREQUENCY, 0, 10_000), required=True,
                             default_factory=list)
    complete: bool = _key(S.Bool(), default=False)
    aborted: str | None = _key(S.Null(S.Str()), default=None)
    in_progress_hz: float | None = _key(S.Null(S.Num()), default=UNSET)

    def document(self) -> dict:
        """The manifest as its JSON document: every key that has a value (None included,
        written as null), in field order."""
        return document(self, absent=UNSET)


def write_manifest(path, manifest: SweepManifest) -> None:
    """``manifest`` to ``path``, atomically (the previous version stays whole when this one
    cannot be written)."""
    write_json(path, manifest.document())


@functools.cache
def _manifest_schema():
    keys = {f.name: f.metadata for f in dataclasses.fields(SweepManifest)}
    return S.Obj(required={k: m["spec"] for k, m in keys.items() if m["required"]},
                 optional={k: m["spec"] for k, m in keys.items() if not m["required"]})


def _check_orders(path, key, entry) -> None:
    """A multisine's lines: strictly increasing, each at least four samples per cycle."""
    orders = entry.get("orders")
    if orders is None:
        S.fail(path, f"{key}.orders", "is missing (a multisine whose status is ok)")
    if any(b <= a for a, b in zip(orders, orders[1:])):
        S.fail(path, f"{key}.orders", "must be strictly increasing", orders)
    if 4 * orders[-1] > entry["period_samples"]:
        S.fail(path, f"{key}.orders", f"the highest line has fewer than 4 samples per cycle of "
               f"the {entry['period_samples']}-sample period", orders[-1])


def read_manifest(path) -> dict:
    """A sweep folder's manifest.json, checked (docs/file-formats.md): every frequency that
    is ``ok`` has the frequency, period and sample window identification needs."""
    doc = read_json(path, "sweep manifest (manifest.json)", _manifest_schema())
    if doc["axis"] == "yaw" and doc["inject"] == "angle":
        S.fail(path, "inject", "angle is not possible on yaw (rate only)")
    for i, entry in enumerate(doc["frequencies"]):
        key = f"frequencies[{i}]"
        if entry["status"] == "ok":
            for name in ("freq_hz", "period_samples", "start_us", "end_us"):
                if name not in entry:
                    S.fail(path, f"{key}.{name}", "is missing (the frequency's status is ok)")
        if entry["status"] == "ok" and entry.get("signal") == "multisine":
            _check_orders(path, key, entry)
        if entry.get("redesign_of", -1) >= i:
            S.fail(path, f"{key}.redesign_of", "must name an earlier entry (its first pass)",
                   entry["redesign_of"])
        if "start_us" in entry and entry["start_us"] > entry.get("end_us", math.inf):
            S.fail(path, f"{key}.end_us", "is before start_us", entry["end_us"])
        if "freq_hz" in entry and "period_samples" in entry:
            loop_hz = entry["freq_hz"] * entry["period_samples"]
            if not LOOP_RANGE_HZ[0] <= loop_hz <= LOOP_RANGE_HZ[1]:
                S.fail(path, key, f"freq_hz x period_samples, the loop rate, is {loop_hz:g} Hz; "
                       f"it must be in [{LOOP_RANGE_HZ[0]:g}, {LOOP_RANGE_HZ[1]:g}] Hz")
    return doc


def excited_seconds(manifest: dict) -> float:
    """The seconds the rig flew excited: each measured excitation's (:func:`entry_seconds`).
    The time between excitations, which a log's span also counts, is left out."""
    return sum(entry_seconds(e, manifest["fade_cycles"]) for e in manifest["frequencies"]
               if "period_samples" in e and "samples" in e)


def entry_seconds(entry: dict, fade_cycles: int) -> float:
    """One measured excitation's seconds excited: its full-amplitude window (its samples and
    those lost on the link) and its two fades (a dwell's ``fade_cycles`` cycles of its
    frequency, a multisine's or chirp's ``fade_samples``), at the loop rate the entry gives
    (``freq_hz`` x ``period_samples``)."""
    fade = entry.get("fade_samples", fade_cycles * entry["period_samples"])
    return (entry["samples"] + entry.get("lost", 0) + 2 * fade) / (entry["freq_hz"] *
                                                                   entry["period_samples"])

"""An ArduPilot DataFlash log (.BIN) with ArduCopter's SystemID mode in it, read for analysis.

ArduCopter's SystemID mode (the mode that injects a chirp, set up by its ``SID_*``
parameters) logs, as documented in ArduPilot's log message reference:

- **SIDS** once as the mode starts: ``Ax`` (``SID_AXIS``: what is excited), ``Mag`` (the
  chirp's amplitude), ``FSt`` and ``FSp`` (its start and stop frequencies, Hz), ``TFin``,
  ``TC``, ``TR``, ``TFout`` (fade-in, constant-frequency, record and fade-out times, s);
- **SIDD** every loop while it runs: ``Time`` (s into the excitation), ``Targ`` (the
  chirp's sample, added where ``Ax`` says), ``F`` (its frequency then, Hz), the IMU's rates
  and accelerations;
- **RATE** (``RDes``, ``R``, ``ROut`` and pitch's and yaw's: the rate controllers' targets
  and measured rates in deg/s and their outputs into the mixer) and **ATT** (``DesRoll``,
  ``Roll``, ...: desired and estimated attitude, deg) every loop too, which the mode logs at
  the loop's rate.

A **segment** is one run of the excitation: the SIDD records from one start (``Time`` back to
its beginning, or a SIDS between) to the next, with the SIDS logged before it. Each SIDD is
matched with the RATE and ATT records of its loop: the nearest in time, within half the
loop's period (a loop whose record is missing has NaN there). pymavlink's DFReader parses the
file; a byte it cannot parse is skipped, as every DataFlash tool does (an ArduPilot log has
no checksum, and this reader cannot check what ArduPilot's logger promises as
:mod:`.bin_log` checks heliquad's own).
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os

import numpy as np

from ...sim.base.errors import InputError
from .bin_log import BinDamage, open_log

__all__ = ["ArduPilotLog", "SidSegment", "read_ardupilot", "RATE_FIELDS", "ATT_FIELDS"]

#: RATE's fields per axis: target rate, measured rate (deg/s), output into the mixer.
RATE_FIELDS = {"roll": ("RDes", "R", "ROut"), "pitch": ("PDes", "P", "POut"),
               "yaw": ("YDes", "Y", "YOut")}
#: ATT's fields per axis: desired and estimated angle (deg).
ATT_FIELDS = {"roll": ("DesRoll", "Roll"), "pitch": ("DesPitch", "Pitch"),
              "yaw": ("DesYaw", "Yaw")}
_SIDS = ("TimeUS", "Ax", "Mag", "FSt", "FSp", "TFin", "TC", "TR", "TFout")
_SIDD = ("TimeUS", "Time", "Targ", "F")
#: RATE's and ATT's fields read: the time and every axis's.
_COLUMNS = {"RATE": ("TimeUS", *(n for names in RATE_FIELDS.values() for n in names)),
            "ATT": ("TimeUS", *(n for names in ATT_FIELDS.values() for n in names))}
#: The records read; the rest of the log is not.
_WANTED = ("SIDS", "SIDD", "RATE", "ATT", "PARM", "MSG")


@dataclasses.dataclass
class SidSegment:
    """One run of the SystemID excitation: its set-up (SIDS's fields, None when the log holds
    no SIDS before it) and per loop (SIDD's), SIDD's time (us), ``Targ``, ``F`` (Hz), and
    the loop's RATE and ATT fields by name (NaN where the loop has none)."""
    setup: dict | None
    time_us: np.ndarray
    target: np.ndarray
    freq_hz: np.ndarray
    fields: dict


@dataclasses.dataclass
class ArduPilotLog:
    """An ArduPilot log's SystemID segments, its parameters and the firmware it names."""
    segments: list
    params: dict
    version: str | None         # the first MSG naming the vehicle's firmware
    damage: BinDamage


def read_ardupilot(path, reader=None) -> ArduPilotLog:
    """The SystemID segments of the ArduPilot log at ``path`` (module docstring); ``reader``:
    the log already opened by :func:`~.bin_log.open_log`. InputError when it has no SystemID
    record."""
    if reader is None:
        reader, _ = open_log(path)
    if not {"SIDS", "SIDD"} & set(reader.name_to_id):
        raise InputError(f"{path}: an ArduPilot log without SystemID records (SIDS, SIDD): "
                         "ArduCopter's SystemID mode never ran in it")
    found = _Found()
    damage = BinDamage(size=os.path.getsize(path))
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        while (m := reader.recv_match(type=list(_WANTED))) is not None:
            try:
                found.take(m)
            except (AttributeError, TypeError, ValueError) as exc:
                at = reader.offset - m.fmt.len
                damage.why = (f"a {m.get_type()} record that does not read as its format "
                              f"says ({exc}): the log is damaged there")
                damage.regions.append((at, damage.size - at))
                break
    if not found.rows["SIDD"]:
        raise InputError(f"{path}: the log defines SystemID's records but holds no SIDD "
                         "sample: the mode never ran an excitation"
                         + (f" ({damage.summary()})" if damage else ""))
    sidd = np.array(found.rows["SIDD"], dtype=float)
    tables = {kind: _table(found.rows[kind]) for kind in _COLUMNS}
    segments = [_segment(sidd[part], found.rows["SIDS"], found.sids_before[part[0]], tables)
                for part in _cut(sidd[:, 1], found.sids_before)]
    return ArduPilotLog(segments, found.params, found.version, damage)


class _Found:
    """The records read, in file order: SIDS and SIDD's fields, the RATE and ATT records, the
    parameters and the firmware named."""

    def __init__(self):
        self.rows = {name: [] for name in _WANTED}
        self.params, self.version, self.sids_before = {}, None, []

    def take(self, m) -> None:
        """One record; AttributeError (a field its format lacks), TypeError or ValueError
        (a value that is not a number) for one that does not read as expected."""
        kind = m.get_type()
        if kind == "PARM":
            self.params[str(m.Name)] = float(m.Value)
        elif kind == "MSG":
            self.version = self.version or _version(str(m.Message))
        elif kind == "SIDS":
            self.rows["SIDS"].append({k: float(getattr(m, k)) for k in _SIDS})
        elif kind == "SIDD":
            self.rows["SIDD"].append(tuple(float(getattr(m, k)) for k in _SIDD))
            self.sids_before.append(len(self.rows["SIDS"]))
        else:
            self.rows[kind].append(tuple(float(getattr(m, k)) for k in _COLUMNS[kind]))


def _version(text: str) -> str | None:
    """A MSG naming the vehicle's firmware ("ArduCopter V4.5.7 (...)"), or None."""
    text = text.strip()
    return text if text.startswith("Ardu") else None


def _cut(wave_time_s, sids_before) -> list:
    """Each segment's SIDD rows (index arrays): a new one where ``Time`` goes back or a SIDS
    came between."""
    before = np.asarray(sids_before)
    starts = np.flatnonzero((np.diff(wave_time_s) < 0) | (np.diff(before) != 0)) + 1
    return np.split(np.arange(wave_time_s.size), starts)


def _table(records):
    """RATE's or ATT's records as an array, its rows in time order (a damaged log's times may
    not rise); None without records."""
    if not records:
        return None
    table = np.array(records, dtype=float)
    return table[np.argsort(table[:, 0], kind="stable")]


def _segment(sidd, setups, sids_before: int, tables) -> SidSegment:
    """The segment of SIDD rows ``sidd`` (TimeUS, Time, Targ, F): the SIDS logged before it
    (the ``sids_before``-th of ``setups``) and its loops' matched RATE and ATT ``tables``."""
    time_us = sidd[:, 0]
    setup = setups[sids_before - 1] if sids_before else None
    loop_us = float(np.median(np.diff(time_us))) if time_us.size > 1 else 0.0
    fields = {}
    for kind, table in tables.items():
        fields.update(_matched(table, _COLUMNS[kind], time_us, loop_us / 2))
    return SidSegment(setup, time_us, sidd[:, 2], sidd[:, 3], fields)


def _matched(table, columns, time_us, within_us) -> dict:
    """``{name: values at time_us}`` of ``columns`` (``TimeUS`` first) from the rows of
    ``table`` (:func:`_table`) nearest in time to each, within ``within_us`` (NaN where none
    is); ``{}`` without a table."""
    if table is None:
        return {}
    t, values = table[:, 0], table[:, 1:]
    last = t.size - 1
    after = np.clip(np.searchsorted(t, time_us), 0, last)
    before = np.clip(after - 1, 0, last)
    nearest = np.where(np.abs(t[after] - time_us) < np.abs(t[before] - time_us), after, before)
    ok = np.abs(t[nearest] - time_us) <= within_us
    picked = np.where(ok[:, None], values[nearest], np.nan)
    return {n: picked[:, i] for i, n in enumerate(columns[1:])}

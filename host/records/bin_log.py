"""A board's on-board log (LOGS/0000000N.BIN: ArduPilot's DataFlash format, docs/file-formats.md
and docs/dataflash-log.md) read for analysis: each logged loop's sample (HQSD and HQMT) as a
row of the telemetry's HQ_SYSID_SAMPLE record array (the one :func:`.tlog.read_tlog_table`
gives, so a log and a telemetry log go into the same analysis), with its SIDD (time into the
excitation, its frequency), the excitations' set-ups (SIDS), the parameters (PARM) and the
gap records (HQGP).

pymavlink's DFReader parses the records. A DataFlash log has no checksum, so the reader checks
what the format and the firmware's logger promise: the records follow one another with no byte
between them (DFReader skips bytes it cannot parse), a loop's SIDD, HQSD and HQMT come together
with one time, the loops' numbers rise and a loop missing from the log follows a gap record (or
an arming that continues the log), times never go back, and a sample's axis, injection point
and state are the dialect's. The log is read up to the first place that breaks one of these (a
log cut mid-record, a flipped byte in a record's header or its numbers, garbage after a point);
what follows it is not used, and what was left out is a :class:`BinDamage` (the tlog's
:class:`~.tlog.TlogDamage` with one region, from there to the file's end, and why). A flipped
bit in a float that keeps it a number is not seen.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import os

import numpy as np
from pymavlink import DFReader

from ...sim.base.dialect import AXES, INJECTIONS, dialect
from ...sim.base.errors import InputError
from ...sim.base.userfiles import open_binary
from .tlog import TlogDamage, message_dtype

__all__ = ["BinLog", "BinDamage", "read_bin", "open_log", "is_ardupilot_log", "is_bin_name",
           "BIN_SUFFIX"]

#: The on-board logs' file names end so (LOGS/00000001.BIN; any case).
BIN_SUFFIX = ".bin"
#: HQSD's fields and HQMT's motors as HQ_SYSID_SAMPLE's (docs/file-formats.md's table).
_HQSD_FIELDS = {"TimeUS": "time_us", "Seq": "seq", "Axis": "axis", "Inj": "injection",
                "ESt": "exc_state", "Arm": "armed", "Mode": "mode", "Exc": "excitation",
                "ASP": "angle_sp", "RSP": "rate_sp", "Rate": "rate", "Ang": "angle",
                "Cmd": "axis_cmd", "Sat": "saturation"}
_MOTORS = tuple(f"M{i}" for i in range(1, 6))        # HQMT's M1..M5: motor[0..4]
_MORE_MOTORS = ("M6", "M7", "M8")                     # HQMX's: motor[5..7], with MCnt
#: The rotor count of a loop with no HQMX: the paper's vehicle's.
_HQMT_ROTORS = 5
#: SIDS's set-up fields (ArduPilot's names).
_SIDS_FIELDS = ("TimeUS", "Ax", "Mag", "FSt", "FSp", "TFin", "TC", "TR", "TFout")


def is_bin_name(path) -> bool:
    """True for a file name of an on-board log (``.BIN``, any case)."""
    return os.fspath(path).lower().endswith(BIN_SUFFIX)


@dataclasses.dataclass
class BinDamage(TlogDamage):
    """Where a .BIN's reading stopped (its one region: from there to the file's end) and why;
    models.json records it as a tlog's damage."""
    why: str = ""
    KEPT = "the records before it were read"

    def summary(self) -> str:
        if not self.regions:
            return ""
        at, left = self.regions[0]
        return (f"read up to byte {at} of {self.size}, the {left} bytes from there not used: "
                f"{self.why or 'no whole record (the log is cut there, or garbage follows)'}")


@dataclasses.dataclass
class BinLog:
    """What a .BIN holds for analysis, up to its first damage (``damage``)."""
    samples: np.recarray            # a row per logged loop, HQ_SYSID_SAMPLE's fields
    exc_time_s: np.ndarray          # SIDD's Time: s since the loop's excitation started
    exc_freq_hz: np.ndarray         # SIDD's F: the excitation's (base) frequency, 0 idle
    setups: list                    # SIDS records as {field: value}, in order
    params: dict                    # PARM: {name: value}, the last value of each
    gaps: list                      # HQGP records as (TimeUS, Dropped, SinceUS)
    damage: BinDamage


class _Reader(DFReader.DFReader_binary):
    """DFReader with its indexer in Python: pymavlink's C indexer prints each byte it skips
    on the process's stderr, out of reach of :func:`contextlib.redirect_stderr`."""

    def init_arrays_fast(self, progress_callback=None):
        self.init_arrays(progress_callback=progress_callback)


class _Collector:
    """The records in file order, checked as the logger writes them; :meth:`take` says why a
    record breaks the log's promises (None when it keeps them)."""

    def __init__(self):
        mav = dialect()
        self.states = {mav.HQ_EXCITATION_STATE_IDLE, mav.HQ_EXCITATION_STATE_FADING,
                       mav.HQ_EXCITATION_STATE_RUNNING}
        self.axes, self.injections = set(AXES.values()), set(INJECTIONS.values())
        self.rows, self.sidd, self.setups, self.params, self.gaps = [], [], [], {}, []
        self.pending: list = []          # the loop's SIDD (and HQSD) waiting for the rest
        self.last_time_us, self.last_seq, self.gap_since = 0, None, False
        self.last_loop_us = None         # the time of the last whole loop (its HQMX's)

    def take(self, m) -> str | None:
        kind = m.get_type()
        time_us = getattr(m, "TimeUS", None)
        if time_us is not None:
            if time_us < self.last_time_us:
                return f"a {kind} record goes back in time"
            self.last_time_us = time_us
        if self.pending and kind != ("HQSD" if len(self.pending) == 1 else "HQMT"):
            return f"a loop's sample is not whole (a {kind} record inside it)"
        if kind == "SIDD":
            self.pending = [m]
        elif kind == "HQSD":
            return self._sample(m)
        elif kind == "HQMT":
            return self._motors(m)
        elif kind == "HQMX":
            return self._more_motors(m)
        elif kind == "SIDS":
            self.setups.append({k: getattr(m, k) for k in _SIDS_FIELDS})
        elif kind == "PARM":
            self.params[m.Name] = float(m.Value)
        elif kind == "HQGP":
            self.gaps.append((m.TimeUS, m.Dropped, m.SinceUS))
            self.gap_since = True
        elif kind == "EV":          # an arming that continues the log: the disarmed loops
            self.gap_since = True   # are not in it
        return None

    def _sample(self, m) -> str | None:
        if not self.pending:
            return "an HQSD record without its loop's SIDD"
        if m.TimeUS != self.pending[0].TimeUS:
            return "a loop's records are not of one time"
        if (m.Axis not in self.axes or m.Inj not in self.injections or
                m.ESt not in self.states or m.Arm not in (0, 1)):
            return f"loop {m.Seq}'s axis, injection point or state is not the dialect's"
        if self.last_seq is not None and (
                m.Seq <= self.last_seq or (m.Seq != self.last_seq + 1 and not self.gap_since)):
            return f"loop {m.Seq} does not follow loop {self.last_seq}"
        self.pending.append(m)
        return None

    def _motors(self, m) -> str | None:
        if len(self.pending) != 2:
            return "an HQMT record without its loop's SIDD and HQSD"
        sidd, hqsd = self.pending
        if m.TimeUS != hqsd.TimeUS:
            return "a loop's records are not of one time"
        self.rows.append(tuple(getattr(hqsd, k) for k in _HQSD_FIELDS)
                         + (tuple(getattr(m, k) for k in _MOTORS) + (0.0,) * 3, _HQMT_ROTORS))
        self.last_loop_us = m.TimeUS
        self.sidd.append((sidd.Time, sidd.F))
        self.pending, self.last_seq, self.gap_since = [], hqsd.Seq, False
        return None

    def _more_motors(self, m) -> str | None:
        """HQMX: the loop just read has another rotor count than five, and motors 6 to 8."""
        if not self.rows or m.TimeUS != self.last_loop_us:
            return "an HQMX record without its loop's HQMT"
        *fields, motors, _ = self.rows[-1]
        self.rows[-1] = (*fields, motors[:5] + tuple(getattr(m, k) for k in _MORE_MOTORS),
                         m.MCnt)
        return None

    def log(self, damage: BinDamage) -> BinLog:
        dtype = message_dtype(dialect(), "HQ_SYSID_SAMPLE")
        by_name = [*_HQSD_FIELDS.values(), "motor", "motor_count"]
        rows = np.zeros(len(self.rows), dtype=dtype)
        for i, name in enumerate(by_name if self.rows else ()):
            rows[name] = [r[i] for r in self.rows]
        sidd = np.array(self.sidd, dtype=float).reshape(-1, 2)
        return BinLog(rows.view(np.recarray), sidd[:, 0], sidd[:, 1], self.setups,
                      self.params, self.gaps, damage)


def _taken(collector, m) -> str | None:
    """:meth:`_Collector.take`, a record whose format lacks a field it reads (a damaged FMT)
    a damage like any other."""
    try:
        return collector.take(m)
    except AttributeError as exc:
        return f"a {m.get_type()} record without its field {exc} (its format is damaged)"


def _size(path) -> int:
    """The file's size; InputError, naming it, for a missing, unreadable or empty file or a
    folder."""
    with open_binary(path, ".BIN log") as fh:
        size = os.fstat(fh.fileno()).st_size
    if size == 0:
        raise InputError(f"{path}: empty file (expected a .BIN log)")
    return size


def open_log(path) -> tuple:
    """``(reader, size)``: the DataFlash log at ``path`` opened by DFReader (its formats
    read, its records indexed). InputError naming the file when it cannot be."""
    size = _size(path)
    # DFReader prints what it skips and cannot parse; the damage is said once, by the caller.
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        try:
            return _Reader(os.fspath(path)), size
        # DFReader raises a bare Exception for a format it cannot take (a damaged FMT record)
        except Exception as exc:                # noqa: BLE001 - said as the file's fault
            raise InputError(f"{path}: not a DataFlash log ({exc})") from None


def is_ardupilot_log(reader) -> bool:
    """The log a DFReader has opened is ArduPilot's, not heliquad's: it does not define
    heliquad's sample (HQSD) and defines RATE or ATT, which ArduCopter logs in every flight
    and heliquad's firmware never does."""
    names = reader.name_to_id
    return "HQSD" not in names and bool({"RATE", "ATT"} & set(names))


def read_bin(path, opened=None) -> BinLog:
    """The .BIN at ``path`` up to its first damage (:class:`BinLog`; module docstring);
    ``opened``: :func:`open_log`'s answer when the caller has it. InputError naming the file
    when it cannot be read, holds no DataFlash record or is another autopilot's log."""
    reader, size = opened or open_log(path)
    if is_ardupilot_log(reader):
        raise InputError(f"{path}: not a log of heliquad's firmware (no HQSD record defined): "
                         "an ArduPilot log's SystemID segments are read by heliquad identify")
    collector, damage = _Collector(), BinDamage(size=size)
    end = 0
    with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
        while (m := reader.recv_msg()) is not None:
            if reader.offset - m.fmt.len != end:        # DFReader skipped bytes
                damage.why = "bytes that are no record (damage, or garbage)"
                break
            if (why := _taken(collector, m)) is not None:
                damage.why, end = why, reader.offset - m.fmt.len
                break
            end, damage.messages = reader.offset, damage.messages + 1
    if damage.messages == 0:
        raise InputError(f"{path}: not a DataFlash log (no record at its start)")
    if end < size:
        damage.regions.append((end, size - end))
    return collector.log(damage)

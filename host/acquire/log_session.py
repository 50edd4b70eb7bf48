"""Serial logging sessions (``heliquad log``) and log summaries (``heliquad tlog``).

A session opens the telemetry link of a board (or of a SIL / ``heliquad board`` pty), writes
every packet to a .tlog as it arrives (flushed as it goes, so Ctrl-C, a crash or a full disk
leaves a valid log up to its last whole record), sends the host's HEARTBEAT every 0.25 s, and
counts lost samples from the gaps in ``HQ_SYSID_SAMPLE.seq``.
"""

from __future__ import annotations

import collections
import time

from ...sim.base.dialect import dialect
from ...sim.base.errors import DiskFull, InputError
from ..records.tlog import TlogDamage, TlogWriter, read_tlog
from .link import DEFAULT_BAUD, HEARTBEAT_PERIOD_S, TelemetryLink

__all__ = ["run_log", "summarise_tlog"]

POLL_S = 0.01
STATUS_EVERY_S = 5.0


def run_log(port: str, out: str, baud: int = DEFAULT_BAUD, duration_s: float | None = None,
            progress=print) -> dict:
    """Log until ``duration_s``, Ctrl-C (or SIGTERM), the link going away or a full disk;
    returns the summary of what the log holds. ``stopped``: why the session ended early
    (an :class:`InputError` for the link, :class:`DiskFull` for the log), else None;
    ``interrupted``: the KeyboardInterrupt (Ctrl-C, or SIGTERM / SIGHUP as
    :class:`~heliquad.sim.base.errors.Terminated`) that ended it, else None: the caller says so
    and exits with its code once the summary is out."""
    link = TelemetryLink(port, baud=baud)          # the port first: a bad one creates nothing
    try:
        tlog = link.tlog = TlogWriter(out)
    except BaseException:
        link.close()
        raise
    stats = {"messages": 0, "samples": 0, "lost": 0, "first_seq": None, "last_seq": None}
    t0 = time.monotonic()
    next_status, next_heartbeat = t0 + STATUS_EVERY_S, t0
    interrupted, stopped = None, None
    try:
        while duration_s is None or time.monotonic() - t0 < duration_s:
            now = time.monotonic()
            if now >= next_heartbeat:
                link.heartbeat()
                next_heartbeat = now + HEARTBEAT_PERIOD_S
            samples = link.poll(only=("HQ_SYSID_SAMPLE",))
            tlog.flush()                         # counted once they are in the file
            for m in samples:
                _count(stats, m.seq)
            stats["messages"] = tlog.messages
            if now >= next_status:
                progress(f"  {now - t0:6.0f} s  {stats['samples']} samples, {stats['lost']} lost, "
                         f"{stats['messages']} messages")
                next_status = now + STATUS_EVERY_S
            time.sleep(POLL_S)
    except KeyboardInterrupt as exc:
        interrupted = exc
    except (InputError, DiskFull) as exc:        # the link went away; no room for the log
        stopped = exc
    finally:
        link.close()
        try:
            tlog.close()
        except DiskFull as exc:                  # the last records did not fit
            stopped = stopped or exc
    stats["messages"] = tlog.messages
    stats["seconds"] = time.monotonic() - t0
    stats["interrupted"] = interrupted
    stats["stopped"] = stopped
    return stats


def _count(stats, seq):
    if stats["last_seq"] is not None and seq > stats["last_seq"] + 1:
        stats["lost"] += seq - stats["last_seq"] - 1
    if stats["first_seq"] is None:
        stats["first_seq"] = seq
    stats["last_seq"] = seq
    stats["samples"] += 1


def summarise_tlog(path: str) -> dict:
    """Message counts, time span and lost samples of a .tlog, and what damage was skipped."""
    damage = TlogDamage()
    try:
        msgs = read_tlog(path, dialect(), damage=damage)
    except OSError as exc:
        raise InputError(f"{path}: {exc.strerror or exc}") from None
    stats = {"messages": len(msgs), "samples": 0, "lost": 0, "first_seq": None,
             "last_seq": None, "types": collections.Counter(m.get_type() for _, m in msgs),
             "damage": f"{path} is damaged: {damage.summary()}" if damage else None,
             "bytes": damage.size}
    for _, m in msgs:
        if m.get_type() == "HQ_SYSID_SAMPLE":
            _count(stats, m.seq)
    stats["span_s"] = (msgs[-1][0] - msgs[0][0]) * 1e-6 if msgs else 0.0
    return stats

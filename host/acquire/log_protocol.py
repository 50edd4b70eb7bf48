"""The MAVLink log protocol from the host (``heliquad logs``): the board's on-board logs
listed, downloaded and erased over the telemetry link (any connection
:mod:`heliquad.host.acquire.connection` opens).

The protocol (MAVLink's common messages, as the firmware serves it, docs/ground-stations.md):

* LOG_REQUEST_LIST: one LOG_ENTRY (id, num_logs, last_log_num, time_utc, size) per log, or
  one with num_logs 0 when there are none; entries lost on the way are asked for again with
  the whole list, a few rounds;
* LOG_REQUEST_DATA (id, offset, count): LOG_DATA packets of up to 90 bytes in order; a
  packet lost on the way leaves a gap, and the rest is asked for again from the gap (a new
  request replaces the one under way on the board). What has come is kept in ``OUT.part``
  as it comes, so a download cut off (a link gone, the tool stopped) resumes where it
  stopped when run again; the whole file is checked against the size LOG_ENTRY gave and
  written atomically;
* LOG_ERASE: the board says ``logs: erased`` (or ``logs: erase failed``);
* LOG_REQUEST_END when a download is whole.

The board serves its logs only while disarmed: armed, it says ``logs: disarm to download``
once and answers nothing, which is :class:`LogsRefused` here (exit 1).
"""

from __future__ import annotations

import dataclasses
import os
import time

from ...sim.base.errors import BoardRefused, InputError
from ..records.output import atomic_write
from .exchange import ANSWER_WAIT_S, POLL_S, QUIET_S, RETRIES, Exchange, NoAnswer

__all__ = ["LogEntry", "LogClient", "LogsRefused", "NoAnswer", "part_path"]

MESSAGES = ("LOG_ENTRY", "LOG_DATA", "STATUSTEXT", "HEARTBEAT")
#: LOG_DATA.data: the most bytes one packet carries.
LOG_DATA_BYTES = 90
#: A gap in the data (a packet lost) waits this long before the rest is asked for again
#: from it: packets come in order, so a gap is a loss, but the request goes out once, not
#: once a packet that follows it.
GAP_WAIT_S = 0.05
#: The firmware's words (firmware/core/link/log_transfer.hpp).
ARMED_TEXT = "logs: disarm to download"
ERASED_TEXT, ERASE_FAILED_TEXT = "logs: erased", "logs: erase failed"
READ_FAILED_TEXT = "logs: read failed"
#: How many progress lines a download prints (one at each tenth).
PROGRESS_STEPS = 10


@dataclasses.dataclass(frozen=True)
class LogEntry:
    """One log as LOG_ENTRY gave it: its number, size and UTC time (0: unknown)."""
    id: int
    size_bytes: int
    time_utc_s: int


class LogsRefused(BoardRefused):
    """The board would not serve its logs (armed) or could not (its card failed)."""


def part_path(out) -> str:
    """Where a download keeps what has come until it is whole: ``OUT.part``."""
    return os.fspath(out) + ".part"


class LogClient(Exchange):
    """The host's side of the log protocol over a
    :class:`~heliquad.host.acquire.link.TelemetryLink`. ``progress`` is told what a
    download does (one line at a time); ``answer_wait_s``, ``retries`` and ``quiet_s`` bound
    every wait."""

    messages = MESSAGES
    silent_hint = "is the board running, with a firmware that serves its logs, on this link?"

    def __init__(self, link, progress=None, answer_wait_s: float = ANSWER_WAIT_S,
                 retries: int = RETRIES, quiet_s: float = QUIET_S):
        super().__init__(link, progress, answer_wait_s, retries, quiet_s)
        self.entries: dict[int, LogEntry] = {}
        self.num_logs = None                      # as the last LOG_ENTRY said
        self.texts: list[str] = []                # STATUSTEXTs since the last request
        self.download_id = None
        self.chunks: dict[int, bytes] = {}        # LOG_DATA of the download, by offset
        # The last data request: when it went, and the highest offset that had come by then
        # (packets past it may still be the stream it replaced, on their way).
        self.asked_at, self.floor = 0.0, -1

    def _handle(self, m) -> None:
        kind = m.get_type()
        if kind == "STATUSTEXT":
            self.texts.append(m.text)
        elif kind == "LOG_ENTRY":
            self.num_logs = int(m.num_logs)
            if m.num_logs:
                self.entries[int(m.id)] = LogEntry(int(m.id), int(m.size), int(m.time_utc))
        elif int(m.id) == self.download_id:
            self.chunks[int(m.ofs)] = bytes(m.data[:m.count])

    def _said(self, start: str) -> str | None:
        return next((t for t in self.texts if t.startswith(start)), None)

    def _request(self, send, done, what: str) -> None:
        """:meth:`_ask`, refused (:class:`LogsRefused`) when the board says it is armed or,
        silent, its heartbeat says so."""
        self.texts.clear()
        try:
            self._ask(send, lambda: done() or self._said(ARMED_TEXT) is not None, what)
        except NoAnswer:
            if self.armed:
                raise self._armed() from None
            raise
        if self._said(ARMED_TEXT) is not None:
            raise self._armed()

    @staticmethod
    def _armed() -> LogsRefused:
        return LogsRefused("the board is armed: it serves its logs only while disarmed "
                           "(it says \"" + ARMED_TEXT + "\")")

    # --- list ----------------------------------------------------------------------------

    def list(self) -> list[LogEntry]:
        """Every log on the board, oldest first (the list asked for again, ``retries``
        rounds, until every entry the board counts has come)."""
        self.entries, self.num_logs = {}, None
        self._request(self.link.request_log_list, lambda: self.num_logs is not None,
                      "the log list request (LOG_REQUEST_LIST)")
        for _ in range(1 + self.retries):
            self._pump_while(lambda: len(self.entries) < self.num_logs,
                             lambda: len(self.entries))
            if len(self.entries) >= self.num_logs:
                break
            self.link.request_log_list()
        if len(self.entries) < self.num_logs:
            raise NoAnswer(f"the board listed {len(self.entries)} of its {self.num_logs} logs "
                           f"after {1 + self.retries} requests on {self.link.name}")
        return [self.entries[i] for i in sorted(self.entries)]

    def entry(self, log_id: int) -> LogEntry:
        """Log ``log_id`` as the board lists it; InputError when it has none of that number."""
        logs = self.list()
        for e in logs:
            if e.id == log_id:
                return e
        have = f"its logs are {logs[0].id}..{logs[-1].id}" if logs else "it has no logs"
        raise InputError(f"the board has no log {log_id} ({have})")

    # --- erase ---------------------------------------------------------------------------

    def erase(self) -> None:
        """LOG_ERASE, until the board says it erased (LogsRefused when it says it could not)."""
        self._request(self.link.erase_logs,
                      lambda: self._said(ERASED_TEXT) is not None or
                      self._said(ERASE_FAILED_TEXT) is not None,
                      "the erase request (LOG_ERASE)")
        if self._said(ERASE_FAILED_TEXT) is not None:
            raise LogsRefused(f'the board could not erase its logs (it says "{ERASE_FAILED_TEXT}")')

    # --- download ------------------------------------------------------------------------

    def download(self, entry: LogEntry, out) -> int:
        """Log ``entry`` into the file ``out`` (written atomically once whole and checked
        against the entry's size), resuming from ``out``.part; returns the bytes resumed
        from. A link that stops answering leaves what came in ``out``.part (NoAnswer)."""
        part = part_path(out)
        have = _read_part(part, entry.size_bytes)
        resumed = len(have)
        if resumed:
            self.progress(f"resuming log {entry.id} at {resumed} of {entry.size_bytes} bytes "
                          f"({part})")
        self.download_id, self.chunks = entry.id, {}
        self.texts.clear()
        shown = [resumed * PROGRESS_STEPS // max(entry.size_bytes, 1)]
        try:
            with _open_part(part, have) as fh:
                self._fetch(entry, have, fh, shown)
        finally:
            self.download_id = None
        self.link.end_log_transfer()
        if len(have) != entry.size_bytes:
            raise LogsRefused(f"log {entry.id} ended at {len(have)} bytes of the "
                              f"{entry.size_bytes} its entry gave; what came is in {part}")
        with atomic_write(out, "wb") as fh:
            fh.write(have)
        os.unlink(part)
        return resumed

    def _fetch(self, entry: LogEntry, have: bytearray, fh, shown: list) -> None:
        """Ask for the rest from the end of ``have`` until it is whole: again after a gap or
        a quiet spell, giving up after ``retries`` requests in a row that brought nothing."""
        fruitless, self.floor = 0, entry.size_bytes        # no stream before the first
        while len(have) < entry.size_bytes:
            before = len(have)
            self._reach()
            self.link.request_log_data(entry.id, before, entry.size_bytes - before)
            self.asked_at = time.monotonic()
            ended = self._receive(entry, have, fh, shown)
            if ended:
                return
            fruitless = 0 if len(have) > before else fruitless + 1
            if fruitless > self.retries:
                if self.armed:
                    raise self._armed()
                raise NoAnswer(f"log {entry.id}: no data from {self.link.name} after "
                               f"{fruitless} requests; {len(have)} of {entry.size_bytes} bytes "
                               f"kept in {fh.name}: run again to resume")

    def _receive(self, entry: LogEntry, have: bytearray, fh, shown: list) -> bool:
        """Take the data in order into ``have`` (and the part file) until it is whole, a gap
        has waited GAP_WAIT_S or nothing has come for ``quiet_s`` (False: ask again); True
        when the board says the log ends here (an empty LOG_DATA, or a failed read)."""
        last_new = gap_since = time.monotonic()
        while len(have) < entry.size_bytes:
            self._pump()
            now = time.monotonic()
            got = self.chunks.pop(len(have), None)
            if got is not None:
                if not got:
                    return True                       # the board's end of this log
                have += got
                fh.write(got)
                fh.flush()
                self._show(entry, len(have), shown)
                last_new = gap_since = now
                continue
            if self._said(ARMED_TEXT) is not None:
                raise self._armed()
            if self._said(READ_FAILED_TEXT) is not None:
                raise LogsRefused(f'the board could not read log {entry.id} (it says '
                                  f'"{READ_FAILED_TEXT}")')
            if not self._gap(len(have), now):
                gap_since = now
            if now - gap_since >= GAP_WAIT_S or now - last_new >= self.quiet_s:
                # The request again from the gap resends what came past it: forget that.
                self.floor = max(self.chunks, default=len(have))
                self.chunks = {}
                return False
            time.sleep(POLL_S)
        return False

    def _gap(self, n: int, now: float) -> bool:
        """Whether a packet after the first ``n`` bytes was lost: one past the gap has come
        that belongs to the stream last asked for (at or below the floor, or any once
        ``quiet_s`` has passed since the request: the stream it replaced has ended by then)."""
        settled = now - self.asked_at >= self.quiet_s
        return any(n < ofs and (settled or ofs <= self.floor) for ofs in self.chunks)

    def _show(self, entry: LogEntry, n: int, shown: list) -> None:
        """A progress line at each tenth of the log: a bar, the share, the bytes."""
        step = n * PROGRESS_STEPS // max(entry.size_bytes, 1)
        if step > shown[0]:
            shown[0] = step
            bar = "#" * step + "." * (PROGRESS_STEPS - step)
            self.progress(f"[{bar}] {100 * n // entry.size_bytes:3d} %  {n} of "
                          f"{entry.size_bytes} bytes")


def _read_part(part: str, size_bytes: int) -> bytearray:
    """What an earlier download of the same log kept; nothing when there is none or it is
    longer than the log (another log's)."""
    try:
        with open(part, "rb") as fh:
            data = bytearray(fh.read(size_bytes + 1))
    except FileNotFoundError:
        return bytearray()
    except OSError as exc:
        raise InputError(f"cannot read {part}: {exc.strerror or exc}") from None
    return data if len(data) <= size_bytes else bytearray()


def _open_part(part: str, have: bytearray):
    """The part file, to append to (started afresh when ``have`` is empty)."""
    try:
        return open(part, "ab" if have else "wb")
    except OSError as exc:
        raise InputError(f"cannot write {part}: {exc.strerror or exc}") from None

"""A request-and-answer exchange with the board over a telemetry link: what the parameter
protocol (:mod:`heliquad.host.acquire.param_protocol`), the log protocol
(:mod:`heliquad.host.acquire.log_protocol`) and the on-board program's
(:mod:`heliquad.host.acquire.program`) share. While it waits it sends the host's
HEARTBEAT every :data:`~heliquad.host.acquire.link.HEARTBEAT_PERIOD_S` (as a ground station
does), hands what arrives to the protocol, and notes from the board's HEARTBEAT whether it is
armed; a request without an answer goes again (``retries`` times) before the board is given
up on, in one line that says what was asked (:class:`NoAnswer`, exit 1).
"""

from __future__ import annotations

import time

from ...sim.base.dialect import dialect
from ...sim.base.errors import LinkLost
from .link import HEARTBEAT_PERIOD_S

__all__ = ["Exchange", "NoAnswer", "ANSWER_WAIT_S", "RETRIES", "ARMED_WAIT_S", "POLL_S",
           "QUIET_S"]

#: How long one request waits for its answer before it is sent again.
ANSWER_WAIT_S = 1.0
#: How many times a request goes again when its answer does not come.
RETRIES = 4
POLL_S = 0.005
#: A list or a download that stops coming for this long asks again for what is missing.
QUIET_S = 0.5
#: How long to wait for the board's HEARTBEAT (whether it is armed): it sends one a second
#: (firmware/core/flight_controller.cpp's streams), half a second to spare.
ARMED_WAIT_S = 1.5


class NoAnswer(LinkLost):
    """A request went unanswered after every retry: the board fell silent (exit 1)."""


class Exchange:
    """The host's side of a request-and-answer protocol over a link (a
    :class:`~heliquad.host.acquire.link.TelemetryLink` or anything with its ``name``,
    ``can_send``, ``heartbeat()`` and ``poll(only=...)``). A protocol names the messages it
    reads (``messages``, HEARTBEAT among them), takes each in :meth:`_handle`, and says in
    ``silent_hint`` what the board's silence suggests."""

    messages: tuple = ("HEARTBEAT",)
    silent_hint = "is the board running on this link?"

    def __init__(self, link, progress=None, answer_wait_s: float = ANSWER_WAIT_S,
                 retries: int = RETRIES, quiet_s: float = QUIET_S):
        self.link = link
        self.progress = progress or (lambda text: None)
        self.answer_wait_s, self.retries, self.quiet_s = answer_wait_s, retries, quiet_s
        self.last_heartbeat = None
        self.armed = None                         # as the board's last HEARTBEAT said

    def _pump_while(self, pending, received) -> None:
        """Pump while ``pending()``, until ``received()`` (a count of what came) has not
        grown for ``quiet_s``: a stream that stopped, whose missing part is asked again."""
        seen, last_new = received(), time.monotonic()
        while pending():
            self._pump()
            if received() != seen:
                seen, last_new = received(), time.monotonic()
            elif time.monotonic() - last_new >= self.quiet_s:
                return
            time.sleep(POLL_S)

    def _handle(self, message) -> None:
        """One message of ``messages`` but HEARTBEAT, as it arrives."""

    def _pump(self) -> None:
        """The heartbeat when due, and what has arrived."""
        now = time.monotonic()
        if self.last_heartbeat is None or now - self.last_heartbeat >= HEARTBEAT_PERIOD_S:
            self.link.heartbeat()
            self.last_heartbeat = now if self.link.can_send else None
        for m in self.link.poll(only=self.messages):
            if m.get_type() == "HEARTBEAT":
                self._heard(m)
            else:
                self._handle(m)

    def _wait(self, done, seconds: float) -> bool:
        """Pump until ``done()`` (True) or ``seconds`` pass (False)."""
        deadline = time.monotonic() + seconds
        while True:
            self._pump()
            if done():
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(POLL_S)

    def _ask(self, send, done, what: str) -> None:
        """``send()`` until ``done()``, at most 1 + retries times; NoAnswer naming ``what``."""
        self._reach()
        for _ in range(1 + self.retries):
            send()
            if self._wait(done, self.answer_wait_s):
                return
        raise NoAnswer(f"no answer to {what} from {self.link.name} after {1 + self.retries} "
                       f"requests ({self.answer_wait_s:g} s each): {self.silent_hint}")

    def _reach(self) -> None:
        """A listening network link can send only once it has heard the board: wait for it."""
        patience = self.answer_wait_s * (1 + self.retries)
        if not self._wait(lambda: self.link.can_send, patience):
            raise NoAnswer(f"nothing heard from the board on {self.link.name} in {patience:g} s; "
                           "a listening link learns where the board is from its telemetry")

    def _heard(self, heartbeat) -> None:
        """The board's HEARTBEAT says whether it is armed (a ground station's, MAV_TYPE_GCS,
        on a shared network link says nothing of the board)."""
        mav = dialect()
        if heartbeat.type != mav.MAV_TYPE_GCS:
            self.armed = bool(heartbeat.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED)

    def is_armed(self, wait_s: float = ARMED_WAIT_S) -> bool | None:
        """Whether the board is armed, from its next HEARTBEAT (waited for up to ``wait_s``);
        None when none came."""
        self.armed = None
        self._wait(lambda: self.armed is not None, wait_s)
        return self.armed

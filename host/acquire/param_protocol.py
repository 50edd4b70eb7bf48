"""The MAVLink parameter protocol from the host (``heliquad params``): the board's
parameters read, set and loaded over the telemetry link (the same link, any connection
:mod:`heliquad.host.acquire.connection` opens).

The protocol (MAVLink's common messages, as the firmware speaks it):

* PARAM_REQUEST_LIST: the board sends every parameter as a PARAM_VALUE (name, value, type,
  count, index); any may be lost on the way, so what is missing afterwards is asked for
  again one index at a time with PARAM_REQUEST_READ, a few times, until the list is whole;
* PARAM_REQUEST_READ by name: one PARAM_VALUE, or a STATUSTEXT ``params: no NAME``;
* PARAM_SET: the board answers with PARAM_VALUE, the new value if it took it, the unchanged
  one if it refused, with a STATUSTEXT saying why.

Values travel in a single-precision float field, whatever the parameter's type:
MAV_PARAM_TYPE_REAL32 for real values, INT32 for whole numbers, whose four bytes are carried
in the float's (byte-wise encoding, as the firmware says in AUTOPILOT_VERSION's capabilities
and as MAVSDK and QGroundControl read every autopilot but ArduPilot). So a real value is
compared after rounding to float32, and a whole number is exact over the int32 range (this
tool still refuses one past 2^24, which a C-cast reader would not get exactly).

Every exchange sends the host's HEARTBEAT while it waits (the firmware wants one at least
every 1.5 s); a request without an answer is sent again (``retries`` times) before the board
is given up on, in one line that says what was asked
(:class:`~heliquad.host.acquire.exchange.Exchange`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...sim.base.errors import BoardRefused, InputError
from ..records.params_file import INTEGER_TYPES, TYPE_NAMES, check_name
from .exchange import ANSWER_WAIT_S, QUIET_S, RETRIES, Exchange, NoAnswer
from .link import decode_value, encode_value

__all__ = ["Param", "ParamClient", "ParamRefused", "NoAnswer", "value_text", "checked_value",
           "encode_value", "decode_value",
           "same_value", "load_params", "session_params", "SessionLink"]

#: After a refused PARAM_SET, how long to wait for the STATUSTEXT that says why (it may
#: come after the PARAM_VALUE).
REASON_WAIT_S = 0.5
#: Whole numbers a single-precision float carries exactly.
MAX_EXACT_INT = 2**24
FLOAT32_MAX = float(np.finfo(np.float32).max)
MESSAGES = ("PARAM_VALUE", "STATUSTEXT", "HEARTBEAT")


@dataclasses.dataclass(frozen=True)
class Param:
    """One parameter as the board sent it: ``value`` as carried (a float, whole numbers
    too), ``type`` its MAV_PARAM_TYPE, ``index`` its place in the board's list."""
    name: str
    value: float
    type: int
    index: int

    @property
    def integer(self) -> bool:
        return self.type in INTEGER_TYPES

    def text(self) -> str:
        return value_text(self.value, self.type)


class ParamRefused(BoardRefused):
    """The board kept the old value of a parameter it was asked to set."""

    def __init__(self, name: str, asked: str, kept: str, reason: str | None):
        self.name, self.reason = name, reason
        why = f'it says "{reason}"' if reason else "it gave no reason"
        super().__init__(f"the board refused {name} = {asked} and kept {kept}: {why}")


#: How far a written value may lie from the float32 it stands for: half the smallest
#: difference MAVProxy's ``param load`` treats as a change (pymavlink's mavparm mindelta,
#: 1e-6, absolute), so a file loaded back there sends no set.
FILE_VALUE_TOLERANCE = 5e-7


def value_text(value: float, param_type: int | None = None) -> str:
    """A value as written and shown: a whole-number type's as an integer, a real one as the
    shortest decimal that reads back as the same single-precision float and lies within
    :data:`FILE_VALUE_TOLERANCE` of it (so every client's reader, in float32 or in double,
    gets the board's value back: 89.99999 would be the same float32 as 89.99999237, but
    MAVProxy compares in double)."""
    if param_type in INTEGER_TYPES:
        return str(int(value))
    f = np.float32(value)
    exact = float(f)
    if f == 0 or 1e-4 <= abs(f) < 1e16:
        text = np.format_float_positional(f, unique=True, trim="-")
    else:
        text = np.format_float_scientific(f, unique=True, trim="-")
    if abs(float(text) - exact) <= FILE_VALUE_TOLERANCE:
        return text
    for digits in range(len(text.replace("-", "").replace(".", "")), 18):
        text = f"{exact:.{digits}g}"
        if abs(float(text) - exact) <= FILE_VALUE_TOLERANCE:
            break
    return text


def same_value(a: float, b: float) -> bool:
    """Equal once rounded to single precision, as the protocol carries them."""
    return bool(np.float32(a) == np.float32(b))


def checked_value(param: Param, value: float) -> float:
    """``value`` for ``param``, as the protocol will carry it: finite, a whole number (exact
    in single precision) for a whole-number type, within single precision for a real one."""
    if not math.isfinite(value):
        raise InputError(f"{param.name}: {value} is not a finite number")
    if param.integer:
        if value != int(value):
            raise InputError(f"{param.name} takes whole numbers ({TYPE_NAMES[param.type]}), "
                             f"not {value:g}")
        if abs(value) > MAX_EXACT_INT:
            raise InputError(f"{param.name}: {int(value)} cannot be carried exactly (values "
                             f"travel as single-precision floats: whole numbers up to "
                             f"{MAX_EXACT_INT})")
    elif abs(value) > FLOAT32_MAX:
        raise InputError(f"{param.name}: {value:g} is beyond single precision")
    return float(np.float32(value))


class ParamClient(Exchange):
    """The host's side of the parameter protocol over a :class:`TelemetryLink`.

    ``progress`` is told what a fetch does (one line at a time); ``answer_wait_s``,
    ``retries`` and ``quiet_s`` bound every wait (``ANSWER_WAIT_S``, ``RETRIES``,
    ``QUIET_S``)."""

    messages = MESSAGES
    silent_hint = "is the board running, with a firmware that has parameters, on this link?"

    def __init__(self, link, progress=None, answer_wait_s: float = ANSWER_WAIT_S,
                 retries: int = RETRIES, quiet_s: float = QUIET_S):
        super().__init__(link, progress, answer_wait_s, retries, quiet_s)
        self.by_index: dict[int, Param] = {}      # the list being fetched
        self.count = None                         # its length, once the board said
        self.fresh: dict[str, Param] = {}         # PARAM_VALUEs since the last request
        self.texts: list[str] = []                # STATUSTEXTs since the last request

    # --- the link ------------------------------------------------------------------------

    def _handle(self, m) -> None:
        if m.get_type() == "STATUSTEXT":
            self.texts.append(m.text)
            return
        p = Param(m.param_id, decode_value(m.param_value, m.param_type), int(m.param_type),
                  int(m.param_index))
        self.fresh[p.name] = p
        if m.param_count:
            self.count = int(m.param_count)
        if self.count is not None and 0 <= p.index < self.count:
            self.by_index[p.index] = p

    def _forget(self) -> None:
        self.fresh.clear()
        self.texts.clear()

    # --- the protocol --------------------------------------------------------------------

    def fetch_all(self) -> list[Param]:
        """Every parameter, in the board's order: the list, then what went missing asked
        for again by index (``retries`` rounds)."""
        self._forget()
        self.by_index, self.count = {}, None
        self.progress(f"fetching parameters from {self.link.name} ...")
        self._ask(self.link.request_params, lambda: self.count is not None,
                  "the parameter list request (PARAM_REQUEST_LIST)")
        self._collect()
        for _ in range(self.retries):
            missing = self._missing()
            if not missing:
                break
            self.progress(f"  {self.count - len(missing)} of {self.count} received; asking "
                          f"again for {len(missing)} by index")
            for index in missing:
                self.link.request_param(index=index)
            self._collect()
        if missing := self._missing():
            shown = ", ".join(map(str, missing[:10])) + (" ..." if len(missing) > 10 else "")
            raise NoAnswer(f"the board sent {self.count - len(missing)} of its {self.count} "
                           f"parameters; index {shown} never came, asked for {self.retries} "
                           f"more times on {self.link.name}")
        self.progress(f"  {self.count} parameters")
        return [self.by_index[i] for i in range(self.count)]

    def _missing(self) -> list[int]:
        return [i for i in range(self.count) if i not in self.by_index]

    def _collect(self) -> None:
        """Pump until the list is whole or nothing new has come for ``quiet_s``."""
        self._pump_while(self._missing, lambda: len(self.by_index))

    def get(self, name: str) -> Param:
        """One parameter by name (InputError if the board has none of that name)."""
        check_name(name)
        self._forget()
        self._ask(lambda: self.link.request_param(name=name),
                  lambda: name in self.fresh or self._no_such(name) is not None,
                  f"reading {name} (PARAM_REQUEST_READ)")
        if name in self.fresh:
            return self.fresh[name]
        raise InputError(f'the board has no parameter {name} (it says "{self._no_such(name)}")')

    def _no_such(self, name: str) -> str | None:
        return next((t for t in self.texts if t.startswith("params: no") and name in t), None)

    def set(self, param: Param, value: float) -> Param:
        """Set a parameter the board has (its type as the board said) and verify the echo;
        :class:`ParamRefused` quoting the board's STATUSTEXT when it kept the old value."""
        value = checked_value(param, value)
        self._forget()
        self._ask(lambda: self.link.set_param(param.name, value, param.type),
                  lambda: param.name in self.fresh,
                  f"setting {param.name} (PARAM_SET)")
        got = self.fresh[param.name]
        if same_value(got.value, value):
            return got
        self._wait(lambda: self._reason(param.name) is not None, REASON_WAIT_S)
        raise ParamRefused(param.name, value_text(value, param.type), got.text(),
                           self._reason(param.name))

    def _reason(self, name: str) -> str | None:
        """The STATUSTEXT that says why a set was refused: one naming the parameter, else
        any since the request."""
        naming = [t for t in self.texts if name in t]
        return (naming or self.texts or [None])[-1]


def load_params(client: ParamClient, entries, progress=print) -> dict:
    """Set every parameter of ``entries`` (``(name, value)`` pairs, a file's) that differs
    from the board, verifying each; a refusal is recorded and the rest go on (a lost link
    ends it). Returns ``{"changed": [(name, old, new)], "unchanged": n, "refused": [(name,
    why)]}``."""
    board = {p.name: p for p in client.fetch_all()}
    out = {"changed": [], "unchanged": 0, "refused": []}
    for name, value in entries:
        param = board.get(name)
        try:
            if param is None:
                raise InputError("the board has no parameter of that name")
            wanted = checked_value(param, value)
        except InputError as exc:                 # not sent: the board could not take it
            out["refused"].append((name, str(exc)))
            progress(f"  {name}: not set: {exc}")
            continue
        if same_value(param.value, wanted):
            out["unchanged"] += 1
            continue
        try:
            got = client.set(param, wanted)
        except (ParamRefused, NoAnswer) as exc:
            out["refused"].append((name, str(exc)))
            progress(f"  {name}: {exc}")
            continue
        out["changed"].append((name, param.text(), got.text()))
        progress(f"  {name}: {param.text()} -> {got.text()}")
    return out


class SessionLink:
    """A session (:mod:`heliquad.host.acquire.session`) as :class:`ParamClient`'s link: requests go
    out on its telemetry link, answers come from :meth:`advance` (which lets its time pass:
    simulated frames on the SIL, a poll period on a board), and the session sends the host's
    HEARTBEAT itself."""

    def __init__(self, session):
        self.session = session
        self.name = getattr(session.tel, "name", "the session's link")

    @property
    def can_send(self) -> bool:
        return getattr(self.session.tel, "can_send", True)

    def heartbeat(self) -> None:
        pass

    def poll(self, only=MESSAGES) -> list:
        return [m for m in self.session.advance() if m.get_type() in only]

    def request_params(self) -> None:
        self.session.tel.request_params()

    def request_param(self, name: str = "", index: int = -1) -> None:
        self.session.tel.request_param(name=name, index=index)

    def set_param(self, name: str, value: float, param_type: int) -> None:
        self.session.tel.set_param(name, value, param_type)


def session_params(session, progress=print) -> dict | None:
    """Every parameter of the board a session flies, ``{name: value}`` in the board's order
    (the values as carried); None, said once, when the board sends none (a firmware without
    parameters)."""
    try:
        params = ParamClient(SessionLink(session)).fetch_all()
    except NoAnswer as exc:
        progress(f"warning: no parameters from the board, so the sweep records no gains: {exc}")
        return None
    progress(f"read {len(params)} parameters from the board")
    return {p.name: p.value for p in params}

"""The telemetry link: how the host tool talks to the firmware, on a real board over USB
serial, over a network link (UDP or TCP, :mod:`heliquad.host.acquire.connection`) and on the SIL's
telemetry pty alike (same code).

Commands out (HEARTBEAT, arm/disarm, mode, excitation), telemetry in; every packet received
is written to the .tlog if one is given. Timestamps are the host's clock unless the caller
passes one (the SIL stamps its run's start plus simulated time, so runs repeat apart from
that offset).
"""

from __future__ import annotations

import struct
import time

from ...sim.base import dialect as names
from ...sim.base.dialect import dialect
from ...sim.base.errors import InputError
from ...sim.base.firmware_facts import MAX_ROTORS
from ...sim.base.framing import Codec, Framer
from .connection import open_connection

# AXES, INJECTIONS and MODES are made on first use (__getattr__), so not listed here.
__all__ = ["TelemetryLink", "INPUT_OUTPUT", "ROTOR_INPUT_OUTPUT", "input_output",
           "response_fields", "response_of", "check_response", "SESSION_MESSAGES", "HEARTBEAT_PERIOD_S",
           "reason_text"]

#: Which logged HQ_SYSID_SAMPLE field is the input and which the output, per injection point
#: the axis sweeps use (the commands' --inject choices). The firmware's per-rotor injections
#: are the per-rotor runs of ``heliquad sweep --inject motors`` (or ``motorN``,
#: :data:`ROTOR_INPUT_OUTPUT`).
INPUT_OUTPUT = {"mixer": ("axis_cmd", "rate"), "rate": ("rate_sp", "rate"),
                "angle": ("angle_sp", "angle")}
#: The per-rotor runs' injections (every rotor on its own lines, or one rotor's alone:
#: motor1 the central rotor; docs/effectiveness.md) and what they record beside the
#: injections: the axis's torque command and the rate.
ROTOR_INPUT_OUTPUT = {name: ("axis_cmd", "rate") for name in
                      ("motors", *(f"motor{n}" for n in range(1, MAX_ROTORS + 1)))}
#: The messages a session driver (SIL or board) reads while an excitation runs, and the
#: parameters' answers (a sweep reads the board's parameters through its session).
SESSION_MESSAGES = ("HQ_SYSID_SAMPLE", "HQ_EXCITATION_STATUS", "STATUSTEXT", "PARAM_VALUE")
#: How often a session sends the host's HEARTBEAT: the firmware stops an excitation 1.5 s
#: after the last one (and disarms a vehicle armed by command), so a few late ones must not
#: end a run.
HEARTBEAT_PERIOD_S = 0.25
#: The host's system id, a ground station's usual one (its component: MAV_COMP_ID_MISSIONPLANNER),
#: and the vehicle's (its component: MAV_COMP_ID_AUTOPILOT1).
HOST_SYSTEM_ID, TARGET_SYSTEM = 255, 1


def __getattr__(name: str):
    """``AXES``, ``INJECTIONS`` and ``MODES``: the dialect's names for HQ_AXIS, HQ_INJECTION
    and HQ_MODE (``{"roll": 0, ...}``, sim/base/dialect.py), made on first use, so importing this
    module (as the command line does) needs no generated code yet."""
    if name in names.NAMED_ENUMS:
        return getattr(names, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def input_output(inject: str) -> tuple:
    """The logged fields (input, output) of an injection point a sweep runs (an axis's or the
    per-rotor run's)."""
    return {**INPUT_OUTPUT, **ROTOR_INPUT_OUTPUT}[inject]


def response_fields(inject: str, response: str | None = None) -> tuple:
    """The logged fields (input, output) a sweep at ``inject`` measures for ``response``
    (:data:`~heliquad.host.records.choices.RESPONSES`; None: the injection's own,
    :func:`input_output`). A mixer sweep measures the plant whatever it is told."""
    return INPUT_OUTPUT["mixer"] if response == "plant" else input_output(inject)


def check_response(inject: str, response: str | None) -> None:
    """Refuse a ``response`` (sweep --response, identify --response) where the injection has
    none to choose: only a setpoint's (rate, angle) has; a mixer sweep, or a rotor's,
    measures the plant."""
    if response is not None and not (inject in INPUT_OUTPUT and
                                     INPUT_OUTPUT[inject] != INPUT_OUTPUT["mixer"]):
        raise InputError("--response is for rate or angle injection (a mixer sweep measures "
                         "the plant)")


def response_of(inject: str, fields: tuple) -> str | None:
    """Which response the fields ``(input, output)`` are at ``inject``: ``plant`` for the
    mixer's pair, ``loop`` for the injection's own, None for any other pair."""
    if tuple(fields) == INPUT_OUTPUT["mixer"]:
        return "plant"
    return "loop" if tuple(fields) == input_output(inject) else None


def reason_text(code: int) -> str:
    """An HQ_REASON value in words: the dialect's description (the firmware's one
    definition), which reads as the end of a sentence."""
    entry = dialect().enums["HQ_REASON"].get(int(code))
    return entry.description.rstrip(".") if entry else f"unknown reason {int(code)}"


#: The firmware's telemetry runs at 921600 baud on the Teensy's UART0 (pins 0/1, through a
#: 3.3 V USB-serial cable): about 25 kB/s of telemetry needs more than 115200 baud carries
#: (11.5 kB/s). USB CDC and the SIL's ptys ignore the rate.
DEFAULT_BAUD = 921600


#: The byte-wise encoding of the whole-number types: the value's bytes at the start of the
#: float's four (little-endian, as MAVLink's mavlink_param_union_t lays them out).
_INT_FORMATS = {1: "<B", 2: "<b", 3: "<H", 4: "<h", 5: "<I", 6: "<i"}
def encode_value(value: float, param_type: int) -> float:
    """The PARAM_SET/PARAM_VALUE float field for ``value``: a real one itself, a whole-number
    type's bytes in the float's."""
    fmt = _INT_FORMATS.get(int(param_type))
    if fmt is None:
        return float(value)
    raw = struct.pack(fmt, int(value)).ljust(4, b"\0")
    return struct.unpack("<f", raw)[0]


def decode_value(raw: float, param_type: int) -> float:
    """A PARAM_VALUE's number from its float field (:func:`encode_value` undone)."""
    fmt = _INT_FORMATS.get(int(param_type))
    if fmt is None:
        return float(raw)
    data = struct.pack("<f", raw)
    return float(struct.unpack(fmt, data[:struct.calcsize(fmt)])[0])


class TelemetryLink:
    """A MAVLink connection to the firmware's telemetry port.

    Parameters
    ----------
    port : str
        A connection string (:mod:`heliquad.host.acquire.connection`): a serial device
        (``/dev/ttyACM0`` or ``COM3`` for a Teensy, or the SIL's telemetry pty) or a network
        link (``udpin:``, ``udpout:``, ``tcp:``, ``tcpin:`` ``HOST:PORT``).
    baud : int
        Baud rate of a serial device (ignored by USB CDC, ptys and the network; the
        Teensy's UART0 runs at DEFAULT_BAUD).
    tlog : TlogWriter, optional
        Where every received packet is logged.
    """

    def __init__(self, port: str, baud: int = DEFAULT_BAUD, tlog=None):
        self.mav_module = dialect()
        self.name = str(port)
        self.transport = open_connection(self.name, baud)
        self.mav = self.mav_module.MAVLink(          # every message out goes through write()
            self, srcSystem=HOST_SYSTEM_ID,
            srcComponent=self.mav_module.MAV_COMP_ID_MISSIONPLANNER)
        self.target = self.mav_module.MAV_COMP_ID_AUTOPILOT1
        self.mav.robust_parsing = True
        self.codec = Codec(self.mav_module)
        self.framer = Framer(self.codec)
        self.ids = {cls.msgname: msgid for msgid, cls in self.codec.classes.items()}
        self.tlog = tlog
        self.bytes_in = 0

    def close(self) -> None:
        self.transport.close()

    def fileno(self) -> int:
        """What to wait on (select) for data to arrive."""
        return self.transport.fileno()

    def write(self, data) -> int:
        """Raw bytes out (packed messages); a lost link is an InputError."""
        return self.transport.write(data)

    def read_packets(self) -> list:
        """Raw ``(msgid, packet, payload)`` of what has arrived, not logged (never blocks).
        For callers that stamp the log themselves."""
        data = self.transport.read()
        if not data:
            return []
        self.bytes_in += len(data)
        return self.framer.feed(data)

    def poll(self, timestamp_us: int | None = None, only=None) -> list:
        """Read what has arrived (never blocks), log every packet, return the messages.

        ``only``: message type names to decode and return (default all); the others are
        still logged. Decoding costs a few microseconds a message, which matters at 200 Hz.
        """
        packets = self.read_packets()
        if self.tlog is not None and packets:
            ts = int(time.time() * 1e6) if timestamp_us is None else timestamp_us
            for _, packet, _ in packets:
                self.tlog.write(ts, packet)
        wanted = None if only is None else {self.ids[name] for name in only}
        return [self.codec.decode(msgid, payload) for msgid, _, payload in packets
                if wanted is None or msgid in wanted]

    def heartbeat(self) -> None:
        """The host's HEARTBEAT. A listening network link that has not heard its peer yet
        has nowhere to send it: then it is skipped (the next one goes once the peer is
        known); any other command raises the InputError that says so."""
        if not self.transport.can_send:
            return
        m = self.mav_module
        self.mav.heartbeat_send(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def arm(self, arm: bool = True) -> None:
        self.mav.command_long_send(TARGET_SYSTEM, self.target,
                                   self.mav_module.MAV_CMD_COMPONENT_ARM_DISARM,
                                   0, 1.0 if arm else 0.0, 0, 0, 0, 0, 0, 0)

    def set_mode(self, mode: str) -> None:
        self.mav.set_mode_send(TARGET_SYSTEM, self.mav_module.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                               names.MODES[mode])

    def start_excitation(self, axis: str, injection: str, freq_hz: float, amplitude: float,
                         cycles: int, fade_cycles: int, harmonics=None, chirp=None) -> None:
        """Start a sine, or with ``harmonics`` (``[(order, amplitude, phase_rad), ...]``) a
        multisine of base frequency ``freq_hz`` whose declared peak is ``amplitude``, or with
        ``chirp`` (``(stop_hz, sweep_s, law)``, law ``log`` or ``linear``) a chirp from
        ``freq_hz`` (``cycles`` 1)."""
        signal, orders, amps, phases = self._signal(harmonics)
        stop_hz = sweep_s = 0.0
        if chirp is not None:
            stop_hz, sweep_s, law = chirp
            signal = (self.mav_module.HQ_SIGNAL_CHIRP if law == "log"
                      else self.mav_module.HQ_SIGNAL_CHIRP_LINEAR)
        self.mav.hq_excitation_send(TARGET_SYSTEM, self.target, self.mav_module.HQ_EXCITATION_START,
                                    names.AXES[axis], names.INJECTIONS[injection], float(freq_hz),
                                    float(amplitude), int(cycles), int(fade_cycles), signal,
                                    orders, amps, phases, float(stop_hz), float(sweep_s))

    def _signal(self, harmonics):
        """HQ_EXCITATION's (and HQ_PROGRAM's) signal and harmonic arrays: a sine without
        ``harmonics``."""
        m = self.mav_module
        signal, orders, amps, phases = m.HQ_SIGNAL_SINE, [0] * 16, [0.0] * 16, [0.0] * 16
        if harmonics is not None:
            signal = m.HQ_SIGNAL_MULTISINE
            for i, (order, amp, phase) in enumerate(harmonics):
                orders[i], amps[i], phases[i] = int(order), float(amp), float(phase)
        return signal, orders, amps, phases

    def program_step(self, index: int, count: int, axis: str, injection: str, freq_hz: float,
                     amplitude: float, cycles: int, fade_cycles: int, harmonics=None) -> None:
        """Step ``index`` of a new on-board program of ``count`` steps (HQ_PROGRAM STEP), the
        excitation as :meth:`start_excitation` gives it."""
        signal, orders, amps, phases = self._signal(harmonics)
        self.mav.hq_program_send(TARGET_SYSTEM, self.target, self.mav_module.HQ_PROGRAM_STEP,
                                 int(index), int(count), names.AXES[axis],
                                 names.INJECTIONS[injection], float(freq_hz), float(amplitude),
                                 int(cycles), int(fade_cycles), signal, orders, amps, phases)

    def program_request(self, action: str, index: int = 0) -> None:
        """HQ_PROGRAM ``"read"`` (step ``index`` of the stored program) or ``"clear"``."""
        m = self.mav_module
        code = m.HQ_PROGRAM_READ if action == "read" else m.HQ_PROGRAM_CLEAR
        self.mav.hq_program_send(TARGET_SYSTEM, self.target, code, int(index), 0, 0, 0, 0.0,
                                 0.0, 0, 0, m.HQ_SIGNAL_SINE, [0] * 16, [0.0] * 16, [0.0] * 16)

    def stop_excitation(self) -> None:
        """Stop any excitation (axis and injection are not read with STOP)."""
        m = self.mav_module
        self.mav.hq_excitation_send(TARGET_SYSTEM, self.target, m.HQ_EXCITATION_STOP,
                                    m.HQ_AXIS_ROLL, m.HQ_INJECTION_ANGLE, 0.0, 0.0, 0, 0)

    def finish_excitation(self) -> None:
        """Finish the running excitation in order: the cycle under way completes, then the
        planned fade-out (HQ_EXCITATION_FINISH)."""
        m = self.mav_module
        self.mav.hq_excitation_send(TARGET_SYSTEM, self.target, m.HQ_EXCITATION_FINISH,
                                    m.HQ_AXIS_ROLL, m.HQ_INJECTION_ANGLE, 0.0, 0.0, 0, 0)

    # --- the MAVLink parameter protocol (host/acquire/param_protocol.py) ---------------------------------

    @property
    def can_send(self) -> bool:
        """Whether what is sent reaches the board (a listening network link must have heard
        it first; :mod:`heliquad.host.acquire.connection`)."""
        return self.transport.can_send

    def request_params(self) -> None:
        """PARAM_REQUEST_LIST: the board sends every parameter as PARAM_VALUE."""
        self.mav.param_request_list_send(TARGET_SYSTEM, self.target)

    def request_param(self, name: str = "", index: int = -1) -> None:
        """PARAM_REQUEST_READ of one parameter, by name (``index`` -1) or by index."""
        self.mav.param_request_read_send(TARGET_SYSTEM, self.target, name.encode("ascii"),
                                         int(index))

    def set_param(self, name: str, value: float, param_type: int) -> None:
        """PARAM_SET; a real value as the float itself, a whole-number type's byte-wise (its
        bytes in the float's, :func:`encode_value`)."""
        self.mav.param_set_send(TARGET_SYSTEM, self.target, name.encode("ascii"),
                                encode_value(value, param_type), int(param_type))

    # --- the MAVLink log protocol (host/acquire/log_protocol.py) -----------------------------------------

    def request_log_list(self, first: int = 0, last: int = 0xFFFF) -> None:
        """LOG_REQUEST_LIST: the board sends one LOG_ENTRY per log from ``first`` to
        ``last`` (0xFFFF: its last), or one with num_logs 0 when it has none."""
        self.mav.log_request_list_send(TARGET_SYSTEM, self.target, int(first), int(last))

    def request_log_data(self, log_id: int, offset: int, count: int) -> None:
        """LOG_REQUEST_DATA: LOG_DATA packets of up to 90 bytes from ``offset``, ``count``
        bytes or up to the log's end; a new request replaces the one under way."""
        self.mav.log_request_data_send(TARGET_SYSTEM, self.target, int(log_id), int(offset),
                                       int(count))

    def erase_logs(self) -> None:
        """LOG_ERASE: every log on the board goes."""
        self.mav.log_erase_send(TARGET_SYSTEM, self.target)

    def end_log_transfer(self) -> None:
        """LOG_REQUEST_END: the transfer under way stops."""
        self.mav.log_request_end_send(TARGET_SYSTEM, self.target)

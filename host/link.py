"""The telemetry link: how the host tool talks to the firmware, on a real board over USB
serial and on the SIL's telemetry pty alike (same code).

Commands out (HEARTBEAT, arm/disarm, mode, excitation), telemetry in; every packet received
is written to the .tlog if one is given. Timestamps are the host's clock unless the caller
passes one (the SIL passes simulated time, so runs repeat exactly).
"""

from __future__ import annotations

import time

import serial

from .errors import InputError
from .mavlink_dialect import dialect

__all__ = ["TelemetryLink", "AXES", "INJECTIONS", "MODES"]

AXES = {"roll": 0, "pitch": 1, "yaw": 2}
INJECTIONS = {"angle": 0, "rate": 1, "mixer": 2}
MODES = {"angle": 1, "rate": 2}
HOST_SYSTEM_ID, HOST_COMPONENT_ID = 255, 190       # a ground station's usual IDs
TARGET_SYSTEM, TARGET_COMPONENT = 1, 1
MAV_CMD_COMPONENT_ARM_DISARM = 400


class TelemetryLink:
    """A MAVLink connection to the firmware's telemetry port.

    Parameters
    ----------
    port : str
        Serial device (``/dev/ttyACM0`` for a Teensy, or the SIL's telemetry pty).
    baud : int
        Baud rate (ignored by USB CDC and ptys, needed by real UARTs).
    tlog : TlogWriter, optional
        Where every received packet is logged.
    """

    def __init__(self, port: str, baud: int = 115200, tlog=None):
        self.mav_module = dialect()
        try:
            self.serial = serial.Serial(port, baudrate=baud, timeout=0, write_timeout=1.0)
        except (serial.SerialException, OSError) as exc:
            raise InputError(f"cannot open {port}: {exc}") from None
        self.mav = self.mav_module.MAVLink(self.serial, srcSystem=HOST_SYSTEM_ID,
                                           srcComponent=HOST_COMPONENT_ID)
        self.mav.robust_parsing = True
        self.tlog = tlog
        self.bytes_in = 0

    def close(self) -> None:
        self.serial.close()

    def poll(self, timestamp_us: int | None = None) -> list:
        """Read what has arrived (never blocks); returns the parsed messages."""
        waiting = self.serial.in_waiting
        if not waiting:
            return []
        data = self.serial.read(waiting)
        self.bytes_in += len(data)
        msgs = self.mav.parse_buffer(data) or []
        msgs = [m for m in msgs if m.get_type() != "BAD_DATA"]
        if self.tlog is not None:
            ts = int(time.time() * 1e6) if timestamp_us is None else timestamp_us
            for m in msgs:
                self.tlog.write(ts, m.get_msgbuf())
        return msgs

    def heartbeat(self) -> None:
        self.mav.heartbeat_send(6, 8, 0, 0, 0)          # MAV_TYPE_GCS, MAV_AUTOPILOT_INVALID

    def arm(self, arm: bool = True) -> None:
        self.mav.command_long_send(TARGET_SYSTEM, TARGET_COMPONENT, MAV_CMD_COMPONENT_ARM_DISARM,
                                   0, 1.0 if arm else 0.0, 0, 0, 0, 0, 0, 0)

    def set_mode(self, mode: str) -> None:
        self.mav.set_mode_send(TARGET_SYSTEM, 1, MODES[mode])

    def start_excitation(self, axis: str, injection: str, freq_hz: float, amplitude: float,
                         cycles: int, fade_cycles: int) -> None:
        self.mav.hq_excitation_send(TARGET_SYSTEM, TARGET_COMPONENT, 1, AXES[axis],
                                    INJECTIONS[injection], float(freq_hz), float(amplitude),
                                    int(cycles), int(fade_cycles))

    def stop_excitation(self) -> None:
        self.mav.hq_excitation_send(TARGET_SYSTEM, TARGET_COMPONENT, 0, 0, 0, 0.0, 0.0, 0, 0)

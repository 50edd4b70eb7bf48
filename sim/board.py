"""Free-running mode: the simulated rig behaves like a board on a serial port.

``heliquad board`` starts the host firmware with a transfer-function plant and steps it in
real time (one frame per loop period of wall-clock time), hovering with the arm switch up,
and publishes the firmware's telemetry link as a pty. Any tool then connects to that path
as it would to /dev/ttyACM0 (`heliquad log`, a sweep, QGroundControl over a serial link,
or pymavlink). The simulator does not read the telemetry: if nobody does, the firmware's
buffer fills and it drops and counts messages, as a UART would.
"""

from __future__ import annotations

import os
import time

from .dialect import dialect
from .lockstep import SimLink, start_firmware
from .sil import rig_step
from .tf_plant import TfPlant

__all__ = ["run_board"]

#: If the simulator falls this far behind real time, it resynchronises instead of racing.
MAX_LAG_S = 0.1


def run_board(axis: str, num, den, telemetry_path: str, loop_hz: float = 200.0,
              collective: float = 0.4, duration_s: float | None = None,
              dmp_image: str | None = None, ready=None, firmware: str = "host",
              params_file: str | None = None, armed: bool = True) -> dict:
    """Run until ``duration_s`` of wall time (or Ctrl-C). Returns counters. ``ready`` is told
    when the telemetry port is there (default: a line on stdout, flushed at once, for
    whatever waits for it). ``params_file``: where the firmware keeps its parameters
    (default: nowhere; every start has the defaults). ``armed=False``: the pilot leaves the
    arm switch and the throttle low (a ground station then sees a disarmed vehicle, whose
    every parameter may change)."""

    ready = ready or (lambda text: print(text, flush=True))
    dt_s = 1.0 / loop_hz
    plant = TfPlant(axis, num, den, dt_s)
    frames, late = 0, 0
    fw = start_firmware(firmware, loop_hz=loop_hz, dmp_image=dmp_image,
                        telemetry_path=os.path.abspath(telemetry_path), params_file=params_file)
    try:
        link = SimLink(fw)
        kind = dialect().HQ_SENSOR_NONE            # until the firmware says what it set up
        try:
            # Said inside: a Ctrl-C from whoever waited for the line stops the board as any
            # later one does.
            ready(f"board running: telemetry on {telemetry_path} (Ctrl-C to stop)")
            t0 = time.monotonic()
            while duration_s is None or frames * dt_s < duration_s:
                frames += 1
                target = t0 + frames * dt_s
                now = time.monotonic()
                if now < target:
                    time.sleep(target - now)
                elif now - target > MAX_LAG_S:
                    late += 1
                    t0 = now - frames * dt_s            # resynchronise to real time
                # The RC of frame 0 is the pilot's at rest: arm switch and throttle low.
                reply = rig_step(link, plant, frames if armed else 0,
                                 int(round(frames * dt_s * 1e6)), kind, collective)
                kind = reply.sensor_kind
        except KeyboardInterrupt:
            pass
        finally:
            link.close()
    finally:
        fw.stop()                          # its links and temporary folder go with it
    return {"frames": frames, "resyncs": late}

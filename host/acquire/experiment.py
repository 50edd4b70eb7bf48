"""One sine experiment with the firmware in the loop (``heliquad sil``): a sweep of one
frequency on the simulated rig that also keeps its samples.

The session (:class:`heliquad.host.acquire.session.SilSession`) boots, arms and hovers the rig;
:func:`heliquad.host.acquire.sweep.measure`, the routine every sweep frequency runs, starts the
excitation and watches it to its end with the same safety checks. Every telemetry packet
goes to ``RUN.tlog`` stamped with the run's start (wall clock) plus simulated time; the
full-amplitude samples go to
``RUN.csv`` (``t_s,u,y``, see :data:`heliquad.host.acquire.link.INPUT_OUTPUT`) for ``heliquad fsf``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time

from ...sim.base.errors import InputError
from ...sim.rig.lockstep import FirmwareError
from ...sim.rig.setup import SilConfig
from ..records.run_csv import write_run_csv
from .measure import SATURATION, measure
from .session import SilSession
from .sweep import SweepPlan

__all__ = ["SilResult", "run_sil", "TAIL_FRAMES"]

#: Frames recorded after the excitation ends.
TAIL_FRAMES = 10


@dataclasses.dataclass
class SilResult:
    tlog_path: str
    csv_path: str
    samples: int                   # full-amplitude samples written to the CSV
    frames: int
    seq_gaps: int                  # HQ_SYSID_SAMPLE sequence gaps (dropped telemetry)
    actual_freq_hz: float
    saturation: dict               # measured samples that saturated, by kind (sweep.SATURATION)
    imu_mode: str
    wall_s: float                  # the whole run, firmware start-up included
    loop_s: float                  # the lockstep loop alone (hover included, start-up not)
    truth: complex                 # sampled-data truth at the actual frequency (nan if unknown)
    stopped: str | None = None     # why the excitation ended early, if it did
    firmware_summary: str = ""     # the firmware's own last word: counters, loop figures
    start_us: int = 0              # the log's stamps: this (the wall clock at the start) + sim time

    @property
    def saturated_samples(self) -> int:
        """Measured samples whose torque command the mixer could not meet."""
        return self.saturation["saturated"]


def run_sil(cfg: SilConfig, out_base: str, progress=print, start_us: int | None = None) -> SilResult:
    """Run the experiment; writes ``out_base.tlog`` and ``out_base.csv``, never over files
    that exist (InputError before anything starts). ``start_us``: what the log's stamps count
    from (default: the wall clock now, :class:`SilSession`)."""
    tlog_path, csv_path = out_base + ".tlog", out_base + ".csv"
    for path in (tlog_path, csv_path):
        if os.path.lexists(path):
            raise InputError(f"{path} exists: heliquad never writes over a run's records; give "
                             "another --out (or move the old files away)")
    plan = SweepPlan(cfg.axis, cfg.inject, [cfg.freq_hz], [cfg.amplitude], cfg.cycles,
                     cfg.fade_cycles)
    t0 = time.monotonic()
    with SilSession(cfg, tlog_path, start_us) as session:
        # The loop's time starts once the firmware is up (the drop-in's boot, some 0.7 s of
        # the Teensy image's, is start-up, as wall_s - loop_s says).
        t_loop = time.monotonic()
        session.hover()
        watch = measure(session, plan, cfg.freq_hz, cfg.amplitude, progress=progress,
                        keep_rows=True)
        session.advance(frames=TAIL_FRAMES)
        loop_s = time.monotonic() - t_loop
        plant, imu_mode, frames = session.plant, session.fw.imu_mode, session.frame
        start_us = session.start_us
    write_run_csv(csv_path, watch.rows)
    e = watch.entry
    if e["status"].startswith("refused") or "did not start" in e["status"]:
        raise FirmwareError(f"{e['status']}; the log is kept in {tlog_path}")
    freq = e.get("freq_hz", math.nan)
    return SilResult(tlog_path=tlog_path, csv_path=csv_path, samples=e["samples"],
                     frames=frames, seq_gaps=e["seq_gaps"], actual_freq_hz=freq,
                     saturation={key: e[key] for key in SATURATION}, imu_mode=imu_mode,
                     wall_s=time.monotonic() - t0, loop_s=loop_s,
                     truth=_truth(plant, freq, cfg.inject),
                     stopped=None if e["status"] == "ok" else e["status"],
                     firmware_summary=session.fw.summary, start_us=start_us)


def _truth(plant, freq_hz: float, inject: str) -> complex:
    """What identification should find at the frequency used, where the plant knows it."""
    if not math.isfinite(freq_hz):
        return complex("nan")
    try:
        return complex(plant.truth(2 * math.pi * freq_hz, inject))
    except ValueError:
        return complex("nan")

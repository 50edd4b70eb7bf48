"""Benchmark: rig time per axis, the paper's dwell against one multisine, at equal accuracy.

On each axis's rig (the 6-DoF vehicle, firmware in the loop, mixer injection):

1. **Still air, ideal sensor** (the method alone): a multisine over the axis's band in its
   default rig time (at most 60 s), and the paper's dwell (8 measured cycles per frequency,
   designed amplitudes) at the multisine's own line frequencies. Prints the rig time of
   each and the largest difference between their points (the dwell's interpolated to the
   multisine's exact frequencies, which differ by the rounding of each sine's period).
2. **Moderate turbulence, the IMU's noise**: the shortest dwell identify can use (1 fade
   cycle each way, 3 measured cycles: one discarded, one fills the FSF's filter, one of
   regression rows) at the default multisine's lines, and that multisine (same lines and
   period) with as many whole periods as fit the dwell's rig time;
   over several seeds, each point's error against the
   simulator's truth. Prints the rig time and the RMS and worst errors of both.

Rig time counts each excitation from the start of its fade-in to the end of its fade-out
(what the rig flies excited). Prints figures; there is no target ratio.

    python benchmarks/rig_time.py [--axes roll pitch yaw] [--seeds 3]
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile

import numpy as np

from heliquad.host.acquire.session import SilSession
from heliquad.host.acquire.sweep import (SWEEP_TLOG, default_plan, multisine_plan, run_sweep,
                                         sil_source)
from heliquad.host.campaign.identify import identify_dir
from heliquad.sim.base.dialect import AXES
from heliquad.sim.rig.setup import SilConfig


def quiet(*_args, **_kwargs):
    pass


def rig_seconds(manifest) -> float:
    """Excited time: each measured excitation's full-amplitude window plus its two fades."""
    total = 0.0
    for e in manifest["frequencies"]:
        if "period_samples" not in e:
            continue
        fs = e["freq_hz"] * e["period_samples"]
        fade = e.get("fade_samples", manifest["fade_cycles"] * e["period_samples"])
        total += (e["samples"] + 2 * fade) / fs
    return total


def run(axis, plan, folder, turbulence=None, seed=0, ideal=False):
    """Sweep ``plan`` on the axis's rig; (points by frequency, truth errors, rig seconds)."""
    os.makedirs(folder)
    cfg = SilConfig(axis=axis, inject="mixer", plant="vehicle", rig=axis, seed=seed,
                    turbulence=turbulence, ideal_sensor=ideal)
    with SilSession(cfg, os.path.join(folder, SWEEP_TLOG)) as session:
        manifest = run_sweep(session, plan, folder,
                             {**sil_source(cfg), "firmware": session.fw.record()}, progress=quiet)
    got = identify_dir(folder, orders=[(0, 2)], progress=quiet, delay=False)
    points = sorted(got["points"], key=lambda p: p.omega_rad_s)
    errors = got["truth"]["points"]
    return points, errors, rig_seconds(manifest)


def _interpolated(points, freqs_hz):
    """The points' gain at ``freqs_hz``: log-magnitude and unwrapped phase, linear in log f."""
    f = np.array([p.freq_hz for p in points])
    g = np.array([p.gain for p in points])
    mag = np.interp(np.log(freqs_hz), np.log(f), np.log(np.abs(g)))
    phase = np.interp(np.log(freqs_hz), np.log(f), np.unwrap(np.angle(g)))
    return np.exp(mag + 1j * phase)


def still_air(axis, tmp) -> None:
    ms_plan = multisine_plan(axis)
    ms, _, ms_s = run(axis, ms_plan, f"{tmp}/{axis}-ms", ideal=True)
    freqs = ms_plan.multisine.freqs_hz
    dwell, _, dwell_s = run(axis, default_plan(axis, freqs_hz=freqs, cycles=8),
                            f"{tmp}/{axis}-dwell", ideal=True)
    want = _interpolated(dwell, np.array([p.freq_hz for p in ms]))
    ratio = np.array([p.gain for p in ms]) / want
    print(f"{axis:>6} still air: multisine {len(ms)} points in {ms_s:.1f} s, dwell "
          f"{len(dwell)} in {dwell_s:.1f} s ({dwell_s / ms_s:.1f}x); largest difference "
          f"{np.max(np.abs(20 * np.log10(np.abs(ratio)))):.3f} dB, "
          f"{np.max(np.abs(np.degrees(np.angle(ratio)))):.2f} deg", flush=True)


def _error_summary(errors) -> tuple:
    db = np.array([e["error_db"] for e in errors])
    deg = np.array([e["error_deg"] for e in errors])
    return (math.sqrt(np.mean(db ** 2)), math.sqrt(np.mean(deg ** 2)),
            float(np.max(np.abs(db))), float(np.max(np.abs(deg))))


def turbulent(axis, tmp, seeds) -> None:
    default = multisine_plan(axis).multisine
    freqs = default.freqs_hz
    dwell_plan = default_plan(axis, freqs_hz=freqs, cycles=3)
    dwell_plan.fade_cycles = 1
    rows = {"dwell": [], "multisine": []}
    rig = {"dwell": [], "multisine": []}
    for seed in range(1, seeds + 1):
        _, errors, seconds = run(axis, dwell_plan, f"{tmp}/{axis}-td{seed}", "moderate", seed)
        rows["dwell"] += errors
        rig["dwell"].append(seconds)
        ms_plan = multisine_plan(axis, rig_time_s=seconds, like=default)
        _, errors, seconds = run(axis, ms_plan, f"{tmp}/{axis}-tm{seed}", "moderate", seed)
        rows["multisine"] += errors
        rig["multisine"].append(seconds)
    for kind, errors in rows.items():
        rms_db, rms_deg, worst_db, worst_deg = _error_summary(errors)
        print(f"{axis:>6} moderate turbulence, {kind:>9}: {np.mean(rig[kind]):.1f} s; error "
              f"against truth RMS {rms_db:.2f} dB {rms_deg:.1f} deg, worst {worst_db:.2f} dB "
              f"{worst_deg:.1f} deg ({len(errors)} points, {seeds} seeds)", flush=True)


def main(argv=None):
    """Both experiments on the axes asked for."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--axes", nargs="+", default=list(AXES), choices=tuple(AXES))
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        for axis in args.axes:
            still_air(axis, tmp)
        for axis in args.axes:
            turbulent(axis, tmp, args.seeds)


if __name__ == "__main__":
    main()

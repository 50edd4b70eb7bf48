"""Benchmark: rig time per axis, the paper's dwell against one multisine, at equal accuracy.

Runs the study ``benchmarks/studies/rig_time.toml`` (``heliquad study``: every run a
``heliquad sweep --sil`` and ``heliquad identify`` on the axis's rig, the 6-DoF vehicle,
mixer injection, firmware in the loop) and prints its figures from the runs' records:

1. **Still air, ideal sensor** (the method alone): the default multisine (at most 60 s)
   and the paper's dwell (8 measured cycles per frequency, designed amplitudes) at the
   multisine's line frequencies: the rig time of each, each one's worst error against the
   simulator's truth, and the largest difference between their points (the dwell's
   interpolated to the multisine's exact frequencies, which differ by the rounding of each
   sine's period to whole loop samples).
2. **Moderate turbulence, the IMU's noise**, seeds 1-3: the shortest dwell identify can
   use (1 fade cycle each way, 3 measured cycles: one discarded, one fills the FSF's
   filter, one of regression rows) at the default multisine's lines, and that multisine
   (same lines and base period) with as many whole periods as fit the dwell's rig time:
   the mean rig time, and the RMS and worst error against the truth over all the points of
   the three seeds.

Rig time is the table's ``excited_s``: each excitation from the start of its fade-in to the
end of its fade-out (what the rig flies excited). Prints figures; there is no target ratio.
With --out the study's folder is kept (the table, figures and page) and the same command
again makes only the runs that are missing.

    python benchmarks/rig_time.py [--out DIR] [--workers N]
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

from heliquad.host.records.points import read_points_csv
from heliquad.host.study.runs import RUNS, SWEEP, read_record
from heliquad.sim.base.dialect import AXES

SPEC = os.path.join(os.path.dirname(os.path.abspath(__file__)), "studies", "rig_time.toml")


def study(out: str, workers: int | None) -> list:
    """``heliquad study`` of :data:`SPEC` into ``out``: every run's record."""
    command = [sys.executable, "-m", "heliquad.host.cli.parser", "study", SPEC, "--out", out]
    if workers:
        command += ["--workers", str(workers)]
    if subprocess.run(command).returncode:
        raise SystemExit(f"heliquad study {SPEC} --out {out} did not finish every run")
    folders = sorted(os.listdir(os.path.join(out, RUNS)))
    return [dict(read_record(os.path.join(out, RUNS, name)), folder=name) for name in folders]


def _interpolated(points, freqs_hz):
    """The points' gain at ``freqs_hz``: log-magnitude and unwrapped phase, linear in log f."""
    f = np.array([p.freq_hz for p in points])
    g = np.array([p.gain for p in points])
    mag = np.interp(np.log(freqs_hz), np.log(f), np.log(np.abs(g)))
    phase = np.interp(np.log(freqs_hz), np.log(f), np.unwrap(np.angle(g)))
    return np.exp(mag + 1j * phase)


def _points(out: str, record: dict) -> list:
    return read_points_csv(os.path.join(out, RUNS, record["folder"], SWEEP, "points.csv"))


def _pick(records, axis, signal, turbulence) -> list:
    return [r for r in records if r["factors"]["axis"] == axis and
            r["factors"]["signal"] == signal and r["factors"]["turbulence"] == turbulence]


def still_air(out: str, records: list, axis: str) -> None:
    (ms,), (dwell,) = (_pick(records, axis, s, "none") for s in ("multisine", "dwell"))
    got = _points(out, ms)
    want = _interpolated(_points(out, dwell), np.array([p.freq_hz for p in got]))
    ratio = np.array([p.gain for p in got]) / want
    print(f"{axis:>6} still air: multisine {ms['points']} points in {ms['excited_s']:.1f} s, "
          f"dwell {dwell['points']} in {dwell['excited_s']:.1f} s "
          f"({dwell['excited_s'] / ms['excited_s']:.1f}x); largest difference "
          f"{np.max(np.abs(20 * np.log10(np.abs(ratio)))):.3f} dB, "
          f"{np.max(np.abs(np.degrees(np.angle(ratio)))):.2f} deg; against the truth, worst: "
          f"multisine {ms['points_worst_db']:.3f} dB {ms['points_worst_deg']:.2f} deg, dwell "
          f"{dwell['points_worst_db']:.3f} dB {dwell['points_worst_deg']:.2f} deg", flush=True)


def _pooled(runs: list, name: str) -> float:
    """The RMS over every point of ``runs`` from each run's RMS and count."""
    return math.sqrt(sum(r["points"] * r[name] ** 2 for r in runs) /
                     sum(r["points"] for r in runs))


def turbulent(records: list, axis: str) -> None:
    for signal in ("dwell", "multisine"):
        runs = _pick(records, axis, signal, "moderate")
        print(f"{axis:>6} moderate turbulence, {signal:>9}: "
              f"{np.mean([r['excited_s'] for r in runs]):.1f} s; error against truth RMS "
              f"{_pooled(runs, 'points_rms_db'):.2f} dB {_pooled(runs, 'points_rms_deg'):.1f} "
              f"deg, worst {max(r['points_worst_db'] for r in runs):.2f} dB "
              f"{max(r['points_worst_deg'] for r in runs):.1f} deg "
              f"({sum(r['points'] for r in runs)} points, {len(runs)} seeds)", flush=True)


def main(argv=None):
    """The study, then its figures, axis by axis."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", help="the study's folder, kept (default: a temporary one)")
    parser.add_argument("--workers", type=int, help="local workers (default: one per core)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="rig_time-") as tmp:
        out = args.out or tmp
        records = study(out, args.workers)
        for axis in AXES:
            still_air(out, records, axis)
        for axis in AXES:
            turbulent(records, axis)


if __name__ == "__main__":
    main()

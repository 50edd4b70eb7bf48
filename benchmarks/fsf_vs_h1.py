"""Benchmark: batch FSF estimate versus Welch H1 (scipy.signal.csd) on the same data.

Ten minutes of 200 Hz data (120 000 samples) of a 1 Hz sine through the paper's roll model
with 20 dB output noise. Both estimators produce a gain and a coherence at the excitation
frequency; each is timed as the best of several repeats in the same run, and the ratio
FSF / H1 is printed (target <= 1.0). The recursive (sample-by-sample) form's throughput is
reported in samples per second.

    python benchmarks/fsf_vs_h1.py [--repeats 7]
"""

import argparse
import math
import pathlib
import sys
import time

import numpy as np
import scipy.signal

from heliquad.host.estimate.baselines import estimate_h1
from heliquad.host.estimate.fsf import RecursiveFsf, estimate_fsf

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "tests"))
from dwell_plant import simulate_sine_dwell  # noqa: E402  (the tests' exact sine-dwell plant)

FS_HZ = 200.0
DURATION_S = 600.0
FREQ_HZ = 1.0
ROLL = ([28.19], [1, 5.13, 22.93])
RECURSIVE_SAMPLES = 20_000


def best_of(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return min(times), result


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    cycles = int(DURATION_S * FREQ_HZ)
    d = simulate_sine_dwell(*ROLL, FREQ_HZ, fs_hz=FS_HZ, cycles=cycles, settle_cycles=8)
    rng = np.random.default_rng(0)
    y = d.y + rng.normal(0, np.sqrt(np.mean(d.y ** 2) / 100), d.y.size)
    u = d.u
    G = np.polyval(ROLL[0], 2j * math.pi * FREQ_HZ) / np.polyval(ROLL[1], 2j * math.pi * FREQ_HZ)

    t_fsf, p_fsf = best_of(lambda: estimate_fsf(u, y, FS_HZ, freq_hz=FREQ_HZ), args.repeats)
    t_h1, p_h1 = best_of(lambda: estimate_h1(u, y, FS_HZ, FREQ_HZ), args.repeats)
    nperseg = int(p_h1.period_samples) * max(1, (2 * u.size // 9) // int(p_h1.period_samples))

    def bare_h1():
        _, s_uy = scipy.signal.csd(u, y, fs=FS_HZ, nperseg=nperseg)
        _, s_uu = scipy.signal.csd(u, u, fs=FS_HZ, nperseg=nperseg)
        return s_uy / s_uu

    t_bare, _ = best_of(bare_h1, args.repeats)
    t_found, _ = best_of(lambda: estimate_fsf(u, y, FS_HZ), max(1, args.repeats // 2))

    rls = RecursiveFsf(round(FS_HZ / FREQ_HZ), discard_periods=0)
    t0 = time.perf_counter()
    for a, b in zip(u[:RECURSIVE_SAMPLES], y[:RECURSIVE_SAMPLES]):
        rls.update(a, b)
    rate = RECURSIVE_SAMPLES / (time.perf_counter() - t0)

    print(f"data: {u.size} samples ({DURATION_S:g} s at {FS_HZ:g} Hz), {FREQ_HZ:g} Hz sine, 20 dB SNR")
    print(f"FSF batch (gain, sigma, coherence)     {1e3 * t_fsf:8.2f} ms   "
          f"|G| error {100 * abs(abs(p_fsf.gain) / abs(G) - 1):.3f} %")
    print(f"H1 Welch, 3 x csd (gain, coherence)   {1e3 * t_h1:8.2f} ms   "
          f"|G| error {100 * abs(abs(p_h1.gain) / abs(G) - 1):.3f} %  (nperseg {nperseg})")
    print(f"H1 Welch, 2 x csd (gain only)         {1e3 * t_bare:8.2f} ms")
    print(f"FSF batch with frequency search       {1e3 * t_found:8.2f} ms")
    print(f"ratio FSF / H1 (like for like)         {t_fsf / t_h1:8.3f}   (target <= 1.0)")
    print(f"ratio FSF / H1 gain-only               {t_fsf / t_bare:8.3f}")
    print(f"recursive FSF + RLS                    {rate:8.0f} samples/s "
          f"({rate / FS_HZ:.0f}x real time at {FS_HZ:g} Hz)")


if __name__ == "__main__":
    main()

"""Benchmark: lockstep frames per second against a raw pty echo round trip, same run.

Baseline: a minimal echo over a pty. A 25-line C program (compiled here with the system's
cc) owns a pty master and writes back every byte it reads; the client writes one frame of
the sim link's size (HQ_SENSOR_FRAME, 210 bytes) with pyserial and reads it back, as
:class:`heliquad.sim.lockstep.SimLink` does. This is the transport's round-trip cost with
nothing else in it.

Lockstep: ``heliquad sil`` with the transfer-function plant (SPEC.md's roll model) at a
200 Hz loop, mixer injection: plant step, sensor packet, frame out, firmware step, reply and
that step's telemetry in, logged. Frames per second over the excitation part of the run.

The same with the 6-DoF vehicle on the roll rig (issue 4: target >= 0.5). Prints the rates,
the ratios and the real-time factors; --profile adds where a vehicle frame's time goes.

    python benchmarks/lockstep_vs_echo.py [--frames 5000] [--profile]
"""

import argparse
import os
import pathlib
import subprocess
import tempfile
import time

import serial

from heliquad.sim.sil import SilConfig, run_sil

ECHO_C = r"""
#define _GNU_SOURCE
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>
int main(void) {
    int m = posix_openpt(O_RDWR | O_NOCTTY);
    if (m < 0 || grantpt(m) || unlockpt(m)) return 1;
    const char* name = ptsname(m);
    int s = open(name, O_RDWR | O_NOCTTY);          /* keep the line open, make it raw */
    struct termios t; tcgetattr(s, &t); cfmakeraw(&t); tcsetattr(s, TCSANOW, &t);
    printf("%s\n", name); fflush(stdout);
    unsigned char buf[4096];
    for (;;) {
        ssize_t n = read(m, buf, sizeof buf);
        if (n <= 0) return 0;
        for (ssize_t off = 0; off < n;) { ssize_t w = write(m, buf + off, n - off); if (w <= 0) return 0; off += w; }
    }
}
"""
FRAME_BYTES = 210


def echo_round_trips(frames: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        src, exe = pathlib.Path(tmp, "echo.c"), pathlib.Path(tmp, "echo")
        src.write_text(ECHO_C)
        subprocess.run(["cc", "-O2", "-o", str(exe), str(src)], check=True)
        proc = subprocess.Popen([str(exe)], stdout=subprocess.PIPE, text=True)
        try:
            port = serial.Serial(proc.stdout.readline().strip(), timeout=1.0)
            frame = bytes(range(FRAME_BYTES))
            for _ in range(100):                                   # warm up
                port.write(frame)
                port.read(FRAME_BYTES)
            t0 = time.perf_counter()
            for _ in range(frames):
                port.write(frame)
                got = port.read(FRAME_BYTES)
                assert len(got) == FRAME_BYTES
            elapsed = time.perf_counter() - t0
            port.close()
        finally:
            proc.kill()
            proc.wait()
    return frames / elapsed


def lockstep_frames(frames: int, plant: str = "tf"):
    cycles = max(1, int(round(frames / 200 * 2.0)))              # 2 Hz: 100 frames a cycle
    cfg = SilConfig(freq_hz=2.0, cycles=cycles, amplitude=0.05, plant=plant, rig="roll")
    with tempfile.TemporaryDirectory() as tmp:
        r = run_sil(cfg, os.path.join(tmp, "bench"), progress=lambda *_: None)
    return r


def profile_vehicle(frames: int) -> None:
    """Where a vehicle-plant frame's time goes: the top functions by own time."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    r = lockstep_frames(frames, "vehicle")
    prof.disable()
    stats = pstats.Stats(prof)
    rows = sorted(stats.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:6]
    print(f"profile, vehicle plant ({r.frames} frames; times inflated by the profiler):")
    for (filename, line, name), (_, _, tottime, _, _) in rows:
        print(f"  {1e6 * tottime / r.frames:7.1f} us/frame  {name} ({os.path.basename(filename)}:{line})")


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=5000)
    parser.add_argument("--profile", action="store_true", help="also profile a vehicle-plant run")
    args = parser.parse_args()
    echo = echo_round_trips(args.frames)
    print(f"raw pty echo ({FRAME_BYTES}-byte frames):      {echo:9.0f} round trips/s")
    for plant, target in (("tf", 0.6), ("vehicle", 0.5)):
        r = lockstep_frames(args.frames, plant)
        fps = r.frames / r.loop_s
        print(f"lockstep, {plant} plant, 200 Hz loop:  {fps:9.0f} frames/s  ({r.frames} frames "
              f"in {r.loop_s:.2f} s), ratio {fps / echo:.3f} (target >= {target}), "
              f"{fps / 200.0:.1f}x real time")
    if args.profile:
        profile_vehicle(min(args.frames, 2000))


if __name__ == "__main__":
    main()
